"""Acceptance of a gyro / star-tracker row, shared by every gyro detector (docs/vsadc.md).

One rule for :class:`~rwa_monitor.core.vsadc.VsadcDetector` and
:class:`~rwa_monitor.core.gyro_diagnosis.GyroDiagnosis`: a non-finite stamp
(``non_finite``) or one not after the last accepted stamp (``non_increasing_time``) drops
the row; a gyro (or reference) that is not three values, or a row no monitored axis can
use, is ``bad_gyro``; a row without a star-tracker rate (invalid or missing quaternion,
first quaternion after a gap) is ``held``: the axes keep their labels, so a star tracker
that stops cannot turn into a fault. The rest is ``accepted``; an axis that cannot use an
accepted row (a value not finite or beyond MAX_ABS_RATE_RAD_S) counts it in
``bad_axis_<a>``. :class:`GyroAxes` is what the gyro detectors
share around it: one channel per axis and the protocol's properties.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

from rwa_monitor.core import keys
from rwa_monitor.core.attitude import StarTrackerRate
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_state import (
    check_counts, check_keys, check_parameters, check_type, GyroRowsState, require)
from rwa_monitor.core.records import Scalar

_BUCKETS = ('accepted', 'held', 'bad_gyro', 'non_finite', 'non_increasing_time')

AXES = ('x', 'y', 'z')
# A body rate at or beyond this is no measurement (gyro ranges end below 20 rad/s): the
# axis does not use the row and counts it (``bad_axis_<a>``). A fixed rule, not a
# parameter: its only job is to keep values of 1e300 from overflowing the windows' sums.
MAX_ABS_RATE_RAD_S = 1.0e3


def check_axes(axes: Sequence[str]) -> tuple[str, ...]:
    """Return ``axes`` as a tuple if it is a non-empty subset of x, y, z, else ValueError."""
    if isinstance(axes, str) or not axes or any(a not in AXES for a in axes):
        raise ValueError(f'axes must be a non-empty subset of x, y, z; got {axes!r}')
    return tuple(axes)


class GyroRows:
    """The row filter and its counters (module docstring): ``accept`` then ``star_rate``."""

    def __init__(self, axes: Sequence[str], *, max_gap: float, norm_tolerance: float) -> None:
        self.axes = check_axes(axes)
        self.index = [AXES.index(a) for a in self.axes]
        self.star_tracker = StarTrackerRate(max_gap=max_gap, norm_tolerance=norm_tolerance)
        self.reset()

    def reset(self) -> None:
        """Forget the last stamp and the star-tracker differencer; zero the counters."""
        self.star_tracker.reset()
        self.rows = self.accepted = self.held = self.bad_gyro = 0
        self.non_finite = self.non_increasing_time = 0
        self.bad_axis = {a: 0 for a in self.axes}
        self.last_time = -math.inf

    def accept(self, t: float, gyro: Sequence[float], ref: Sequence[float] | None = None
               ) -> bool:
        """Count the row; return False (counted by reason) if its stamp or shape is bad."""
        self.rows += 1
        if not math.isfinite(t):
            self.non_finite += 1
            return False
        if t <= self.last_time:
            self.non_increasing_time += 1
            return False
        if len(gyro) != 3 or (ref is not None and len(ref) != 3):
            self.bad_gyro += 1
            return False
        return True

    def star_rate(self, t: float, q: Sequence[float] | None
                  ) -> tuple[float, float, float] | None:
        """Take the row's stamp and quaternion; return the star-tracker rate or None (held)."""
        self.last_time = t
        rate = None if q is None else self.star_tracker.update(t, q)
        if rate is None:
            self.held += 1
        else:
            self.accepted += 1
        return rate

    @property
    def counters(self) -> dict[str, int]:
        """Return rows seen, accepted, held and dropped by reason."""
        st = self.star_tracker
        return {'rows': self.rows, 'accepted': self.accepted, 'held': self.held,
                'bad_gyro': self.bad_gyro, keys.NON_FINITE: self.non_finite,
                keys.NON_INCREASING_TIME: self.non_increasing_time,
                'invalid_quaternions': st.invalid, 'star_tracker_gaps': st.gaps,
                **{f'bad_axis_{a}': n for a, n in self.bad_axis.items()}}

    def record(self) -> GyroRowsState:
        """Return the filter's state: counters, last stamp, star-tracker differencer."""
        return GyroRowsState(self.rows, self.accepted, self.held, self.bad_gyro,
                             self.non_finite, self.non_increasing_time, dict(self.bad_axis),
                             self.last_time, self.star_tracker.record())

    def check_record(self, record: GyroRowsState, path: str) -> None:
        """Refuse negative counters, rows not counted once each, other axes, a bad stamp."""
        check_type(record, GyroRowsState, path)
        check_counts(record, ('rows',) + _BUCKETS, path)
        require(sum(getattr(record, b) for b in _BUCKETS) == record.rows, f'{path}.rows',
                'differs from the sum of ' + ', '.join(_BUCKETS))
        check_keys(record.bad_axis, self.axes, f'{path}.bad_axis')
        for axis, n in record.bad_axis.items():
            require(type(n) is int and n >= 0, f'{path}.bad_axis[{axis}]',
                    f'expected a count >= 0, got {n!r}')
        require(record.last_time < math.inf, f'{path}.last_time', 'expected -inf or finite')
        self.star_tracker.check_record(record.star_tracker, f'{path}.star_tracker')
        require(record.star_tracker.previous_time <= record.last_time,
                f'{path}.star_tracker.previous_time', 'after the last row')

    def restore(self, record: GyroRowsState) -> None:
        """Put ``record`` back (checked first: RecordError, and the filter unchanged)."""
        self.check_record(record, type(record).__name__)
        self.star_tracker.restore(record.star_tracker)
        for name in ('rows',) + _BUCKETS:
            setattr(self, name, getattr(record, name))
        self.bad_axis = {a: record.bad_axis[a] for a in self.axes}
        self.last_time = record.last_time


