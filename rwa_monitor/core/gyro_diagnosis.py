"""Gyro drift/bias diagnosis of three axes on the gyro-minus-star-tracker residual.

:class:`GyroDiagnosis` is the default gyro detector (``feature: residual``, docs/vsadc.md):
rows accepted by the shared row filter (core/gyro_rows.py), the residual of each axis
(trapezoidal gyro mean minus star-tracker rate) fed to one
:class:`~rwa_monitor.core.gyro_residual.ResidualAxis` each (the algorithm: Algorithm 1 of
the vsadc-gyro-drift paper on block means, see that module). :func:`make_gyro_detector`
builds the detector of a VSADC parameter block, this one or the paper's VsadcDetector.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_residual import AXIS_DEFAULTS, ResidualAxis
from rwa_monitor.core.gyro_rows import AXES, GyroAxes, GyroRows
from rwa_monitor.core.gyro_state import check_keys, GyroDiagnosisState, require
from rwa_monitor.core.params import check_real
from rwa_monitor.core.schema import VSADC, vsadc_kwargs
from rwa_monitor.core.vsadc import make_event, VsadcDetector

#: |gyro| at or above this (rad/s) is a saturated sample: held and counted, never a fault.
DEFAULT_SATURATION_RAD_S = VSADC['saturation_rad_s'].default
_D = VSADC.defaults()   # keyword defaults: the schema's (one home, docs/parameters.md)


class GyroDiagnosis(GyroAxes):
    """Drift/bias diagnosis of the three gyro axes from gyro rates and star-tracker q.

    A gyro detector (:class:`~rwa_monitor.core.protocol.GyroDetector`): ``update(t, gyro,
    q, ref=None, index=None)`` per row returns AnomalyEvents (detector ``vsadc``,
    components ``gyro_x/y/z``). Bad input never reaches an axis: the row filter shared
    with every gyro detector (:mod:`rwa_monitor.core.gyro_rows`) drops bad stamps and
    shapes and holds the axes on rows without a star-tracker rate; per axis, a non-finite
    gyro value (``bad_axis_<a>``) or one at or above ``saturation_rad_s``
    (``saturated_<a>``) leaves that axis's label unchanged. ``ref`` is accepted and ignored
    (the residual needs no guidance reference).

    Parameters
    ----------
    calibration : mapping or None
        Axis -> the dict of :func:`~rwa_monitor.core.gyro_calibration.calibrate_gyro`
        (the ``gyro:`` block of calibration.yaml); None or a missing axis: defaults.
    saturation_rad_s : float
        A gyro rate at or above this (rad/s) is saturated: held and counted.
    max_gap, norm_tolerance : float
        Star-tracker rate: restart after a gap (s); quaternion norm tolerance.
    axes : sequence of str
        The gyro axes monitored, a non-empty subset of ``('x', 'y', 'z')``.
    block, nominal_blocks, tracking_blocks, guard_blocks, fit_blocks, decide_blocks, \
