"""One gyro axis of the residual drift/bias diagnosis (docs/vsadc.md).

Algorithm 1 of the vsadc-gyro-drift paper on a feature that cancels the true body rate:
per axis the residual ``e = (g_{k-1} + g_k)/2 - w_st,k``
(:mod:`rwa_monitor.core.gyro_calibration`) is averaged over blocks of ``block`` steps.

- Nominal class (Alg. 1 lines 9-13): the mean of the first ``nominal_blocks`` blocks; then,
  beyond the paper, a running mean over ``tracking_blocks`` fed by the block ``guard_blocks``
  back, only while the axis is healthy and the last ``guard_blocks + 1`` blocks lie within
  ``freeze_fraction`` of the threshold (a slow thermal wander is nominal, a fault freezes
  the nominal before it is declared).
- Evolving class and distance (lines 15-20, eq. (8)): the signed distance of the newest
  block mean to the nominal centre, ``d``; a fault when ``|d|`` exceeds the level threshold
  on ``confirm_blocks`` successive blocks (line 26) or, beyond the paper, when a two-sided
  CUSUM of ``d / block_std`` (reference value ``cusum_allowance``) passes
  ``cusum_threshold``.
- Drift or bias (lines 27-34): instead of the spread of ``d`` against self-adapted sigma
  limits, a likelihood comparison on the half-block means of the last ``decide_blocks``
  blocks of a step (bias) and a ramp (drift), each with its onset fitted, whitened with
  the calibrated noise model (:mod:`rwa_monitor.core.gyro_decision`): the kind is
  declared when one model explains the data better by ``decide_chi2`` (in block
  variances), or after ``max_wait_blocks`` by the better one. The fitted onset is the
  event's change time.
- While faulty: drift becomes bias when the least-squares slope over the last
  ``fit_blocks`` blocks falls below half the slope threshold; bias becomes drift only
  when the level has also moved from the held bias level by the level threshold and the
  slope is above the slope threshold (a kind change needs its own evidence at the level
  of the declaration); both confirmed on ``confirm_blocks`` blocks, and not before the
  fault has lasted ``fit_blocks`` blocks (the step itself is a slope). Recovery when
  ``|d|`` stays below ``recovery_fraction`` of the threshold for ``confirm_blocks``
  blocks.

Thresholds come from :func:`rwa_monitor.core.gyro_calibration.calibrate_gyro` (the
``gyro:`` block of calibration.yaml) or, without one, from ``DEFAULT_BLOCK_STD``.
"""

from __future__ import annotations

from collections import deque
import math
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import gyro_calibration as gc
from rwa_monitor.core.gyro_decision import step_or_ramp, whitener
from rwa_monitor.core.gyro_state import (
    check_counts, check_finite, check_label, check_stamps, check_type, require,
    ResidualAxisState, ResidualThresholds, stamp_list, stamps_record)
from rwa_monitor.core.params import check_int, check_real
from rwa_monitor.core.schema import RESIDUAL_PARAMETERS, VSADC
from rwa_monitor.core.vsadc_axis import BIAS, DRIFT, HEALTHY, Transition

#: Block-mean spread without a calibration (rad/s): the largest of the three axes measured
#: by calibrate_gyro on the bus development seeds 1-3 (docs/vsadc.md), rounded up.
DEFAULT_BLOCK_STD = 4.0e-6
#: Block length (s) of ``DEFAULT_BLOCK_STD`` (40 steps at 4 Hz). The star-tracker part of a
#: block mean, which dominates it, falls as 1 / block length: without a calibration the
#: spread is scaled to the block length of the record (measured on its first block).
DEFAULT_BLOCK_S = 10.0
#: Lowest lag-1 correlation of block means the decision's noise model accepts (MA(1) of
#: differenced star-tracker noise plus white gyro noise: -0.5 is the limit, no gyro noise).
MIN_LAG1 = -0.45
#: Axis keywords and defaults: the ``residual_*`` parameters of the VSADC schema.
AXIS_DEFAULTS: dict[str, Any] = {
    name[len('residual_'):]: VSADC[name].default
    for name in RESIDUAL_PARAMETERS if name.startswith('residual_')}


