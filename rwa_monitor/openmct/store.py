"""The telemetry points the operator's view shows: a tree and a time series per point.

Tree: spacecraft -> components (wheels ``rw1``..., ``gyro``) -> points. A point's key is
``<spacecraft>.<component>.<point>`` (``sc1.rw1.speed``): Open MCT joins object keys with
``/`` in its addresses and splits ``namespace:key`` at the colon, so names are reduced to
``[A-Za-z0-9_-]`` (:func:`safe_name`). Times are telemetry seconds (``met``); the server
adds UTC where an epoch is known. Every point keeps its history in memory: a fleet's or a
recording's at start, and what the live bridge adds (the newest ``LIVE_CAPACITY`` samples
per point).

One lock guards the store: the live bridge writes from the ROS thread, the server reads
from its event loop.
"""

from __future__ import annotations

import dataclasses
import math
import re
import threading
from typing import Any

import numpy as np

# Points, their unit and meaning; ``kind``: number (a plot), state (0 nominal, 1 warning,
# 2 error: an anomaly not acknowledged), event (one datum per anomaly event).
POINTS = {
    'speed': ('number', 'rad/s', 'wheel speed'),
    'friction': ('number', 'N m', 'friction torque (project sign, docs/contracts.md)'),
    'residual': ('number', 'N m', 'friction minus the nominal model'),
    'dry': ('number', 'N m', 'dry friction level of each pass (model (1))'),
    'viscous': ('number', 'N m s/rad', 'viscous friction level of each pass (model (1))'),
    'dry_trend': ('number', 'N m', 'trend line through the dry levels'),
    'viscous_trend': ('number', 'N m s/rad', 'trend line through the viscous levels'),
    'rate_x': ('number', 'rad/s', 'gyro rate, x axis'),
    'rate_y': ('number', 'rad/s', 'gyro rate, y axis'),
    'rate_z': ('number', 'rad/s', 'gyro rate, z axis'),
    'state': ('state', '', 'anomaly state: 0 nominal, 1 warning, 2 error, not acknowledged'),
    'events': ('event', '', 'anomaly events: kind, change and declared time, revision'),
}
WHEEL_POINTS = ('speed', 'friction', 'residual', 'dry', 'viscous', 'dry_trend',
                'viscous_trend', 'state', 'events')
GYRO_POINTS = ('rate_x', 'rate_y', 'rate_z', 'state', 'events')
STATE_NAMES = {0: 'nominal', 1: 'anomaly (warning)', 2: 'anomaly (error)'}
LIVE_CAPACITY = 200_000


def safe_name(name: str) -> str:
    """Return ``name`` reduced to the characters an Open MCT key may hold safely."""
    return re.sub(r'[^A-Za-z0-9_-]', '_', str(name)) or '_'


def component_kind(component: str) -> str:
    """Return ``gyro`` for the gyro and its axes, ``wheel`` otherwise."""
    return 'gyro' if component == 'gyro' or component.startswith('gyro_') else 'wheel'


def owner(component: str) -> str:
    """Return the tree component of an event's component (gyro axes belong to the gyro)."""
    return 'gyro' if component_kind(component) == 'gyro' else component