class GyroAxes:
    """A gyro detector's common part: the row filter, one channel per axis, the properties.

    A subclass builds its channels (objects with ``reset()``, ``state``, ``record()``,
    ``check_record`` and ``restore``) and writes ``update`` (core/protocol.py
    ``GyroDetector``), setting ``_last_event``, and its ``state()`` / ``restore`` from the
    parts below.
    """

    def __init__(self, rows: GyroRows, channels: list, params: dict[str, Any]) -> None:
        self._rows = rows
        self.axes = rows.axes
        self.channels = channels
        self._params = params

    def reset(self) -> None:
        """Reset every axis, the row filter (star-tracker differencer) and the counters."""
        for ch in self.channels:
            ch.reset()
        self._rows.reset()
        self._last_event: AnomalyEvent | None = None

    @property
    def states(self) -> dict[str, int]:
        """Return axis -> current label."""
        return {a: ch.state for a, ch in zip(self.axes, self.channels)}

    @property
    def params(self) -> dict[str, Any]:
        """Return the keyword parameters (checked; the axis ones are every axis's)."""
        return dict(self._params)

    @property
    def counters(self) -> dict[str, int]:
        """Return rows seen, accepted, held and rejected by cause."""
        return self._rows.counters

    @property
    def last_event(self) -> AnomalyEvent | None:
        """Return the last event returned by ``update`` (None before any)."""
        return self._last_event

    def _state_parameters(self) -> dict[str, Scalar]:
        """Return the checked parameters a state must have been made with (axes aside).

        Each value as the part that uses it checked it: an axis, the star-tracker
        differencer or the detector itself (``sigma_window: auto`` is the window length).
        """
        owners = (self.channels[0], self._rows.star_tracker, self)
        return {name: getattr(next(o for o in owners if hasattr(o, name)), name)
                for name in self._params if name != 'axes'}

    def _axis_records(self) -> dict[str, Any]:
        return {a: ch.record() for a, ch in zip(self.axes, self.channels)}

    def _check_state(self, state: Any, cls: type) -> None:
        """Refuse a state of another class, parameters or axes, or inconsistent parts."""
        path = cls.__name__
        check_type(state, cls, path)
        check_parameters(state.parameters, self._state_parameters(), path)
        check_keys(state.axes, self.axes, f'{path}.axes')
        for axis, ch in zip(self.axes, self.channels):
            ch.check_record(state.axes[axis], f'{path}.axes[{axis}]')
        self._rows.check_record(state.rows, f'{path}.rows')
        require(state.last_event is None or type(state.last_event) is AnomalyEvent,
                f'{path}.last_event', 'expected an AnomalyEvent or None')

    def _restore_state(self, state: Any) -> None:
        """Put a state checked by :meth:`_check_state` back (cannot fail)."""
        for axis, ch in zip(self.axes, self.channels):
            ch.restore(state.axes[axis])
        self._rows.restore(state.rows)
        self._last_event = state.last_event
