// rwa_monitor's Open MCT plugin: object tree, history, live data, limits, time, layouts.
//
// Everything comes from the server that served this page (`rwa-monitor openmct`):
// /api/dictionary (the tree), /api/history (a point's samples), /api/live (WebSocket).
// Object keys (namespace 'rwa'):
//   root                      folder "rwa_monitor"  -> fleet, then one folder per spacecraft
//   fleet                     Display Layout: every spacecraft's anomaly states at once
//   <sc>                      folder -> <sc>.display, <sc>.states, <sc>.events, components
//   <sc>.display              Display Layout of one spacecraft (states, events, plots)
//   <sc>.states / <sc>.events LAD table of the states / table of the events
//   <sc>.<c>                  folder of a wheel or the gyro -> its plots and points
//   <sc>.<c>.<point>          a telemetry point (speed, friction, residual, dry, ..., state)
//   <sc>.<c>.plot_<name>      overlay plots (friction + residual, a level + its trend, rates)
// Times: 'met' (telemetry seconds) always, 'utc' (ms) when the server knows an epoch.
/* global openmct */
(function () {
  'use strict';

  const NS = 'rwa';
  const TELEMETRY_TYPE = 'rwa.telemetry';
  const MET = 'met';
  const CLOCK = 'rwa.telemetry';
  const STATE_CLASSES = {
    1: { cssClass: 'is-limit--upr is-limit--yellow', name: 'anomaly, not acknowledged' },
    2: { cssClass: 'is-limit--upr is-limit--red', name: 'anomaly (error), not acknowledged' }
  };
  const PLOTS = {
    plot_friction: { name: 'friction and residual', points: ['friction', 'residual'] },
    plot_speed: { name: 'speed', points: ['speed'] },
    plot_dry: { name: 'dry level and trend', points: ['dry', 'dry_trend'] },
    plot_viscous: { name: 'viscous level and trend', points: ['viscous', 'viscous_trend'] },
    plot_rates: { name: 'rates', points: ['rate_x', 'rate_y', 'rate_z'] }
  };

  let dictionary = null;
  const compositionListeners = new Map(); // parent key -> [{callback, context}]

  function id(key) {
    return { namespace: NS, key: key };
  }

  function fetchDictionary() {
    return fetch('/api/dictionary', { cache: 'no-store' }).then((response) => {
      if (!response.ok) {
        throw new Error('HTTP ' + response.status);
      }
      return response.json();
    });
  }

  function hasUtc() {
    return dictionary.epoch_unix_s !== null && dictionary.epoch_unix_s !== undefined;
  }

  function timeSystemKey() {
    return hasUtc() ? 'utc' : MET;
  }

  // ---------------------------------------------------------------- times and formats
  function formatMet(value) {
    if (typeof value !== 'number' || !isFinite(value)) {
      return '';
    }
    const sign = value < 0 ? '-' : '';
    let s = Math.abs(value);
    const days = Math.floor(s / 86400);
    s -= days * 86400;
    const hh = String(Math.floor(s / 3600)).padStart(2, '0');
    const mm = String(Math.floor((s % 3600) / 60)).padStart(2, '0');
    const ss = (s % 60).toFixed(1).padStart(4, '0');
    return sign + 'T+' + (days ? days + 'd ' : '') + hh + ':' + mm + ':' + ss;
  }

  function parseMet(text) {
    if (typeof text === 'number') {
      return text;
    }
    const m = /^\s*(-)?T?\+?\s*(?:(\d+)d\s*)?(\d+):(\d+):(\d+(?:\.\d*)?)\s*$/.exec(String(text));
    if (m) {
      const v = Number(m[2] || 0) * 86400 + Number(m[3]) * 3600 + Number(m[4]) * 60 +
        Number(m[5]);
      return m[1] ? -v : v;
    }
    return Number(text);
  }

  const metFormat = {
    key: 'rwa.met',
    format: formatMet,
    parse: parseMet,
    validate: (text) => isFinite(parseMet(text))
  };

  const metDurationFormat = {
    key: 'rwa.met.duration',
    format: (value) => formatMet(value).replace('T+', ''),
    parse: parseMet,
    validate: (text) => isFinite(parseMet(text))
  };

  const metTimeSystem = {
    key: MET,
    name: 'Telemetry time (s from the start)',
    cssClass: 'icon-clock',
    timeFormat: 'rwa.met',
    durationFormat: 'rwa.met.duration',
    isUTCBased: false
  };

  // A clock that follows the newest live sample (a replay runs at any rate).
  const telemetryClock = {
    key: CLOCK,
    name: 'Telemetry clock',
    cssClass: 'icon-clock',
    description: 'The time of the newest live sample received',
    listeners: [],
    last: { met: 0, utc: 0 },
    on(event, callback) {
      if (event === 'tick') {
        this.listeners.push(callback);
      }
    },
    off(event, callback) {
      this.listeners = this.listeners.filter((c) => c !== callback);
    },
    currentValue() {
      return timeSystemKey() === 'utc' ? this.last.utc : this.last.met;
    },
    advance(datum) {
      if (typeof datum.met === 'number' && datum.met > this.last.met) {
        this.last = { met: datum.met, utc: datum.utc || 0 };
        this.pending = true;
      }
    },
    flush() {
      if (this.pending) {
        this.pending = false;
        const value = this.currentValue();
        this.listeners.forEach((callback) => callback(value));
      }
    }
  };

  // ---------------------------------------------------------------- the live feed
  const live = {
    socket: null,
    callbacks: new Map(), // key -> Set of callbacks
    connect() {
      const scheme = window.location.protocol === 'https:' ? 'wss://' : 'ws://';
      this.socket = new WebSocket(scheme + window.location.host + '/api/live');
      this.socket.onopen = () => this.send({ subscribe: Array.from(this.callbacks.keys()) });
      this.socket.onmessage = (message) => this.receive(JSON.parse(message.data));
      this.socket.onclose = () => setTimeout(() => this.connect(), 2000);
    },
    send(request) {
      if (this.socket && this.socket.readyState === WebSocket.OPEN) {
        this.socket.send(JSON.stringify(request));
      }
    },
    receive(message) {
      if (message.type === 'data') {
        message.data.forEach(([key, datum]) => {
          telemetryClock.advance(datum);
          (this.callbacks.get(key) || []).forEach((callback) => callback(datum));
        });
        telemetryClock.flush();
      } else if (message.type === 'dictionary' && message.version !== dictionary.version) {
        refreshDictionary();
      }
    },
    subscribe(key, callback) {
      if (!this.callbacks.has(key)) {
        this.callbacks.set(key, new Set());
        this.send({ subscribe: [key] });
      }
      this.callbacks.get(key).add(callback);
      return () => {
        const set = this.callbacks.get(key);
        set.delete(callback);
        if (!set.size) {
          this.callbacks.delete(key);
          this.send({ unsubscribe: [key] });
        }
      };
    }
  };

  // The tree grew (a live spacecraft or wheel appeared): tell the open compositions.
  function refreshDictionary() {
    const before = new Map();
    compositionListeners.forEach((_, key) => before.set(key, childKeys(key)));
    return fetchDictionary().then((fresh) => {
      dictionary = fresh;
      before.forEach((old, key) => {
        const added = childKeys(key).filter((k) => !old.includes(k));
        (compositionListeners.get(key) || []).forEach((l) =>
          added.forEach((k) => l.callback.call(l.context, id(k))));
      });
    });
  }

  // ---------------------------------------------------------------- the object tree
  function findCraft(key) {
    return dictionary.spacecraft.find((sc) => sc.key === key);
  }

  function findComponent(sc, key) {
    return sc && sc.components.find((c) => c.key === key);
  }

  function plotsOf(component) {
    return Object.keys(PLOTS).filter((plot) =>
      PLOTS[plot].points.some((p) => component.points.includes(p)));
  }

  function childKeys(key) {
    if (key === 'root') {
      return ['fleet'].concat(dictionary.spacecraft.map((sc) => sc.key));
    }
    if (key === 'fleet') {
      return dictionary.spacecraft.map((sc) => sc.key + '.states');
    }
    const parts = key.split('.');
    const sc = findCraft(parts[0]);
    if (!sc) {
      return [];
    }
    if (parts.length === 1) {
      return [sc.key + '.display', sc.key + '.states', sc.key + '.events'].concat(
        sc.components.map((c) => sc.key + '.' + c.key));
    }
    if (parts[1] === 'display') {
      return displayItems(sc).map((item) => item.key);
    }
    if (parts[1] === 'states' || parts[1] === 'events') {
      return sc.components.filter((c) => c.points.includes(parts[1] === 'states' ? 'state'
        : 'events')).map((c) => sc.key + '.' + c.key + '.' + (parts[1] === 'states'
        ? 'state' : 'events'));
    }
    const component = findComponent(sc, parts[1]);
    if (!component) {
      return [];
    }
    if (parts.length === 2) {
      return plotsOf(component).map((p) => key + '.' + p).concat(
        component.points.map((p) => key + '.' + p));
    }
    const plot = PLOTS[parts[2]];
    return plot ? plot.points.filter((p) => component.points.includes(p)).map(
      (p) => parts[0] + '.' + parts[1] + '.' + p) : [];
  }

  function pointMetadata(point) {
    const info = dictionary.points[point];
    const values = [{
      key: MET, name: 'Time', source: 'met', format: 'rwa.met', hints: { domain: hasUtc() ? 2 : 1 }
    }];
    if (hasUtc()) {
      values.push({ key: 'utc', name: 'Time (UTC)', source: 'utc', format: 'utc',
        hints: { domain: 1 } });
    }
    const timeFormat = hasUtc() ? 'utc' : 'rwa.met';
    const timeSuffix = hasUtc() ? '_utc' : '';
    if (info.kind === 'state') {
      values.push({
        key: 'value', name: 'Anomaly state', format: 'enum', hints: { range: 1 },
        enumerations: Object.entries(dictionary.states).map(([v, s]) => ({ value: Number(v), string: s }))
      });
      values.push({ key: 'kind', name: 'Kind', format: 'string' });
    } else if (info.kind === 'event') {
      values.push({ key: 'component', name: 'Component', format: 'string' });
      values.push({ key: 'kind', name: 'Kind', format: 'string' });
      values.push({ key: 'change', name: 'Change time', source: 'change' + timeSuffix,
        format: timeFormat });
      values.push({ key: 'declared', name: 'Declared time', source: 'declared' + timeSuffix,
        format: timeFormat });
      values.push({ key: 'value', name: 'Revision', format: 'number', hints: { range: 1 } });
      values.push({ key: 'final', name: 'Final', format: 'string' });
      values.push({ key: 'p_value', name: 'p-value', format: 'float' });
      values.push({ key: 'delta_dry_nm', name: 'Dry step', unit: 'N m', format: 'float' });
      values.push({ key: 'delta_viscous_nms', name: 'Viscous step', unit: 'N m s/rad',
        format: 'float' });
      values.push({ key: 'detector', name: 'Detector', format: 'string' });
    } else {
      values.push({ key: 'value', name: point.replace('_', ' '), unit: info.unit,
        format: 'float', hints: { range: 1 } });
    }
    return { values: values };
  }

  // Per-pass levels are points (a line between passes would invent values); trend lines
  // and samples are lines.
  function seriesStyle(key) {
    const point = key.split('.')[2];
    const level = point === 'dry' || point === 'viscous';
    return { identifier: id(key), interpolate: level ? 'none' : 'linear', markers: level,
      markerShape: 'circle', markerSize: level ? 5 : 2 };
  }

  function folder(key, name, location) {
    return {
      identifier: id(key), name: name, type: 'folder', location: location,
      composition: childKeys(key).map(id)
    };
  }

  // Display Layout items (grid of 10 px): the states and events of a spacecraft, then one
  // plot per wheel and for the gyro: friction with its residual when the data have them,
  // else the dry level with its trend.
  function displayItems(sc) {
    const items = [
      { key: sc.key + '.states', x: 0, y: 0, width: 34, height: 22 },
      { key: sc.key + '.events', x: 35, y: 0, width: 64, height: 22 }
    ];
    sc.components.forEach((c, i) => {
      const plots = plotsOf(c);
      const plot = plots.includes('plot_friction') ? 'plot_friction'
        : plots.includes('plot_dry') ? 'plot_dry' : plots[0];
      if (plot) {
        items.push({ key: sc.key + '.' + c.key + '.' + plot, x: (i % 2) * 50,
          y: 23 + Math.floor(i / 2) * 25, width: 49, height: 24 });
      }
    });
    return items;
  }

  function layout(key, name, location, items) {
    return {
      identifier: id(key), name: name, type: 'layout', location: location,
      composition: items.map((item) => id(item.key)),
      configuration: {
        layoutGrid: [10, 10],
        items: items.map((item, i) => ({
          id: key + '-item-' + i, type: 'subobject-view', identifier: id(item.key),
          x: item.x, y: item.y, width: item.width, height: item.height,
          hasFrame: true, fontSize: 'default', font: 'default'
        }))
      }
    };
  }

  function fleetItems() {
    return dictionary.spacecraft.map((sc, i) => ({
      key: sc.key + '.states', x: (i % 3) * 36, y: Math.floor(i / 3) * 21,
      width: 35, height: 20
    }));
  }

  function getObject(identifier) {
    const key = identifier.key;
    if (key === 'root') {
      return folder('root', 'rwa_monitor', 'ROOT');
    }
    if (key === 'fleet') {
      return layout('fleet', 'Fleet: anomaly states', NS + ':root', fleetItems());
    }
    const parts = key.split('.');
    const sc = findCraft(parts[0]);
    if (!sc) {
      return undefined;
    }
    if (parts.length === 1) {
      return folder(key, sc.name, NS + ':root');
    }
    const parent = NS + ':' + sc.key;
    if (parts[1] === 'display') {
      return layout(key, sc.name + ' display', parent, displayItems(sc));
    }
    if (parts[1] === 'states') {
      return { identifier: id(key), name: sc.name + ': anomaly states', type: 'LadTable',
        location: parent, composition: childKeys(key).map(id),
        configuration: { hiddenColumns: { type: true }, isFixedLayout: true } };
    }
    if (parts[1] === 'events') {
      return { identifier: id(key), name: sc.name + ': events', type: 'table',
        location: parent, composition: childKeys(key).map(id),
        configuration: { columnWidths: {}, hiddenColumns: { met: hasUtc() },
          telemetryMode: 'unlimited', persistModeChange: false, rowLimit: 50 } };
    }
    const component = findComponent(sc, parts[1]);
    if (!component) {
      return undefined;
    }
    if (parts.length === 2) {
      return folder(key, sc.name + ' ' + component.name, parent);
    }
    const location = NS + ':' + parts[0] + '.' + parts[1];
    if (PLOTS[parts[2]]) {
      return { identifier: id(key), name: sc.name + ' ' + component.name + ' ' +
        PLOTS[parts[2]].name, type: 'telemetry.plot.overlay', location: location,
        composition: childKeys(key).map(id),
        configuration: { series: childKeys(key).map(seriesStyle) } };
    }
    const point = parts[2];
    if (!component.points.includes(point)) {
      return undefined;
    }
    const info = dictionary.points[point];
    return {
      identifier: id(key),
      name: component.name + ' ' + (point === 'state' ? 'anomaly state' : point.replace('_', ' ')),
      type: TELEMETRY_TYPE, location: location,
      telemetry: pointMetadata(point), rwa: { key: key, kind: info.kind, unit: info.unit }
    };
  }

  // Objects are made from the dictionary; what a view or the operator changes on them
  // (a plot's series colours, a moved layout item) is kept for this page's session.
  const edited = new Map();
  const objectProvider = {
    get(identifier) {
      const object = edited.get(identifier.key) || getObject(identifier);
      return object ? Promise.resolve(object)
        : Promise.reject(new Error('rwa_monitor has no object ' + identifier.key));
    },
    create(domainObject) {
      edited.set(domainObject.identifier.key, domainObject);
      return Promise.resolve(true);
    },
    update(domainObject) {
      edited.set(domainObject.identifier.key, domainObject);
      return Promise.resolve(true);
    }
  };

  const compositionProvider = {
    appliesTo(domainObject) {
      return domainObject.identifier.namespace === NS && Array.isArray(domainObject.composition);
    },
    load(domainObject) {
      return Promise.resolve(childKeys(domainObject.identifier.key).map(id));
    },
    on(domainObject, event, callback, context) {
      if (event === 'add') {
        const key = domainObject.identifier.key;
        if (!compositionListeners.has(key)) {
          compositionListeners.set(key, []);
        }
        compositionListeners.get(key).push({ callback: callback, context: context });
      }
    },
    off(domainObject, event, callback) {
      const list = compositionListeners.get(domainObject.identifier.key);
      if (list) {
        compositionListeners.set(domainObject.identifier.key,
          list.filter((l) => l.callback !== callback));
      }
    },
    add() {},
    remove() {},
    includes(parent, childId) {
      return childKeys(parent.identifier.key).includes(childId.key);
    },
    reorder() {}
  };

  // ---------------------------------------------------------------- telemetry
  const telemetryProvider = {
    supportsRequest(domainObject) {
      return domainObject.type === TELEMETRY_TYPE;
    },
    request(domainObject, options) {
      const query = new URLSearchParams({
        key: domainObject.rwa.key,
        domain: options.domain === 'utc' ? 'utc' : MET,
        start: String(options.start),
        end: String(options.end)
      });
      if (options.size) {
        query.set('size', String(options.size));
      }
      if (options.strategy === 'latest') {
        query.set('strategy', 'latest');
      }
      return fetch('/api/history?' + query.toString(), { signal: options.signal })
        .then((response) => (response.ok ? response.json() : []));
    },
    supportsSubscribe(domainObject) {
      return domainObject.type === TELEMETRY_TYPE && dictionary.live;
    },
    subscribe(domainObject, callback) {
      return live.subscribe(domainObject.rwa.key, callback);
    },
    supportsLimits(domainObject) {
      return domainObject.type === TELEMETRY_TYPE && domainObject.rwa.kind === 'state';
    },
    getLimitEvaluator() {
      return {
        evaluate(datum, valueMetadata) {
          if (valueMetadata && valueMetadata.key !== 'value') {
            return undefined;
          }
          return STATE_CLASSES[Math.round(datum.value)];
        }
      };
    }
  };

  // ---------------------------------------------------------------- conductor
  function conductor(d) {
    dictionary = d;
    const utc = hasUtc();
    const scale = utc ? 1000 : 1;
    const span = d.span_s || [0, 3600];
    const toTime = (s) => (utc ? (d.epoch_unix_s + s) * 1000 : s);
    const pad = Math.max((span[1] - span[0]) * 0.02, 1);
    const options = [{
      name: 'Fixed', timeSystem: timeSystemKey(),
      bounds: { start: toTime(span[0] - pad), end: toTime(span[1] + pad) }
    }];
    if (d.live) {
      options.unshift({
        name: 'Realtime', timeSystem: timeSystemKey(), clock: CLOCK,
        clockOffsets: { start: -600 * scale, end: 10 * scale }
      });
    }
    return options;
  }

  function plugin(d) {
    dictionary = d;
    if (d.span_s) {   // the clock starts at the newest sample the server holds
      const met = d.span_s[1];
      telemetryClock.last = { met: met, utc: hasUtc() ? (d.epoch_unix_s + met) * 1000 : 0 };
    }
    return function install(mct) {
      mct.types.addType(TELEMETRY_TYPE, {
        name: 'rwa_monitor telemetry point', cssClass: 'icon-telemetry', creatable: false
      });
      mct.telemetry.addFormat(metFormat);
      mct.telemetry.addFormat(metDurationFormat);
      mct.time.addTimeSystem(metTimeSystem);
      mct.time.addClock(telemetryClock);
      mct.objects.addRoot(id('root'), mct.priority.HIGHEST);
      mct.objects.addProvider(NS, objectProvider);
      mct.composition.addProvider(compositionProvider);
      mct.telemetry.addProvider(telemetryProvider);
      if (d.live) {
        live.connect();
      }
    };
  }

  window.RwaMonitor = {
    fetchDictionary: () => fetchDictionary().then((d) => (dictionary = d)),
    plugin: plugin,
    conductor: conductor,
    defaultPath: () => '#/browse/' + NS + ':root/' + NS + ':fleet',
    formatMet: formatMet,
    parseMet: parseMet,
    live: live
  };
})();