class Series:
    """Samples of one point in time order: times (s), values, and per sample extra fields.

    Numbers live in numpy arrays (a recording's wheels hold millions of samples);
    ``extra`` (state and event points only) holds one dict per sample. ``capacity``: keep
    only the newest samples (live points).
    """

    def __init__(self, capacity: int | None = None) -> None:
        self.capacity = capacity
        self._t = np.empty(0)
        self._v = np.empty(0)
        self._n = 0
        self.extra: list[dict[str, Any]] = []

    def __len__(self) -> int:
        return self._n

    @property
    def t(self) -> np.ndarray:
        """Return the sample times (a view)."""
        return self._t[:self._n]

    @property
    def v(self) -> np.ndarray:
        """Return the sample values (a view)."""
        return self._v[:self._n]

    def extend(self, times: Any, values: Any,
               extra: list[dict[str, Any]] | None = None) -> None:
        """Append samples; samples out of time order are merged in place (stable)."""
        times = np.asarray(times, dtype=float).reshape(-1)
        values = np.asarray(values, dtype=float).reshape(-1)
        if times.size != values.size or (extra is not None and len(extra) != times.size):
            raise ValueError('times, values (and extra) must have one length')
        if not times.size:
            return
        need = self._n + times.size
        if need > self._t.size:
            size = max(need, 2 * self._t.size, 64)
            self._t = np.concatenate([self._t[:self._n], np.empty(size - self._n)])
            self._v = np.concatenate([self._v[:self._n], np.empty(size - self._n)])
        self._t[self._n:need] = times
        self._v[self._n:need] = values
        if extra is not None and not self.extra and self._n:
            self.extra = [{} for _ in range(self._n)]    # extras start: align the earlier
        if extra is not None or self.extra:
            self.extra.extend(extra if extra is not None else [{}] * times.size)
        ordered = self._n == 0 or times[0] >= self._t[self._n - 1]
        self._n = need
        if not ordered or (times.size > 1 and np.any(np.diff(times) < 0)):
            order = np.argsort(self._t[:need], kind='stable')
            self._t[:need] = self._t[order]
            self._v[:need] = self._v[order]
            if self.extra:
                self.extra = [self.extra[i] for i in order]
        if self.capacity is not None and self._n > self.capacity:
            cut = self._n - self.capacity
            self._t = self._t[cut:self._n].copy()
            self._v = self._v[cut:self._n].copy()
            self._n -= cut
            if self.extra:
                del self.extra[:cut]

    def datum(self, i: int) -> dict[str, Any]:
        """Return sample ``i`` as a datum: ``met`` (s), ``value`` and its extra fields."""
        value = float(self._v[i])
        out = {'met': float(self._t[i]), 'value': value if math.isfinite(value) else None}
        if self.extra:
            out.update(self.extra[i])
        return out

    def query(self, start: float, end: float, size: int | None = None,
              latest: bool = False) -> list[dict[str, Any]]:
        """Return the samples with ``start <= t <= end`` as datums.

        ``latest``: only the last sample at or before ``end``. ``size``: at most about
        ``2 * size`` samples, the lowest and the highest value of each of ``size`` equal
        runs of samples (a step or a spike stays visible).
        """
        t = self.t
        lo = int(np.searchsorted(t, start, 'left'))
        hi = int(np.searchsorted(t, end, 'right'))
        if latest:
            return [self.datum(hi - 1)] if hi > 0 else []
        if size is None or size <= 0 or hi - lo <= 2 * size:
            return [self.datum(i) for i in range(lo, hi)]
        values = self._v[lo:hi]
        edges = np.linspace(0, hi - lo, size + 1).astype(int)
        picked: list[int] = []
        for a, b in zip(edges[:-1], edges[1:]):
            part = values[a:b]
            if not part.size:
                continue
            if not np.isfinite(part).any():
                picked.append(lo + a)
                continue
            low, high = int(np.nanargmin(part)), int(np.nanargmax(part))
            picked.extend(lo + a + k for k in sorted({low, high}))
        return [self.datum(i) for i in picked]

    def span(self) -> tuple[float, float] | None:
        """Return the first and last time, or None when empty."""
        return (float(self._t[0]), float(self._t[self._n - 1])) if self._n else None


@dataclasses.dataclass
class Component:
    """One wheel or the gyro of a spacecraft, with the points it has data for."""

    key: str
    name: str
    kind: str
    points: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class Spacecraft:
    """One spacecraft of the tree; ``notes`` (e.g. what was not examined) go on the page."""

    key: str
    name: str
    components: dict[str, Component] = dataclasses.field(default_factory=dict)
    notes: list[str] = dataclasses.field(default_factory=list)
    live: bool = False