def axis_thresholds(calibration: Mapping[str, Any] | None, block: int,
                    fit_blocks: int, sample_s: float = 0.25) -> dict[str, float]:
    """Return the level, quiet and slope thresholds and block std of one axis.

    From its calibration dict (keys of :func:`calibrate_gyro`) or, when None, from
    ``DEFAULT_BLOCK_STD`` with the calibration's own factors.
    """
    if calibration:
        try:
            return {'block_std': check_real('block_std_rad_s',
                                            calibration['block_std_rad_s'], 0.0, low_open=True),
                    'level': check_real('level_threshold_rad_s',
                                        calibration['level_threshold_rad_s'], 0.0,
                                        low_open=True),
                    'quiet': check_real('quiet_level_rad_s', calibration['quiet_level_rad_s'],
                                        0.0, low_open=True),
                    'slope': check_real('slope_threshold_rad_s2',
                                        calibration['slope_threshold_rad_s2'], 0.0,
                                        low_open=True)}
        except KeyError as exc:
            raise ValueError(f'gyro calibration lacks {exc.args[0]}') from None
    std = DEFAULT_BLOCK_STD * DEFAULT_BLOCK_S / (block * sample_s)
    return {'block_std': std, 'level': gc.DEFAULT_LEVEL_K * std + gc.DEFAULT_WANDER_RAD_S,
            'quiet': 3.0 * std,
            'slope': gc.DEFAULT_SLOPE_K * gc.slope_std(std, fit_blocks, block * sample_s)}


