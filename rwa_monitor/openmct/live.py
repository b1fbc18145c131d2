"""Live points from decoded ROS messages (the ROS side: nodes/openmct_bridge.py).

A namespace is a spacecraft (``/sat1/telemetry/wheels`` -> ``sat1``; the root namespace
-> ``ROOT_NAME``). :class:`LiveFeed` gathers samples per point and moves them into the
store on :meth:`LiveFeed.flush` (a few times a second), one ``add`` per point.

- wheels: ``speed``, ``friction`` and ``residual`` (against the ``--calibration``
  nominal, else against model (1) fitted to the wheel's first ``REFERENCE_S`` seconds,
  as for a recording: history.wheel_residual; until that fit exists there is no residual);
- gyro: ``rate_x/y/z``;
- ``events``: each anomaly event as the events file writes it;
- ``state``, per component, the nodes' latched alarms (docs/nodes.md "Alarms"): an event
  of an anomaly kind latches its level for its (node, component) at once; a
  ``/diagnostics`` status of that node and component with ``latched_alarms`` > 0 keeps
  (or sets) the latched kind's level; one without it, stamped after the event's
  declaration, means the operator acknowledged it (``~/acknowledge``): the latch is
  released. The state is the highest latched level over the component's nodes.
"""

from __future__ import annotations

import math
import threading
from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.openmct import history
from rwa_monitor.openmct.store import GroundStore, owner

ROOT_NAME = 'live'


def craft_of_namespace(namespace: str) -> str:
    """Return the spacecraft name of a ROS namespace (``/sat1`` -> ``sat1``)."""
    name = namespace.strip('/')
    return name or ROOT_NAME


def craft_of_status(status_name: str) -> tuple[str, str]:
    """Return (spacecraft, node) of a status named ``"[ns/]node: check"``."""
    node = status_name.split(':', 1)[0].strip().strip('/')
    namespace = node.rsplit('/', 1)[0] if '/' in node else ''
    return craft_of_namespace(namespace), node


class _Wheel:
    """One live wheel's residual: the nominal known, or the first samples until fitted."""

    def __init__(self, block: Mapping[str, Any] | None) -> None:
        self.nominal = None
        if block is not None:
            from rwa_monitor.core.nominal import NominalWheel
            self.nominal = NominalWheel(block)
        self.reference: tuple[float, float] | None = None
        self.first: list[tuple[float, float, float]] = []

    def residuals(self, t: float, speed: float, friction: float
                  ) -> tuple[list[float], list[float], bool]:
        """Return (times, residuals, back-filled) this sample makes known.

        Once the reference is fitted, the residuals of the samples it was fitted on come
        back together (back-filled: history only, so that a live plot never draws
        backwards).
        """
        if self.nominal is not None:
            value, _ = self.nominal.residual_one(t, speed, friction)
            return [t], [value], False
        if self.reference is not None:
            return [t], [friction - float(history.model_one(speed, *self.reference))], False
        self.first.append((t, speed, friction))
        if t - self.first[0][0] < history.REFERENCE_S:
            return [], [], False
        ts, ws, fs = (np.array(c) for c in zip(*self.first))
        self.first = []
        self.reference = history.reference_levels(ts, ws, fs)
        if self.reference is None:      # not excited enough: try the next REFERENCE_S
            return [], [], False
        return list(ts), list(fs - history.model_one(ws, *self.reference)), True