confirm_blocks, max_wait_blocks, decide_chi2, freeze_fraction, recovery_fraction, \
cusum_threshold, cusum_allowance
        Per-axis parameters of :class:`ResidualAxis`: the ``residual_*`` parameters of
        core/schema.py ``VSADC`` (docs/parameters.md), without the prefix.

    Examples
    --------
    >>> det = GyroDiagnosis(block=4, nominal_blocks=2)
    >>> det.update(0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    []
    >>> det.update(0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    []
    >>> det.counters['held'], det.counters['non_increasing_time']
    (1, 1)
    """

    def __init__(self, *, calibration: Mapping[str, Mapping[str, Any]] | None = None,
                 saturation_rad_s: float = _D['saturation_rad_s'],
                 max_gap: float = _D['max_gap'], norm_tolerance: float = _D['norm_tolerance'],
                 axes: Sequence[str] = AXES, block: int = _D['residual_block'],
                 nominal_blocks: int = _D['residual_nominal_blocks'],
                 tracking_blocks: int = _D['residual_tracking_blocks'],
                 guard_blocks: int = _D['residual_guard_blocks'],
                 fit_blocks: int = _D['residual_fit_blocks'],
                 decide_blocks: int = _D['residual_decide_blocks'],
                 confirm_blocks: int = _D['residual_confirm_blocks'],
                 max_wait_blocks: int = _D['residual_max_wait_blocks'],
                 decide_chi2: float = _D['residual_decide_chi2'],
                 freeze_fraction: float = _D['residual_freeze_fraction'],
                 recovery_fraction: float = _D['residual_recovery_fraction'],
                 cusum_threshold: float = _D['residual_cusum_threshold'],
                 cusum_allowance: float = _D['residual_cusum_allowance']) -> None:
        axis_parameters = dict(
            block=block, nominal_blocks=nominal_blocks, tracking_blocks=tracking_blocks,
            guard_blocks=guard_blocks, fit_blocks=fit_blocks, decide_blocks=decide_blocks,
            confirm_blocks=confirm_blocks, max_wait_blocks=max_wait_blocks,
            decide_chi2=decide_chi2, freeze_fraction=freeze_fraction,
            recovery_fraction=recovery_fraction, cusum_threshold=cusum_threshold,
            cusum_allowance=cusum_allowance)
        rows = GyroRows(axes, max_gap=max_gap, norm_tolerance=norm_tolerance)
        self.saturation_rad_s = check_real('saturation_rad_s', saturation_rad_s, 0.0,
                                           low_open=True)
        calibration = calibration or {}
        channels = [ResidualAxis(calibration.get(a), **axis_parameters) for a in rows.axes]
        super().__init__(rows, channels, {
            'saturation_rad_s': self.saturation_rad_s, 'max_gap': max_gap,
            'norm_tolerance': norm_tolerance, 'axes': rows.axes,
            **{k: getattr(channels[0], k) for k in AXIS_DEFAULTS}})
        self.reset()

    def reset(self) -> None:
        """Reset every axis, the row filter, the counters and the previous gyro sample."""
        super().reset()
        self.saturated = {a: 0 for a in self.axes}
        self.saturated_now = {a: False for a in self.axes}
        self._prev_gyro: tuple[float, float, float] | None = None
        self._prev_time = -math.inf

    @property
    def counters(self) -> dict[str, int]:
        """Return rows seen, accepted, held and rejected by cause, and saturated per axis."""
        out = super().counters
        out.update({f'saturated_{a}': n for a, n in self.saturated.items()})
        return out

    def update(self, t: float, gyro: Sequence[float], q: Sequence[float] | None,
               ref: Sequence[float] | None = None,
               index: int | None = None) -> list[AnomalyEvent]:
        """Take one row; return the events of every axis whose label changed.

        As :meth:`rwa_monitor.core.protocol.GyroDetector.update`; ``ref`` is ignored (the
        gyro-minus-star-tracker residual needs no reference).
        """
        rows = self._rows
        index = rows.rows if index is None else index
        if not rows.accept(t, gyro):
            return []
        g = tuple(float(v) for v in gyro)
        st_prev = rows.star_tracker.last_time
        rate = rows.star_rate(t, q)
        prev, prev_time = self._prev_gyro, self._prev_time
        self._prev_gyro, self._prev_time = g, t
        if rate is None:
            return []
        trapezoid = prev is not None and prev_time == st_prev
        stamp = (t, index)
        events = []
        for axis, i, ch in zip(self.axes, rows.index, self.channels):
            now = g[i]
            before = prev[i] if trapezoid else now
            if not math.isfinite(now):
                rows.bad_axis[axis] += 1  # rejected on this axis only (issue 17)
                continue
            if not math.isfinite(before):
                continue
            sat = max(abs(now), abs(before)) >= self.saturation_rad_s
            self.saturated_now[axis] = sat
            if sat:
                self.saturated[axis] += 1
                continue
            tr = ch.update(0.5 * (now + before) - rate[i], t, stamp)
            if tr is not None:
                events.append(make_event(axis, tr))
        if events:
            self._last_event = events[-1]
        return events

    def state(self) -> GyroDiagnosisState:
        """Return the detector's state as a typed record (core/gyro_state.py).

        ``records.encode(det.state())``, then ``records.decode`` and :meth:`restore` into
        a detector built with the same parameters and calibration, resumes exactly where
        this one stands.
        """
        return GyroDiagnosisState(
            self._state_parameters(), self._axis_records(), self._rows.record(),
            self._last_event, dict(self.saturated), dict(self.saturated_now),
            self._prev_gyro, self._prev_time)

    def restore(self, state: GyroDiagnosisState) -> None:
        """Resume from ``state``, checked whole first.

        A state of other parameters, calibration, axes or block lengths, or inconsistent
        with itself, raises :class:`~rwa_monitor.core.records.RecordError` naming the
        field, and the detector is left as it was.
        """
        self._check_state(state, GyroDiagnosisState)
        path = 'GyroDiagnosisState'
        for name in ('saturated', 'saturated_now'):
            check_keys(getattr(state, name), self.axes, f'{path}.{name}')
        for axis in self.axes:
            n = state.saturated[axis]
            require(type(n) is int and n >= 0, f'{path}.saturated[{axis}]',
                    f'expected a count >= 0, got {n!r}')
            require(type(state.saturated_now[axis]) is bool, f'{path}.saturated_now[{axis}]',
                    'expected true or false')
        require(state.previous_time == state.rows.last_time, f'{path}.previous_time',
                'differs from rows.last_time (the stamp of the last row taken)')
        require((state.previous_gyro is None) == (state.previous_time == -math.inf),
                f'{path}.previous_gyro', 'a previous gyro sample needs a stamp, and back')
        if state.previous_gyro is not None:
            require(len(state.previous_gyro) == 3, f'{path}.previous_gyro', 'expected 3')
        self._restore_state(state)
        self.saturated = {a: state.saturated[a] for a in self.axes}
        self.saturated_now = {a: state.saturated_now[a] for a in self.axes}
        self._prev_gyro, self._prev_time = state.previous_gyro, state.previous_time


def gyro_diagnosis_kwargs(values: Mapping[str, Any]) -> dict[str, Any]:
    """Return GyroDiagnosis keywords from checked VSADC values (``residual_`` dropped)."""
    shared = vsadc_kwargs(values)
    return {'saturation_rad_s': values['saturation_rad_s'], 'max_gap': shared['max_gap'],
            'norm_tolerance': shared['norm_tolerance'], 'axes': shared['axes'],
            **{k: values[f'residual_{k}'] for k in AXIS_DEFAULTS}}


def make_gyro_detector(values: Mapping[str, Any],
                       calibration: Mapping[str, Mapping[str, Any]] | None = None
                       ) -> GyroDiagnosis | VsadcDetector:
    """Return the detector of checked VSADC schema values (``feature`` residual or paper).

    ``calibration`` (axis -> dict of calibrate_gyro) applies to the residual feature; the
    paper's VsadcDetector is built either way, so that every value of the block is checked.
    """
    paper = VsadcDetector(**vsadc_kwargs(values))
    if values['feature'] == 'paper':
        return paper
    return GyroDiagnosis(calibration=calibration, **gyro_diagnosis_kwargs(values))
