"""History for the operator's view: a fleet's outputs and a recording, as points.

From a fleet's output folder (docs/fleet.md; files only, nothing of the engine runs):
``events.json`` -> each component's ``events`` and ``state``; ``trend.parquet`` -> each
wheel's per-pass ``dry`` and ``viscous`` levels (at the pass's mid time, with standard
error, pass and samples); summary.json's ``components.<wheel>.trend`` -> ``dry_trend`` and
``viscous_trend`` (the report's line at each pass's mid time); ``not_examined`` -> notes.

From a recording (any file ``read_telemetry`` reads) and its events: ``speed``,
``friction``, ``residual`` (friction minus the nominal model: the calibration's, or
model (1) fitted to the wheel's first ``REFERENCE_S`` seconds when there is none), the
``dry`` and ``viscous`` levels of each ``SEGMENT_S`` segment (the fleet's per-pass fit,
``core.trend.pass_levels``) with their trend line, the gyro rates, ``events``, ``state``.

The anomaly state of a component (:func:`state_steps`): 0 until its first declared
anomaly, then the level of the kinds declared so far, each change counted with its
latest kind (ERROR 2 for ``both`` and ``drift``, WARN 1 otherwise, as the nodes' latched
alarms: docs/nodes.md "Alarms"). An archive has no acknowledgement, so an anomaly stays
active to the end.
"""

from __future__ import annotations

import datetime
import json
import math
import pathlib
from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.core.trend import pass_levels, SECONDS_PER_DAY, wheel_trend
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.openmct.store import GroundStore, owner

REFERENCE_S = 600.0     # s of a wheel's first data that define its nominal without calibration
SEGMENT_S = 600.0       # s per level fit of a recording (the fleet's passes are 10 min)
ERROR_KINDS = ('both', 'drift')
NOT_ANOMALIES = ('calibration_changed', 'healthy')
EVENT_FIELDS = ('detector', 'component', 'kind', 'revision', 'final', 'p_value',
                'delta_dry_nm', 'delta_viscous_nms', 'kind_shape', 'spacecraft')


def level_of(kind: str) -> int:
    """Return the state level of an event kind: 2 error, 1 warning, 0 not an anomaly."""
    if kind in NOT_ANOMALIES:
        return 0
    return 2 if kind in ERROR_KINDS else 1


def parse_epoch(value: Any) -> float | None:
    """Return an epoch as Unix seconds: a number, or an ISO 8601 time (UTC if no zone)."""
    if value is None or value == '':
        return None
    if isinstance(value, (int, float)) and math.isfinite(value):
        return float(value)
    try:
        when = datetime.datetime.fromisoformat(str(value).replace('Z', '+00:00'))
    except ValueError:
        raise ConfigError(f'epoch {value!r}: not an ISO 8601 time (e.g. '
                          f'2026-01-01T00:00:00Z) nor Unix seconds') from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.timezone.utc)
    return when.timestamp()


def event_datum(event: Mapping[str, Any]) -> dict[str, Any]:
    """Return the extra fields of an ``events`` datum from an events-file record."""
    out = {name: event.get(name) for name in EVENT_FIELDS if name in event}
    out['change'] = _number(event.get('time'))
    out['declared'] = _number(event.get('declared_time'))
    out.setdefault('final', False)
    return out


def state_steps(events: Sequence[Mapping[str, Any]]) -> tuple[list[float], list[float],
                                                              list[dict[str, Any]]]:
    """Return one component's anomaly state at each of its events' declared times."""
    current: dict[Any, str] = {}
    times, values, extra = [], [], []
    for event in sorted(events, key=lambda e: (_number(e.get('declared_time')),
                                               e.get('revision', 0))):
        change = (event.get('detector'), event.get('component'), event.get('index'),
                  event.get('time'))
        kind = str(event.get('kind'))
        if level_of(kind) == 0 and change not in current:
            continue
        current[change] = kind
        level = max((level_of(k) for k in current.values()), default=0)
        times.append(_number(event.get('declared_time')))
        values.append(float(level))
        extra.append({'kind': ', '.join(sorted({k for k in current.values()
                                                if level_of(k)})) or kind,
                      'component': event.get('component'),
                      'change': _number(event.get('time'))})
    return times, values, extra


