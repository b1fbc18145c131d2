"""VSADC on the three gyro axes from raw telemetry (vsadc-gyro-drift paper, ``feature: paper``).

:class:`VsadcDetector` feeds the rows accepted by the shared row filter
(core/gyro_rows.py) to one :class:`~rwa_monitor.core.vsadc_axis.VsadcAxis` per axis (the
algorithm, Alg. 1, and every choice it leaves open: that module and docs/vsadc.md);
:func:`make_event` turns an axis's label change into an AnomalyEvent.
"""

from __future__ import annotations

from typing import Sequence

from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_rows import AXES, GyroAxes, GyroRows, MAX_ABS_RATE_RAD_S
from rwa_monitor.core.gyro_state import VsadcState
from rwa_monitor.core.params import AUTO
from rwa_monitor.core.vsadc_axis import (  # noqa: F401  (the labels, for importers)
    BIAS, DRIFT, HEALTHY, STATE_NAMES, Transition, VsadcAxis)

_NO_REFERENCE = (0.0, 0.0, 0.0)
DETECTOR = 'vsadc'


class VsadcDetector(GyroAxes):
    """VSADC on the three gyro axes from raw telemetry: gyro, star-tracker q, reference rate.

    A gyro detector (:class:`~rwa_monitor.core.protocol.GyroDetector`): ``update(t, gyro,
    q, ref)`` per row returns the AnomalyEvents of label changes. Bad input never reaches
    the axes: the row filter shared with every gyro detector
    (:mod:`rwa_monitor.core.gyro_rows`) drops and counts bad stamps and shapes and holds
    the axes on rows without a star-tracker rate, so a star tracker that stops cannot turn
    into a drift. A non-finite gyro or reference value is rejected per axis
    (``bad_axis_<a>``): the other axes still take the row; a row no axis can use counts as
    ``bad_gyro``.

    Parameters
    ----------
    window, sigma_window, distance_threshold, reference_window, margin, exit_limit, \
exit_margin, hold, nominal_tracking, freeze_fraction, adaptive, recovery_fraction
        Per-axis parameters of :class:`VsadcAxis` (meanings and bounds: core/schema.py
        ``VSADC``, docs/parameters.md); ``sigma_window`` and ``reference_window`` take
        :data:`~rwa_monitor.core.params.AUTO` (= ``window``).
    max_gap : float
        Seconds between star-tracker samples above which the star-tracker rate restarts.
    norm_tolerance : float
        Quaternions whose norm is off 1 by more than this are rejected.
    axes : sequence of str
        The gyro axes monitored, a non-empty subset of ``('x', 'y', 'z')``.

    Examples
    --------
    >>> det = VsadcDetector(window=20, reference_window=20)
    >>> det.update(0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0])
    []
    >>> det.update(float('nan'), [0.0, 0.0, 0.0], None, None)
    []
    >>> det.counters['accepted'], det.counters['held'], det.counters['non_finite']
    (0, 1, 1)
    """

    def __init__(self, *, window: int = 200, distance_threshold: float = 1.5e-5,
                 sigma_window: int | str = AUTO, reference_window: int | str = 1200,
                 margin: float = 1.5, exit_limit: str = 'max', exit_margin: float = 1.25,
                 hold: int = 1, nominal_tracking: int = 0, freeze_fraction: float = 0.5,
                 adaptive: bool = True, recovery_fraction: float = 0.75,
                 max_gap: float = 1.0, norm_tolerance: float = 0.1,
                 axes: Sequence[str] = AXES) -> None:
        axis_parameters = dict(
            window=window, distance_threshold=distance_threshold, sigma_window=sigma_window,
            reference_window=reference_window, margin=margin, exit_limit=exit_limit,
            exit_margin=exit_margin, hold=hold, nominal_tracking=nominal_tracking,
            freeze_fraction=freeze_fraction, adaptive=adaptive,
            recovery_fraction=recovery_fraction)
        rows = GyroRows(axes, max_gap=max_gap, norm_tolerance=norm_tolerance)
        super().__init__(rows, [VsadcAxis(**axis_parameters) for _ in rows.axes],
                         {'max_gap': max_gap, 'norm_tolerance': norm_tolerance,
                          'axes': rows.axes, **axis_parameters})
        self.reset()

    def update(self, t: float, gyro: Sequence[float], q: Sequence[float] | None,
               ref: Sequence[float] | None = None,
               index: int | None = None) -> list[AnomalyEvent]:
        """Take one row; return the events of every axis whose label changed.

        As :meth:`rwa_monitor.core.protocol.GyroDetector.update`; ``ref`` None is a zero
        reference rate (the ``reference_rate`` default).
        """
        rows = self._rows
        index = rows.rows if index is None else index
        if not rows.accept(t, gyro, ref):
            return []
        g, r = gyro, _NO_REFERENCE if ref is None else ref
        usable = [_plausible(g[i]) and _plausible(r[i]) for i in rows.index]
        if not any(usable):
            rows.bad_gyro += 1
            return []
        rate = rows.star_rate(t, q)
        if rate is None:
            return []
        stamp = (t, index)
        events = []
        for axis, i, ch, ok in zip(self.axes, rows.index, self.channels, usable):
            if not ok or not _plausible(rate[i]):
                rows.bad_axis[axis] += 1
                continue
            tr = ch.update(r[i] - rate[i], r[i] - g[i], stamp)
            if tr is not None:
                events.append(make_event(axis, tr))
        if events:
            self._last_event = events[-1]
        return events

    def state(self) -> VsadcState:
        """Return the detector's state as a typed record (core/gyro_state.py).

        ``records.encode(det.state())``, then ``records.decode`` and :meth:`restore` into
        a detector built with the same parameters, resumes exactly where this one stands.
        """
        return VsadcState(self._state_parameters(), self._axis_records(),
                          self._rows.record(), self._last_event)

    def restore(self, state: VsadcState) -> None:
        """Resume from ``state``, checked whole first.

        A state of other parameters, axes or window lengths, or inconsistent with itself,
        raises :class:`~rwa_monitor.core.records.RecordError` naming the field, and the
        detector is left as it was.
        """
        self._check_state(state, VsadcState)
        self._restore_state(state)


def _plausible(value: float) -> bool:
    """Return True for a finite rate below MAX_ABS_RATE_RAD_S (False for NaN too)."""
    return abs(value) < MAX_ABS_RATE_RAD_S


def make_event(axis: str, tr: Transition) -> AnomalyEvent:
    """Return the AnomalyEvent of a transition (kind = the new state's name)."""
    onset = tr.onset if tr.onset is not None else tr.declared
    return AnomalyEvent(
        detector=DETECTOR, component=f'gyro_{axis}', kind=STATE_NAMES[tr.state],
        time=float(onset[0]), index=int(onset[1]), declared_time=float(tr.declared[0]),
        declared_index=int(tr.declared[1]),
        details={keys.PREVIOUS_KIND: STATE_NAMES[tr.previous], keys.DISTANCE: tr.distance,
                 keys.DISTANCE_SIGMA: tr.sigma})
