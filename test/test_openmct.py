"""The operator's view without a browser: points, history, live feed, server rules, bundle.

The page itself is tested in chromium (test_openmct_browser.py); here the parts it relies
on: the anomaly state an archive and the live topics give, the residual and the levels,
the server's Host, Origin and Content-Security-Policy rules, and where the bundle is found.
"""

import asyncio
import contextlib
import json
import pathlib
import threading
import urllib.error
import urllib.request

import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from rwa_monitor.cli.main import build_parser
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.openmct import bundle, history
from rwa_monitor.openmct.live import LiveFeed
from rwa_monitor.openmct.server import GroundServer
from rwa_monitor.openmct.store import GroundStore, Series
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth


def _event(component, kind, change, declared, revision=0, index=None, detector='llr'):
    return {'detector': detector, 'component': component, 'kind': kind, 'time': change,
            'index': index if index is not None else int(change * 10),
            'declared_time': declared, 'revision': revision, 'p_value': 1e-9}


def test_minmax_decimation_keeps_each_runs_extremes_and_latest_is_the_last_before_end():
    series = Series()
    t = np.arange(1000.0)
    v = np.zeros(1000)
    v[437], v[812] = 5.0, -3.0          # a spike up, a spike down
    series.extend(t, v)
    series.extend([500.5], [1.0])       # out of time order: merged in place
    got = series.query(0, 2000, size=10)
    assert len(got) <= 20
    assert {d['value'] for d in got} >= {5.0, -3.0}
    assert [d['met'] for d in got] == sorted(d['met'] for d in got)
    assert series.query(0, 500.7, latest=True) == [{'met': 500.5, 'value': 1.0}]
    assert len(series.query(10, 20)) == 11
    series.extend([2000.0], [7.0], [{'kind': 'dry'}])    # the first sample with extras
    assert series.query(1999, 2001) == [{'met': 2000.0, 'value': 7.0, 'kind': 'dry'}]
    assert series.query(0, 0) == [{'met': 0.0, 'value': 0.0}]


def test_the_anomaly_state_counts_each_change_with_its_latest_kind():
    events = [_event('rw2', 'undecided', 90.0, 100.0),
              _event('rw2', 'viscous', 90.0, 200.0, revision=1),
              _event('rw2', 'both', 250.0, 300.0),
              _event('rw2', 'calibration_changed', 400.0, 400.0)]
    times, values, extra = history.state_steps(events)
    assert times == [100.0, 200.0, 300.0]
    assert values == [1.0, 1.0, 2.0]          # WARN for dry/viscous/undecided, ERROR for both
    assert extra[-1]['kind'] == 'both, viscous'