class LiveFeed:
    """Decoded live messages -> store points; see the module docstring."""

    def __init__(self, store: GroundStore,
                 calibration: Mapping[str, Any] | None = None) -> None:
        self.store = store
        self.calibration = calibration or {}
        self._lock = threading.Lock()
        self._buffers: dict[tuple[str, str, str], tuple[list, list, list]] = {}
        self._backfill: list[tuple[str, str, list, list]] = []
        self._wheels: dict[tuple[str, str], _Wheel] = {}
        self._latched: dict[tuple[str, str, str], tuple[int, str, float]] = {}
        self._state: dict[tuple[str, str], int] = {}
        self.counters = {'wheels': 0, 'gyro': 0, 'events': 0, 'statuses': 0}

    def _put(self, craft: str, component: str, point: str, t: float, value: float,
             extra: dict[str, Any] | None = None) -> None:
        times, values, extras = self._buffers.setdefault((craft, component, point),
                                                         ([], [], []))
        times.append(t)
        values.append(value)
        extras.append(extra if extra is not None else {})

    def wheels(self, namespace: str, t: float, names: Sequence[str],
               speeds: Sequence[float], frictions: Sequence[float] | None) -> None:
        """Take one wheels message (JointState: names, velocity, effort)."""
        craft = craft_of_namespace(namespace)
        with self._lock:
            self.counters['wheels'] += 1
            for i, name in enumerate(names):
                self._put(craft, name, 'speed', t, float(speeds[i]))
                if frictions is None:
                    continue
                friction = float(frictions[i])
                self._put(craft, name, 'friction', t, friction)
                wheel = self._wheels.get((craft, name))
                if wheel is None:
                    block = (self.calibration.get('wheels') or {}).get(name)
                    wheel = self._wheels[(craft, name)] = _Wheel(block)
                times, values, backfill = wheel.residuals(t, float(speeds[i]), friction)
                if backfill:
                    self._backfill.append((craft, name, times, values))
                else:
                    for rt, rv in zip(times, values):
                        self._put(craft, name, 'residual', rt, rv)

    def gyro(self, namespace: str, t: float, rates: Sequence[float]) -> None:
        """Take one gyro message (Imu angular velocity, rad/s)."""
        craft = craft_of_namespace(namespace)
        with self._lock:
            self.counters['gyro'] += 1
            for axis, rate in zip('xyz', rates):
                self._put(craft, 'gyro', f'rate_{axis}', t, float(rate))

    def event(self, namespace: str, node: str, record: Mapping[str, Any]) -> None:
        """Take one anomaly event, an events-file record that ``node`` published."""
        craft = craft_of_namespace(namespace)
        component = str(record.get('component'))
        declared = float(record.get('declared_time', math.nan))
        with self._lock:
            self.counters['events'] += 1
            self._put(craft, owner(component), 'events', declared,
                      float(record.get('revision', 0) or 0), history.event_datum(record))
            level = history.level_of(str(record.get('kind')))
            if level:
                self._latched[(craft, node, component)] = (level, str(record.get('kind')),
                                                           declared)
                self._state.setdefault((craft, owner(component)), 0)
                self._update_state(craft, component, declared)

    def status(self, stamp: float, name: str, hardware_id: str,
               fields: Mapping[str, Any]) -> None:
        """Take one status of /diagnostics: its array stamp, name, hardware id, values."""
        craft, node = craft_of_status(name)
        key = (craft, node, hardware_id)
        with self._lock:
            self.counters['statuses'] += 1
            if (craft, owner(hardware_id)) not in self._state:
                return     # not a wheel or gyro seen on the telemetry (a node's own check)
            latched = fields.get('latched_alarms')
            if isinstance(latched, (int, float)) and latched > 0:
                kind = str(fields.get('latched_kind', 'anomaly'))
                old = self._latched.get(key)
                self._latched[key] = (history.level_of(kind) or 1, kind,
                                      old[2] if old else stamp)
                self._update_state(craft, hardware_id, stamp)
            else:
                if key in self._latched and stamp > self._latched[key][2]:
                    del self._latched[key]          # acknowledged by the operator
                self._update_state(craft, hardware_id, stamp)

    def _update_state(self, craft: str, component: str, t: float) -> None:
        mine = owner(component)
        entries = [v for (c, _, comp), v in self._latched.items()
                   if c == craft and owner(comp) == mine]
        level = max((v[0] for v in entries), default=0)
        kinds = ', '.join(sorted({v[1] for v in entries})) or 'none'
        self._state[(craft, mine)] = level
        self._put(craft, mine, 'state', t, float(level), {'kind': kinds})

    def flush(self) -> None:
        """Move the gathered samples into the store (queued there for the WebSocket)."""
        with self._lock:
            buffers, self._buffers = self._buffers, {}
            backfill, self._backfill = self._backfill, []
            new_states = {}
            for (craft, component, point), (times, _, _) in buffers.items():
                if point != 'state' and (craft, owner(component)) not in self._state:
                    new_states.setdefault((craft, owner(component)), times[0])
            for craft_component in new_states:   # every live component shows a state
                self._state[craft_component] = 0
        for (craft, component), t in new_states.items():
            self.store.add(craft, component, 'state', [t], [0.0], [{'kind': 'none'}],
                           live=True)
        for craft, wheel, times, values in backfill:
            self.store.craft(craft, live=True)
            self.store.add(craft, wheel, 'residual', times, values)
        for (craft, component, point), (times, values, extras) in buffers.items():
            self.store.add(craft, component, point, times, values, extras, live=True)