class ResidualAxis:
    """One axis: ``update(e, time, stamp)`` per residual; a Transition when the label changes.

    ``stamp`` is any object returned in transitions (e.g. ``(time, row)``).
    """

    def __init__(self, calibration: Mapping[str, Any] | None = None, **params: Any) -> None:
        bad = sorted(set(params) - set(AXIS_DEFAULTS))
        if bad:
            raise ValueError(f'unknown gyro diagnosis parameter(s): {", ".join(bad)}')
        p = {**AXIS_DEFAULTS, **params}
        self.block = check_int('block', p['block'], 2, 100_000)
        self.nominal_blocks = check_int('nominal_blocks', p['nominal_blocks'], 1, 100_000)
        self.tracking_blocks = check_int('tracking_blocks', p['tracking_blocks'], 0, 1_000_000)
        self.guard_blocks = check_int('guard_blocks', p['guard_blocks'], 0, 1000)
        self.fit_blocks = check_int('fit_blocks', p['fit_blocks'], 3, 10_000)
        self.decide_blocks = check_int('decide_blocks', p['decide_blocks'], 3, 10_000)
        self.confirm_blocks = check_int('confirm_blocks', p['confirm_blocks'], 1, 1000)
        self.max_wait_blocks = check_int('max_wait_blocks', p['max_wait_blocks'], 0, 1000)
        self.decide_chi2 = check_real('decide_chi2', p['decide_chi2'], 0.0)
        self.freeze_fraction = check_real('freeze_fraction', p['freeze_fraction'], 0.0, 1.0)
        self.recovery_fraction = check_real('recovery_fraction', p['recovery_fraction'],
                                            0.0, 1.0, low_open=True)
        self.cusum_threshold = check_real('cusum_threshold', p['cusum_threshold'], 0.0)
        self.cusum_allowance = check_real('cusum_allowance', p['cusum_allowance'], 0.0)
        self._calibrated = bool(calibration)
        self._calibration_thresholds = axis_thresholds(calibration, self.block, self.fit_blocks)
        self._set_thresholds(self._calibration_thresholds)
        self._sample_s: float | None = None     # the step the defaults were scaled to
        rho = float((calibration or {}).get('block_lag1_correlation', 0.0))
        self.lag1_correlation = min(max(rho, MIN_LAG1) if math.isfinite(rho) else 0.0, 0.0)
        self._whiteners: dict[int, np.ndarray] = {}
        self.reset()

    def _set_thresholds(self, th: Mapping[str, float]) -> None:
        self.block_std, self.level_threshold = th['block_std'], th['level']
        self.quiet_level, self.slope_threshold = th['quiet'], th['slope']

    def reset(self) -> None:
        """Forget everything: the next residual starts a new nominal batch."""
        self._sum = self._first_half = 0.0
        self._times: list[float] = []
        self._stamps: list[Any] = []
        keep = max(self.decide_blocks, self.fit_blocks, self.guard_blocks + 1)
        self._blocks: deque = deque(maxlen=keep)       # (mean, times, stamps)
        self._nb = 0
        self._nominal_sum = 0.0
        self.nominal = math.nan
        self._state = HEALTHY
        self._over = self._waited = self._pending_run = self._fault_blocks = 0
        self._pending = HEALTHY
        self._level_sum, self._level_n = 0.0, 0
        self._n = 0
        self.distance = self.slope = math.nan
        self.cusum = [0.0, 0.0]     # upward, downward (block standard deviations)

    # Names the node's health report reads (shared with VsadcAxis).
    @property
    def sigma(self) -> float:
        """Return the last fitted slope (rad/s per s), shown as the spread statistic."""
        return self.slope

    @property
    def sigma_lim1(self) -> float:
        """Return the level threshold (rad/s)."""
        return self.level_threshold

    @property
    def sigma_lim2(self) -> float:
        """Return the slope threshold (rad/s per s)."""
        return self.slope_threshold

    @property
    def state(self) -> int:
        """Return the current label (0 healthy, 1 drift, 2 bias)."""
        return self._state

    @property
    def samples(self) -> int:
        """Return the residuals taken since the last reset."""
        return self._n

    @property
    def ready(self) -> bool:
        """Return True once the nominal level is learnt."""
        return self._nb >= self.nominal_blocks

    def update(self, e: float, time: float, stamp: Any = None) -> Transition | None:
        """Take one residual (rad/s) at ``time`` (s); return a Transition on a label change."""
        self._n += 1
        self._sum += e
        self._times.append(time)
        self._stamps.append(stamp)
        if len(self._times) == self.block // 2:
            self._first_half = self._sum
        if len(self._times) < self.block:
            return None
        mean = self._sum / self.block
        half = self.block // 2
        halves = (self._first_half / half, (self._sum - self._first_half) / (self.block - half))
        block = (mean, np.array(self._times), self._stamps, halves)
        self._sum, self._times, self._stamps = 0.0, [], []
        if self._nb == 0 and not self._calibrated:     # defaults at this record's rate
            step = (block[1][-1] - block[1][0]) / (self.block - 1)
            if step > 0:
                self._set_thresholds(axis_thresholds(None, self.block, self.fit_blocks, step))
                self._sample_s = float(step)
        return self._on_block(block)

    def _on_block(self, block: tuple) -> Transition | None:
        self._blocks.append(block)
        self._nb += 1
        mean = block[0]
        if self._nb <= self.nominal_blocks:                 # Alg. 1 lines 9-13
            self._nominal_sum += mean
            if self._nb == self.nominal_blocks:
                self.nominal = self._nominal_sum / self.nominal_blocks
            return None
        d = mean - self.nominal                             # eq. (8), one dimension
        self.distance = d
        stamp = block[2][-1]
        if self._state == HEALTHY:
            self._track_nominal()
            self._over = self._over + 1 if abs(d) > self.level_threshold else 0
            if self._over < self.confirm_blocks and not self._cusum_alarm(d):
                self._waited = 0
                return None
            kind, onset = self._decide(force=self._waited >= self.max_wait_blocks)
            self._waited += 1
            if kind is None:
                return None
            return self._change(kind, onset, stamp, d)
        self._fault_blocks += 1
        if abs(d) < self.recovery_fraction * self.level_threshold:
            return self._confirm(HEALTHY, stamp, d)
        moved = False
        if self._state == BIAS:             # the held level: mean of the bias's blocks
            moved = bool(self._level_n) and (abs(d - self._level_sum / self._level_n)
                                             > self.level_threshold)
            self._level_sum, self._level_n = self._level_sum + d, self._level_n + 1
        if self._fault_blocks < self.fit_blocks:
            self._pending_run = 0
            return None
        self.slope = self._slope()
        if self._state == DRIFT and abs(self.slope) < 0.5 * self.slope_threshold:
            return self._confirm(BIAS, stamp, d)
        if moved and abs(self.slope) > self.slope_threshold:
            return self._confirm(DRIFT, stamp, d)
        if moved and self._pending_run == 0:    # a further step: a bias at a new level
            self._level_sum, self._level_n = d, 1
        self._pending_run = 0
        return None

    def _cusum_alarm(self, d: float) -> bool:
        """Update the two-sided CUSUM of the block distances; True above its threshold.

        Page's CUSUM on ``z = d / block_std`` with reference value ``cusum_allowance``
        (block standard deviations: the nominal tracking's lag under a slow wander); a
        threshold of 0 turns it off (level test only).
        """
        if not self.cusum_threshold:
            return False
        z = d / self.block_std
        up, down = self.cusum
        self.cusum = [max(0.0, up + z - self.cusum_allowance),
                      max(0.0, down - z - self.cusum_allowance)]
        return max(self.cusum) > self.cusum_threshold

    def _confirm(self, new: int, stamp: Any, d: float) -> Transition | None:
        if new != self._pending:
            self._pending, self._pending_run = new, 0
        self._pending_run += 1
        if self._pending_run < self.confirm_blocks:
            return None
        return self._change(new, stamp, stamp, d)

    def _change(self, new: int, onset: Any, stamp: Any, d: float) -> Transition:
        previous, self._state = self._state, new
        self._pending, self._pending_run = new, 0
        self._over = self._waited = self._fault_blocks = 0
        self._level_sum, self._level_n = 0.0, 0
        self.cusum = [0.0, 0.0]
        return Transition(previous, new, onset, stamp, abs(d), self.slope)

    def _track_nominal(self) -> None:
        """Move the nominal towards the block ``guard_blocks`` back (beyond the paper)."""
        g = self.guard_blocks
        if not self.tracking_blocks or len(self._blocks) < g + 1:
            return
        recent = list(self._blocks)[-(g + 1):]
        limit = self.freeze_fraction * self.level_threshold
        if all(abs(b[0] - self.nominal) < limit for b in recent):
            self.nominal += (recent[0][0] - self.nominal) / self.tracking_blocks

    def _slope(self) -> float:
        """Return the least-squares slope (rad/s per s) of the last ``fit_blocks`` means."""
        blocks = list(self._blocks)[-self.fit_blocks:]
        t = np.array([b[1].mean() for b in blocks])
        y = np.array([b[0] for b in blocks])
        t = t - t.mean()
        return float(np.dot(t, y - y.mean()) / np.dot(t, t))

    def _decide(self, force: bool) -> tuple[int | None, Any]:
        """Return the kind and onset stamp of the last ``decide_blocks`` blocks, or None.

        Step or ramp: :func:`~rwa_monitor.core.gyro_decision.step_or_ramp`, on the
        half-block means, whitened (the whiteners cached per size).
        """
        blocks = list(self._blocks)[-self.decide_blocks:]
        k = 2 * len(blocks)                                 # half-block means
        whiten = self._whiteners.get(k)
        if whiten is None:
            whiten = self._whiteners[k] = whitener(k, self.lag1_correlation)
        kind, i = step_or_ramp(np.array([h for b in blocks for h in b[3]]) - self.nominal,
                               np.stack([b[1] for b in blocks]), whiten,
                               self.block_std, self.decide_chi2, force)
        if kind is None:
            return None, None
        return kind, [s for b in blocks for s in b[2]][i]

    def record(self) -> ResidualAxisState:
        """Return the axis's state (core/gyro_state.py); stamps must be ``(time, row)``."""
        blocks, where = list(self._blocks), 'ResidualAxisState'
        k = len(blocks)
        return ResidualAxisState(
            samples=self._n, blocks_seen=self._nb, partial_sum=self._sum,
            first_half_sum=self._first_half,
            partial_times=np.array(self._times, dtype=np.float64),
            partial_stamps=stamps_record(self._stamps, f'{where}.partial_stamps'),
            block_means=np.array([b[0] for b in blocks], dtype=np.float64),
            block_halves=np.array([b[3] for b in blocks], dtype=np.float64).reshape(k, 2),
            block_times=np.array([b[1] for b in blocks],
                                 dtype=np.float64).reshape(k, self.block),
            block_stamps=stamps_record([s for b in blocks for s in b[2]],
                                       f'{where}.block_stamps'),
            nominal_sum=self._nominal_sum, nominal=self.nominal, label=self._state,
            pending=self._pending, pending_run=self._pending_run, over=self._over,
            waited=self._waited, fault_blocks=self._fault_blocks, level_sum=self._level_sum,
            level_blocks=self._level_n, distance=self.distance, slope=self.slope,
            cusum=(self.cusum[0], self.cusum[1]), calibrated=self._calibrated,
            lag1_correlation=self.lag1_correlation,
            thresholds=ResidualThresholds(self.block_std, self.level_threshold,
                                          self.quiet_level, self.slope_threshold),
            threshold_sample_s=self._sample_s)

    def _expected_thresholds(self, sample_s: float | None) -> dict[str, float]:
        if sample_s is None:
            return self._calibration_thresholds
        return axis_thresholds(None, self.block, self.fit_blocks, sample_s)

    def check_record(self, record: ResidualAxisState, path: str) -> None:
        """Refuse a record of other parameters or calibration, or inconsistent with itself."""
        check_type(record, ResidualAxisState, path)
        check_counts(record, ('samples', 'blocks_seen', 'pending_run', 'over', 'waited',
                              'fault_blocks', 'level_blocks'), path)
        n, nb, b = record.samples, record.blocks_seen, self.block
        p, k = len(record.partial_times), min(nb, self._blocks.maxlen)
        require(p < b and n == nb * b + p, f'{path}.partial_times',
                f'{p} samples in the block being filled: not {n} - {nb} blocks of {b}')
        check_stamps(record.partial_stamps, p, f'{path}.partial_stamps')
        for name, shape in (('block_means', (k,)), ('block_halves', (k, 2)),
                            ('block_times', (k, b))):
            require(getattr(record, name).shape == shape, f'{path}.{name}',
                    f'expected shape {shape} ({nb} blocks seen, {self._blocks.maxlen} kept)')
        check_stamps(record.block_stamps, k * b, f'{path}.block_stamps')
        check_finite(path, record.partial_times, record.partial_sum, record.first_half_sum,
                     record.block_means, record.block_halves, record.block_times,
                     record.nominal_sum, record.level_sum, record.cusum)
        require(min(record.cusum) >= 0.0, f'{path}.cusum', 'negative')
        require(math.isfinite(record.nominal) == (nb >= self.nominal_blocks),
                f'{path}.nominal', f'must be a number once {self.nominal_blocks} blocks are seen')
        for name in ('label', 'pending'):
            check_label(getattr(record, name), f'{path}.{name}')
        require(record.calibrated == self._calibrated and record.lag1_correlation
                == self.lag1_correlation, f'{path}.calibrated',
                'the state was made with another calibration')
        s = record.threshold_sample_s
        require(s is None or (not self._calibrated and math.isfinite(s) and s > 0),
                f'{path}.threshold_sample_s', f'expected None or a step > 0 s, got {s!r}')
        require(record.thresholds == ResidualThresholds(**self._expected_thresholds(s)),
                f'{path}.thresholds', 'the state was made with another calibration')

    def restore(self, record: ResidualAxisState) -> None:
        """Resume from ``record`` (checked first: RecordError, and the axis unchanged)."""
        self.check_record(record, type(record).__name__)
        self._n, self._nb = record.samples, record.blocks_seen
        self._sum, self._first_half = record.partial_sum, record.first_half_sum
        self._times = record.partial_times.tolist()
        self._stamps = stamp_list(record.partial_stamps)
        stamps, b = stamp_list(record.block_stamps), self.block
        self._blocks = deque(
            ((mean, np.array(times), stamps[i * b:(i + 1) * b], tuple(halves))
             for i, (mean, times, halves) in enumerate(zip(
                record.block_means.tolist(), record.block_times,
                record.block_halves.tolist()))), maxlen=self._blocks.maxlen)
        self._nominal_sum, self.nominal = record.nominal_sum, record.nominal
        self._state, self._pending = record.label, record.pending
        self._pending_run, self._over = record.pending_run, record.over
        self._waited, self._fault_blocks = record.waited, record.fault_blocks
        self._level_sum, self._level_n = record.level_sum, record.level_blocks
        self.distance, self.slope = record.distance, record.slope
        self.cusum = list(record.cusum)
        self._set_thresholds(self._expected_thresholds(record.threshold_sample_s))
        self._sample_s = record.threshold_sample_s