class GroundStore:
    """The tree and every point's series; see the module docstring."""

    def __init__(self, epoch_unix_s: float | None = None, live: bool = False) -> None:
        self.epoch_unix_s = epoch_unix_s
        self.live = live
        self.spacecraft: dict[str, Spacecraft] = {}
        self.series: dict[str, Series] = {}
        self.version = 0            # grows when the tree changes (the page adds objects)
        self.lock = threading.RLock()
        self._pending: list[tuple[str, dict[str, Any]]] = []
        self.sources: list[str] = []

    def craft(self, name: str, *, live: bool = False) -> Spacecraft:
        """Return a spacecraft of the tree, added if new."""
        with self.lock:
            key = safe_name(name)
            sc = self.spacecraft.get(key)
            if sc is None:
                sc = self.spacecraft[key] = Spacecraft(key, str(name), live=live)
                self.version += 1
            return sc

    def point(self, craft: str, component: str, point: str, *, live: bool = False
              ) -> Series:
        """Return the series of a point, adding spacecraft, component and point as needed."""
        if point not in POINTS:
            raise ValueError(f'unknown point {point!r}; known: {", ".join(POINTS)}')
        with self.lock:
            ckey = safe_name(craft)
            sc = self.craft(craft, live=live)
            kkey = safe_name(component)
            comp = sc.components.get(kkey)
            if comp is None:
                comp = sc.components[kkey] = Component(kkey, str(component),
                                                       component_kind(component))
                self.version += 1
            if point not in comp.points:
                order = WHEEL_POINTS if comp.kind == 'wheel' else GYRO_POINTS
                comp.points.append(point)
                comp.points.sort(key=lambda p: order.index(p) if p in order else len(order))
                self.version += 1
            key = f'{ckey}.{kkey}.{point}'
            series = self.series.get(key)
            if series is None:
                series = self.series[key] = Series(LIVE_CAPACITY if live or sc.live
                                                   else None)
            return series

    def add(self, craft: str, component: str, point: str, times: Any, values: Any,
            extra: list[dict[str, Any]] | None = None, *, live: bool = False) -> None:
        """Append samples to a point (live ones are also queued for the WebSocket)."""
        with self.lock:
            series = self.point(craft, component, point, live=live)
            series.extend(times, values, extra)
            if live:
                key = f'{safe_name(craft)}.{safe_name(component)}.{point}'
                times = np.asarray(times, dtype=float).reshape(-1)
                values = np.asarray(values, dtype=float).reshape(-1)
                for t, v, x in zip(times, values, extra or [{}] * times.size):
                    datum = {'met': float(t), 'value': float(v) if math.isfinite(v) else None,
                             **x}
                    self._pending.append((key, self.stamp(datum)))

    def stamp(self, datum: dict[str, Any]) -> dict[str, Any]:
        """Add UTC (ms since 1970) beside each telemetry time of a datum, epoch known."""
        if self.epoch_unix_s is not None:
            for name in ('met', 'change', 'declared'):
                value = datum.get(name)
                if isinstance(value, (int, float)) and math.isfinite(value):
                    key = 'utc' if name == 'met' else f'{name}_utc'
                    datum[key] = (self.epoch_unix_s + value) * 1000.0
        return datum

    def take_pending(self) -> list[tuple[str, dict[str, Any]]]:
        """Return and forget the live samples not yet sent."""
        with self.lock:
            out, self._pending = self._pending, []
            return out

    def span(self) -> tuple[float, float] | None:
        """Return the first and last time over every point, or None without data."""
        with self.lock:
            spans = [s.span() for s in self.series.values()]
        spans = [s for s in spans if s is not None]
        if not spans:
            return None
        return min(s[0] for s in spans), max(s[1] for s in spans)

    def dictionary(self) -> dict[str, Any]:
        """Return the tree as JSON for the page (``/api/dictionary``)."""
        with self.lock:
            span = self.span()
            return {
                'version': self.version, 'live': self.live,
                'epoch_unix_s': self.epoch_unix_s, 'sources': list(self.sources),
                'span_s': list(span) if span else None,
                'points': {name: {'kind': kind, 'unit': unit, 'description': text}
                           for name, (kind, unit, text) in POINTS.items()},
                'states': {str(k): v for k, v in STATE_NAMES.items()},
                'spacecraft': [
                    {'key': sc.key, 'name': sc.name, 'notes': sc.notes, 'live': sc.live,
                     'components': [{'key': c.key, 'name': c.name, 'kind': c.kind,
                                     'points': list(c.points)}
                                    for c in sorted(sc.components.values(),
                                                    key=_component_order)]}
                    for sc in sorted(self.spacecraft.values(), key=lambda s: s.key)]}

    def history(self, key: str, start: float, end: float, size: int | None = None,
                latest: bool = False) -> list[dict[str, Any]]:
        """Return a point's samples in ``[start, end]`` (KeyError for an unknown point)."""
        with self.lock:
            return [self.stamp(d) for d in self.series[key].query(start, end, size, latest)]


def _component_order(component: Component) -> tuple:
    return (component.kind == 'gyro', component.key)