def add_events(store: GroundStore, craft: str, events: Sequence[Mapping[str, Any]],
               components: Sequence[str] = (), start: float = 0.0) -> None:
    """Add ``events`` (events-file records) to a spacecraft: events and state points.

    Every component in ``components`` gets a state point even without events (0 from
    ``start``, the start of the data).
    """
    by_owner: dict[str, list[Mapping[str, Any]]] = {c: [] for c in components}
    for event in events:
        by_owner.setdefault(owner(str(event.get('component'))), []).append(event)
    for component, mine in by_owner.items():
        times, values, extra = state_steps(mine)
        store.add(craft, component, 'state', [start] + times, [0.0] + values,
                  [{'kind': 'none'}] + extra)
        ordered = sorted(mine, key=lambda e: _number(e.get('declared_time')))
        store.add(craft, component, 'events',
                  [_number(e.get('declared_time')) for e in ordered],
                  [float(e.get('revision', 0) or 0) for e in ordered],
                  [event_datum(e) for e in ordered])


def load_fleet(store: GroundStore, out: pathlib.Path) -> dict[str, Any]:
    """Fill ``store`` from a fleet's output folder; return summary.json's content."""
    out = pathlib.Path(out)
    summary = _json(out / 'summary.json')
    # The history's end-of-run events that a later run replaced are kept there, marked
    # ``superseded``; the view shows the current answer only (docs/contracts.md).
    events = [e for e in _json(out / 'events.json').get('events', [])
              if not e.get('superseded')]
    crafts = summary.get('spacecraft') or {}
    trend_rows = _trend_rows(out / 'trend.parquet')
    for row in trend_rows:
        mid = 0.5 * (_number(row.get('t_start')) + _number(row.get('t_end')))
        for level in ('dry', 'viscous'):
            store.add(row['spacecraft'], row['wheel'], level, [mid], [_number(row.get(level))],
                      [{'se': _number(row.get(f'{level}_se')), 'pass': row.get('pass'),
                        'samples': row.get('samples'), 'relative_to': row.get('relative_to')}])
    for craft, entry in sorted(crafts.items()):
        components = list((entry.get('components') or {}).keys())
        for component, facts in (entry.get('components') or {}).items():
            _add_trend_line(store, craft, component, (facts or {}).get('trend'), trend_rows)
        starts = [_number(r.get('t_start')) for r in trend_rows if r['spacecraft'] == craft]
        add_events(store, craft, [e for e in events if e.get('spacecraft') == craft],
                   [owner(c) for c in components], min(starts, default=0.0))
        notes = [f'not examined: {what}: {why}'
                 for what, why in (entry.get('not_examined') or {}).items()]
        store.craft(craft).notes.extend(notes)
    store.sources.append(f'fleet outputs {out}')
    return summary


def fleet_epoch(summary: Mapping[str, Any]) -> float | None:
    """Return the archive epoch a fleet's summary.json names (``epoch_utc`` or ``epoch``)."""
    for name in ('epoch_utc', 'epoch'):
        if summary.get(name) not in (None, ''):
            return parse_epoch(summary[name])
    return None


def _add_trend_line(store: GroundStore, craft: str, wheel: str,
                    trend: Mapping[str, Any] | None, rows: list[dict[str, Any]]) -> None:
    """Add the trend lines of one wheel at its fitted passes' mid times (summary's numbers).

    The passes fitted: those in the trend's reference, from its ``since_s`` (a confirmed
    step) when it has one (fleet/trends.py).
    """
    if not trend:
        return
    since = trend.get('since_s')
    since = -math.inf if since is None else _number(since)
    mine = [r for r in rows if r['spacecraft'] == craft and r['wheel'] == wheel
            and r.get('relative_to') == trend.get('relative_to')
            and _number(r.get('t_start')) >= since]
    mids = sorted(0.5 * (_number(r.get('t_start')) + _number(r.get('t_end'))) for r in mine)
    for level in ('dry', 'viscous'):
        slope, intercept = trend.get(f'{level}_slope_per_day'), trend.get(f'{level}_intercept')
        if not mids or slope is None or intercept is None:
            continue
        line = [intercept + slope * t / SECONDS_PER_DAY for t in mids]
        p = trend.get(f'{level}_p_value')
        store.add(craft, wheel, f'{level}_trend', mids, line,
                  [{'slope_per_day': slope, 'p_value': p}] * len(mids))