@pytest.fixture
def fleet_outputs(tmp_path):
    """Return a fleet output folder written by hand: two spacecraft, one event chain."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    events = [dict(_event('rw1', 'undecided', 5000.0, 5100.0), spacecraft='sc2'),
              dict(_event('rw1', 'dry', 5000.0, 9000.0, revision=1), spacecraft='sc2')]
    rows = []
    for craft in ('sc1', 'sc2'):
        for k in range(6):
            rows.append({'spacecraft': craft, 'wheel': 'rw1', 'pass': f'p{k}',
                         't_start': 3600.0 * k, 't_end': 3600.0 * k + 600.0, 'samples': 6000,
                         'dry': 2e-4 + 1e-6 * k, 'dry_se': 1e-6, 'viscous': 5e-7,
                         'viscous_se': 1e-8, 'relative_to': 'zero'})
    trend = {'passes': 6, 'relative_to': 'zero', 'dry_slope_per_day': 2.4e-5,
             'dry_intercept': 1.99e-4, 'viscous_slope_per_day': 0.0,
             'viscous_intercept': 5e-7}
    since = {'sc1': trend, 'sc2': {**trend, 'passes': 4, 'since_s': 7200.0}}   # a step
    summary = {'spacecraft': {c: {'components': {'rw1': {'trend': since[c]}},
                                  'not_examined': {'pass p9': 'unreadable'} if c == 'sc1'
                                  else {}} for c in ('sc1', 'sc2')},
               'epoch_utc': '2026-03-01T00:00:00Z'}
    (tmp_path / 'events.json').write_text(json.dumps({'events': events}))
    (tmp_path / 'summary.json').write_text(json.dumps(summary))
    pq.write_table(pa.Table.from_pylist(rows), tmp_path / 'trend.parquet')
    return tmp_path


def test_a_fleets_outputs_become_levels_trend_lines_states_and_notes(fleet_outputs):
    store = GroundStore()
    summary = history.load_fleet(store, fleet_outputs)
    store.epoch_unix_s = history.fleet_epoch(summary)
    assert store.epoch_unix_s == 1772323200.0          # 2026-03-01T00:00:00Z
    tree = store.dictionary()
    assert [sc['key'] for sc in tree['spacecraft']] == ['sc1', 'sc2']
    assert tree['spacecraft'][0]['notes'] == ['not examined: pass p9: unreadable']
    dry = store.history('sc1.rw1.dry', -1, 1e9)
    assert [d['met'] for d in dry] == [3600.0 * k + 300.0 for k in range(6)]
    assert dry[0]['utc'] == (1772323200.0 + 300.0) * 1000.0
    line = store.history('sc1.rw1.dry_trend', -1, 1e9)
    assert line[2]['value'] == pytest.approx(1.99e-4 + 2.4e-5 * 7500.0 / 86400.0)
    assert len(line) == 6
    after = store.history('sc2.rw1.dry_trend', -1, 1e9)     # drawn from the step only
    assert [d['met'] for d in after] == [3600.0 * k + 300.0 for k in range(2, 6)]
    assert [d['value'] for d in store.history('sc1.rw1.state', -1, 1e9)] == [0.0]
    states = store.history('sc2.rw1.state', -1, 1e9)
    assert [(d['met'], d['value'], d['kind']) for d in states] == [
        (0.0, 0.0, 'none'), (5100.0, 1.0, 'undecided'), (9000.0, 1.0, 'dry')]
    events = store.history('sc2.rw1.events', -1, 1e9)
    assert [(e['kind'], e['change'], e['declared'], e['final']) for e in events] == [
        ('undecided', 5000.0, 5100.0, False), ('dry', 5000.0, 9000.0, False)]
    assert events[1]['change_utc'] == (1772323200.0 + 5000.0) * 1000.0


def test_a_fleet_folder_without_outputs_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match='fleet output folder'):
        history.load_fleet(GroundStore(), tmp_path)


def test_a_recordings_residual_shows_the_step_and_its_levels_follow_it():
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], duration_s=3600.0, rate_hz=10.0, seed=4301,
        anomalies=[Anomaly('rw2', 'dry', 2400.0, delta_dry=6e-4)])
    store = GroundStore()
    history.load_recording(store, tele, 'run', [_event('rw2', 'dry', 2400.0, 2460.0)])
    residual = store.series['run.rw2.residual']
    speed = store.series['run.rw2.speed'].v
    before, after = residual.t < 2400.0, residual.t >= 2400.0
    fast = np.abs(speed) > 1.0
    signed = residual.v * np.sign(speed)
    # a dry step of +6e-4 N m makes friction 6e-4 N m more negative along the spin
    # (eq. (1)); the mean over thousands of samples of noise 5e-5 N m is known to ~1e-6
    assert abs(np.mean(signed[before & fast])) < 2e-5
    assert np.mean(signed[after & fast]) == pytest.approx(-6e-4, abs=3e-5)
    dry = store.history('run.rw2.dry', -1, 1e9)
    assert len(dry) == 6
    assert dry[-1]['value'] - dry[0]['value'] == pytest.approx(6e-4, abs=6e-5)
    assert [d['value'] for d in store.history('run.rw1.state', -1, 1e9)] == [0.0]
    assert store.history('run.rw2.state', -1, 1e9)[-1]['value'] == 1.0


def test_live_state_latches_on_an_event_and_clears_on_acknowledgement_only():
    store = GroundStore(live=True)
    feed = LiveFeed(store)
    feed.wheels('/sat1', 10.0, ['rw1', 'rw2'], [50.0, 60.0], [-2e-4, -2e-4])
    feed.flush()
    assert [d['value'] for d in store.history('sat1.rw2.state', -1, 1e9)] == [0.0]
    feed.event('/sat1', 'sat1/llr_detector', _event('rw2', 'dry', 90.0, 100.0))
    feed.status(99.0, 'sat1/llr_detector: rw2 friction', 'rw2', {})    # sent before it
    feed.status(101.0, 'sat1/llr_detector: rw2 friction', 'rw2',
                {'latched_alarms': 1, 'latched_kind': 'dry'})
    feed.status(101.0, 'sat1/fss_diagnoser: rw2 window', 'rw2', {})     # another node
    feed.status(101.0, 'sat1/llr_detector: alarms', 'alarms', {'active': 1})
    feed.flush()
    assert [d['value'] for d in store.history('sat1.rw2.state', -1, 1e9)][-1] == 1.0
    assert [d['value'] for d in store.history('sat1.rw1.state', -1, 1e9)][-1] == 0.0
    assert 'alarms' not in {c['key'] for c in store.dictionary()['spacecraft'][0]
                            ['components']}
    feed.event('/sat1', 'sat1/llr_detector', _event('rw2', 'both', 150.0, 160.0))
    feed.flush()
    assert store.history('sat1.rw2.state', -1, 1e9)[-1]['value'] == 2.0
    feed.status(170.0, 'sat1/llr_detector: rw2 friction', 'rw2', {})   # acknowledged
    feed.flush()
    assert store.history('sat1.rw2.state', -1, 1e9)[-1]['value'] == 0.0
    sent = store.take_pending()
    assert {k for k, _ in sent} >= {'sat1.rw2.state', 'sat1.rw2.events', 'sat1.rw1.speed'}


def test_live_residual_waits_for_its_reference_and_never_goes_back_in_time_live():
    store = GroundStore(live=True)
    feed = LiveFeed(store)
    rng = np.random.default_rng(4302)
    t = np.arange(0.0, 700.0, 0.1)
    speed = 100.0 * np.sin(t / 30.0) + 20.0
    friction = -2e-4 * np.sign(speed) - 5e-7 * speed + rng.normal(0, 5e-5, t.size)
    for k in range(t.size):
        feed.wheels('/', t[k], ['rw1'], [speed[k]], [friction[k]])
        if k % 100 == 0:
            feed.flush()
    feed.flush()
    residual = store.series['live.rw1.residual']
    assert residual.t[0] == 0.0 and residual.t[-1] == t[-1]
    assert abs(np.mean(residual.v)) < 5e-6
    live_times = [d['met'] for k, d in store.take_pending() if k == 'live.rw1.residual']
    assert live_times and live_times == sorted(live_times) and live_times[0] >= 600.0


# ------------------------------------------------------------------------ the server
@contextlib.contextmanager
def serving(store, tmp_path, **kwargs):
    """Run a GroundServer (fake bundle) in a thread; yield it."""
    dist = tmp_path / 'dist'
    dist.mkdir(exist_ok=True)
    (dist / 'openmct.js').write_text('/* stand-in */')
    box, ready = {}, threading.Event()

    async def main():
        box['server'] = GroundServer(store, dist, port=0, **kwargs)
        box['loop'], box['stop'] = asyncio.get_running_loop(), asyncio.Event()
        ready.set()
        await box['stop'].wait()
        box['server'].stop()
    thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)
    thread.start()
    assert ready.wait(10)
    try:
        yield box['server']
    finally:
        box['loop'].call_soon_threadsafe(box['stop'].set)
        thread.join(10)


def _get(url, host=None):
    request = urllib.request.Request(url, headers={'Host': host} if host else {})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as err:
        return err.code, dict(err.headers), b''


def test_the_server_serves_only_its_own_names_with_a_same_origin_policy(tmp_path):
    store = GroundStore(epoch_unix_s=1000.0)
    store.add('sc1', 'rw1', 'speed', [1.0, 2.0, 3.0], [10.0, 20.0, 30.0])
    with serving(store, tmp_path) as server:
        status, headers, body = _get(server.url)
        assert status == 200 and b'/openmct/openmct.js' in body
        csp = headers['Content-Security-Policy']
        assert "default-src 'self'" in csp and "connect-src 'self'" in csp
        assert _get(server.url + 'openmct/openmct.js')[0] == 200
        assert _get(server.url + 'openmct/../bundle.py')[0] in (403, 404)
        # DNS rebinding: a page of another name resolved to 127.0.0.1 gets nothing
        assert _get(server.url + 'api/dictionary', host=f'evil.example:{server.port}')[0] \
            == 403
        assert _get(server.url + 'api/dictionary', host=f'localhost:{server.port}')[0] == 200
        status, _, body = _get(server.url + 'api/history?key=sc1.rw1.speed&domain=utc'
                               '&start=1001500&end=1003000')
        assert status == 200
        assert [d['value'] for d in json.loads(body)] == [20.0, 30.0]
        assert _get(server.url + 'api/history?key=nope')[0] == 404


def test_the_live_websocket_accepts_its_page_origin_only(tmp_path):
    store = GroundStore(live=True)
    with serving(store, tmp_path) as server:
        ws_url = f'ws://127.0.0.1:{server.port}/api/live'
        with pytest.raises(InvalidStatus) as refused:
            connect(ws_url, origin='http://evil.example', open_timeout=10)
        assert refused.value.response.status_code == 403
        assert server.refused == ['http://evil.example']
        with connect(ws_url, origin=f'http://127.0.0.1:{server.port}', open_timeout=10) as ws:
            ws.send(json.dumps({'subscribe': ['sat.rw1.speed']}))
            while True:   # the subscription is read by the server's loop: send until seen
                store.add('sat', 'rw1', 'speed', [1.0], [5.0], live=True)
                message = json.loads(ws.recv(timeout=10))
                if message['type'] == 'data':
                    break
            assert message['data'][0] == ['sat.rw1.speed', {'met': 1.0, 'value': 5.0}]
    with serving(GroundStore(live=True), tmp_path,
                 allowed_origins=['http://console.example']) as server:
        with connect(f'ws://127.0.0.1:{server.port}/api/live',
                     origin='http://console.example', open_timeout=10):
            pass


def test_the_command_binds_loopback_by_default_and_needs_something_to_show():
    args = build_parser().parse_args(['openmct', '--fleet', 'x'])
    assert args.host == '127.0.0.1' and args.port == 8090 and args.allow_origin == []
    with pytest.raises(ConfigError, match='nothing to show'):
        args.func(build_parser().parse_args(['openmct']))


def test_the_bundle_is_the_locked_version_or_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr(bundle, 'NPM_DIR', pathlib.Path(bundle.NPM_DIR))
    monkeypatch.setenv('XDG_DATA_HOME', str(tmp_path / 'data'))
    fake = tmp_path / 'node_modules' / 'openmct'
    (fake / 'dist').mkdir(parents=True)
    (fake / 'package.json').write_text(json.dumps({'version': '0.0.1'}))
    (fake / 'dist' / 'openmct.js').write_text('')
    monkeypatch.setenv(bundle.ENV, str(tmp_path))
    found = [p for p in bundle.candidates() if (p / 'package.json').is_file()]
    if found[1:]:       # the clone's own bundle is there: it is taken after ours is refused
        assert bundle.find_bundle() == found[1] / 'dist'
    else:
        with pytest.raises(ConfigError, match=r'version 0\.0\.1.*make openmct'):
            bundle.find_bundle()
    (fake / 'package.json').write_text(json.dumps({'version': bundle.pinned_version()}))
    assert bundle.find_bundle() == fake / 'dist'