def load_recording(store: GroundStore, tele: Any, craft: str,
                   events: Sequence[Mapping[str, Any]],
                   calibration: Mapping[str, Any] | None = None,
                   segment_s: float = SEGMENT_S) -> None:
    """Fill ``store`` with one spacecraft's recording (see the module docstring)."""
    t = np.asarray(tele.time, dtype=float)
    for wheel, channels in tele.wheels.items():
        store.add(craft, wheel, 'speed', t, channels.speed)
        if channels.friction is None:
            continue
        store.add(craft, wheel, 'friction', t, channels.friction)
        residual, basis = wheel_residual(wheel, t, channels.speed, channels.friction,
                                         calibration)
        if residual is not None:
            store.add(craft, wheel, 'residual', t, residual,
                      [{'nominal': basis}] * t.size)
        add_segment_levels(store, craft, wheel, t, channels.speed, channels.friction,
                           segment_s)
    if tele.gyro is not None:
        for i, axis in enumerate('xyz'):
            store.add(craft, 'gyro', f'rate_{axis}', t, tele.gyro[:, i])
    components = list(tele.wheels) + (['gyro'] if tele.gyro is not None else [])
    add_events(store, craft, events, components, float(t[0]) if t.size else 0.0)
    store.sources.append(f'recording {tele.source or craft}')


def wheel_residual(wheel: str, t: np.ndarray, speed: np.ndarray, friction: np.ndarray,
                   calibration: Mapping[str, Any] | None) -> tuple[np.ndarray | None, str]:
    """Return (friction minus nominal, what the nominal is), or (None, why not)."""
    block = ((calibration or {}).get('wheels') or {}).get(wheel)
    if block is not None:
        from rwa_monitor.core.nominal import NominalWheel
        nominal = NominalWheel(block)
        residual, _ = nominal.residual(t, speed, friction)
        return np.asarray(residual, dtype=float), 'calibration'
    reference = reference_levels(t, speed, friction)
    if reference is None:
        return None, 'no reference fit'
    dry, viscous = reference
    basis = f'model (1) fit on the first {REFERENCE_S:g} s'
    return friction - model_one(speed, dry, viscous), basis


def reference_levels(t: np.ndarray, speed: np.ndarray, friction: np.ndarray,
                     seconds: float = REFERENCE_S) -> tuple[float, float] | None:
    """Return model (1)'s dry and viscous levels fitted to the first ``seconds``, or None."""
    first = np.asarray(t) <= t[0] + seconds if len(t) else np.zeros(0, bool)
    levels = pass_levels(t[first], speed[first], friction[first])
    if not (math.isfinite(levels.dry) and math.isfinite(levels.viscous)):
        return None
    return levels.dry, levels.viscous


def model_one(speed: np.ndarray, dry: float, viscous: float) -> np.ndarray:
    """Return model (1)'s friction ``-dry sign(w) - viscous w`` (eq. (1), core/friction.py)."""
    w = np.asarray(speed, dtype=float)
    return -dry * np.sign(w) - viscous * w


def add_segment_levels(store: GroundStore, craft: str, wheel: str, t: np.ndarray,
                       speed: np.ndarray, friction: np.ndarray, segment_s: float) -> None:
    """Add the dry and viscous levels of each ``segment_s`` segment, and their trend line."""
    if not len(t):
        return
    edges = np.arange(t[0], t[-1] + segment_s, segment_s)
    mids, fits = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        part = (t >= a) & (t < b)
        if np.count_nonzero(part) < 2:
            continue
        levels = pass_levels(t[part], speed[part], friction[part])
        mids.append(0.5 * (levels.t_start + levels.t_end))
        fits.append(levels)
    for level in ('dry', 'viscous'):
        values = np.array([getattr(f, level) for f in fits])
        errors = np.array([getattr(f, f'{level}_se') for f in fits])
        store.add(craft, wheel, level, mids, values,
                  [{'se': float(e), 'samples': f.samples} for e, f in zip(errors, fits)])
        trend = wheel_trend(np.array(mids), values, errors)
        if math.isfinite(trend.slope):
            line = trend.intercept + trend.slope * np.array(mids) / SECONDS_PER_DAY
            store.add(craft, wheel, f'{level}_trend', mids, line,
                      [{'slope_per_day': trend.slope, 'p_value': trend.p_value}] * len(mids))


def _trend_rows(path: pathlib.Path) -> list[dict[str, Any]]:
    if not path.is_file():
        return []
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise ConfigError(f'{path}: reading Parquet needs pyarrow (pip install '
                          f'"rwa_monitor[fleet]")') from None
    return pq.read_table(path).to_pylist()


def _json(path: pathlib.Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f'{path}: not found (is {path.parent} a fleet output folder, '
                          f'written by rwa-monitor fleet -o?)') from None
    except (OSError, ValueError) as err:
        raise ConfigError(f'{path}: unreadable: {err}') from None


def _number(value: Any) -> float:
    return float(value) if isinstance(value, (int, float)) else math.nan
