"""VSADC gyro drift/bias classifier, one axis, streaming (vsadc-gyro-drift paper, Alg. 1).

Per axis the feature is ``x = (res_sst, res_gyr)`` (eqs. (3), (7)); the nominal centre is
the mean of the first ``window`` samples (Alg. 1 lines 9-13), the evolving centre the
mean of the last ``window`` (lines 15-18), ``d`` their distance (eq. (8), line 20) and
``sigma`` the standard deviation of the last ``sigma_window`` distances (line 22; the
paper uses ``window``, the default). Labels: 0 healthy, 1 drift, 2 bias. Every choice the
pseudo-code leaves open is argued in docs/vsadc.md; in short:

- the sigma limits come from a *reference* set of sigmas, never from the window that
  holds the current sigma (a max that includes the current value cannot be exceeded):
  the last ``reference_window`` sigmas computed while the axis was healthy and ``d`` was
  below ``freeze_fraction`` times the distance threshold;
- ``sigma_lim1`` = ``margin`` times their max is the threshold to *enter* drift (line
  28, "first occurrence"); ``sigma_lim2`` = ``exit_margin`` times their max (or mean,
  ``exit_limit``) the threshold to *stay* in drift (line 30, "continuous"): hysteresis;
- self-adaptation (``adaptive``): once a bias has lasted ``reference_window`` samples, the
  threshold to enter drift from it is ``margin`` times the max of the bias's own sigmas
  (the limit follows the occupied area of the feature space, paper section 3.3);
- start-up: label 0 until the nominal batch, one independent evolving window, one
  window of distances and ``reference_window`` reference sigmas exist;
- a new label is adopted after ``hold`` consecutive samples agree (1 = Alg. 1 as is);
- a fault ends when ``d`` falls below ``recovery_fraction`` times the threshold (1 = the
  paper), so that a distance hovering at the threshold does not flicker;
- beyond the paper, ``nominal_tracking`` > 0 keeps moving the nominal centre with the
  samples that leave the evolving window (a running mean over that many samples), only
  while the axis is healthy and ``d`` is below ``freeze_fraction`` times the threshold,
  so a drift freezes the nominal before it is detected.

The paper-literal reading is ``sigma_window=window, reference_window=window, margin=1,
exit_limit='mean', exit_margin=1, adaptive=False, recovery_fraction=1``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from rwa_monitor.core import keys
from rwa_monitor.core.gyro_state import (
    check_counts, check_finite, check_label, check_stamps, check_type, chronological, require,
    ring, stamp_list, stamp_record, stamps_record, VsadcAxisState)
from rwa_monitor.core.params import AUTO, check_choice, check_int, check_real
from rwa_monitor.core.sliding import RESUM_EVERY as _RESUM_EVERY, SlidingMax, SlidingWindow

HEALTHY, DRIFT, BIAS = 0, 1, 2
STATE_NAMES = keys.GYRO_STATES


@dataclass(frozen=True)
class Transition:
    """A change of an axis's label: ``onset`` and ``declared`` are the caller's stamps."""

    previous: int
    state: int
    onset: Any
    declared: Any
    distance: float
    sigma: float


class VsadcAxis:
    """Streaming VSADC on one gyro axis: ``update(res_sst, res_gyr, stamp)`` per sample.

    ``stamp`` is any object (e.g. ``(time, row)``) returned in the transitions as the
    declaration and the estimated onset; memory is O(``window`` + ``reference_window``).
    """

    def __init__(self, *, window: int = 200, distance_threshold: float = 1.5e-5,
                 sigma_window: int | str = AUTO, reference_window: int | str = 1200,
                 margin: float = 1.5, exit_limit: str = 'max', exit_margin: float = 1.25,
                 hold: int = 1, nominal_tracking: int = 0,
                 freeze_fraction: float = 0.5, adaptive: bool = True,
                 recovery_fraction: float = 0.75) -> None:
        self.window = check_int('window', window, 2, 100_000)
        self.sigma_window = check_int(
            'sigma_window', self.window if sigma_window in (None, AUTO) else sigma_window, 2,
            100_000)
        self.exit_limit = check_choice('exit_limit', exit_limit, ('mean', 'max'))
        self.exit_margin = check_real('exit_margin', exit_margin, 0.0, low_open=True)
        self.distance_threshold = check_real('distance_threshold', distance_threshold, 0.0,
                                             low_open=True)
        self.reference_window = check_int(
            'reference_window',
            self.window if reference_window in (None, AUTO) else reference_window,
            1, 1_000_000)
        self.margin = check_real('margin', margin, 0.0, low_open=True)
        self.hold = check_int('hold', hold, 1, 100_000)
        self.nominal_tracking = check_int('nominal_tracking', nominal_tracking, 0)
        self.freeze_fraction = check_real('freeze_fraction', freeze_fraction, 0.0, 1.0)
        self.recovery_fraction = check_real('recovery_fraction', recovery_fraction, 0.0, 1.0,
                                            low_open=True)
        if not isinstance(adaptive, bool):
            raise ValueError(f'adaptive must be true or false, got {adaptive!r}')
        self.adaptive = adaptive
        self.reset()

    def reset(self) -> None:
        """Forget everything: the next sample starts a new nominal batch."""
        w, m = self.window, self.sigma_window
        self._buf1, self._buf2 = [0.0] * w, [0.0] * w       # feature windows (ring)
        self._stamps: list[Any] = [None] * w
        self._pos = 0
        self._sum1 = self._sum2 = 0.0
        self._dbuf = [0.0] * m                              # distance window (ring)
        self._dpos = self._dcount = 0
        self._dsum = self._dsq = 0.0
        self._ready = False
        self._ref_max = SlidingMax(self.reference_window)
        self._ref = SlidingWindow(self.reference_window)
        self._new_regime()
        self._n = 0
        self._mu1 = self._mu2 = 0.0
        self._state = HEALTHY
        self._candidate, self._run = HEALTHY, 0
        self._quiet_stamp: Any = None
        self._d_mean = self._d_var = 0.0
        self.distance = self.sigma = math.nan
        self.sigma_lim1 = self.sigma_lim2 = math.nan

    @property
    def state(self) -> int:
        """Return the current label (0 healthy, 1 drift, 2 bias)."""
        return self._state

    @property
    def samples(self) -> int:
        """Return the number of samples taken since the last reset."""
        return self._n

    @property
    def ready(self) -> bool:
        """Return True once start-up is over: ``reference_window`` sigmas were learnt."""
        return (self._n >= 2 * self.window + self.sigma_window
                and self._ref.count >= self.reference_window)

    @property
    def nominal_centre(self) -> tuple[float, float]:
        """Return the nominal class centre (mean res_sst, mean res_gyr), rad/s."""
        return self._mu1, self._mu2

    def update(self, res_sst: float, res_gyr: float, stamp: Any = None) -> Transition | None:
        """Take one feature sample; return a Transition when the label changes.

        Alg. 1 lines 7-37 for one axis. Non-finite features must be filtered by the
        caller (:class:`VsadcDetector` holds the axis instead).
        """
        w = self.window
        pos = self._pos
        old1, old2, old_stamp = self._buf1[pos], self._buf2[pos], self._stamps[pos]
        self._buf1[pos], self._buf2[pos], self._stamps[pos] = res_sst, res_gyr, stamp
        self._pos = pos + 1 if pos + 1 < w else 0
        n = self._n = self._n + 1
        self._sum1 += res_sst - old1                        # old values are 0.0 while filling
        self._sum2 += res_gyr - old2
        if n % _RESUM_EVERY == 0:                           # bound the running sums' rounding
            self._sum1, self._sum2 = math.fsum(self._buf1), math.fsum(self._buf2)
        if n < w:
            return None
        if n == w:                                          # Alg. 1 lines 12-13
            self._mu1, self._mu2 = self._sum1 / w, self._sum2 / w
        d1 = self._sum1 / w - self._mu1
        d2 = self._sum2 / w - self._mu2
        d = math.sqrt(d1 * d1 + d2 * d2)                    # eq. (8), line 20
        self.distance = d
        m = self.sigma_window
        dpos = self._dpos
        dold = self._dbuf[dpos]
        self._dbuf[dpos] = d
        self._dpos = dpos + 1 if dpos + 1 < m else 0
        if self._dcount < m:
            self._dcount += 1
        self._dsum += d - dold
        self._dsq += d * d - dold * dold
        if n % _RESUM_EVERY == 0:
            self._dsum = math.fsum(self._dbuf)
            self._dsq = math.fsum(v * v for v in self._dbuf)
        if n < w + m - 1:
            return None
        mean_d = self._dsum / m
        var = self._dsq / m - mean_d * mean_d
        sigma = math.sqrt(var) if var > 0.0 else 0.0        # line 22
        self.sigma = sigma
        if not self._ready:
            self._ready = self.ready
            if not self._ready:
                if n >= 2 * w + m:
                    self._learn_nominal(d, sigma, old1, old2, True)
                return None
        ref_max = self._ref_max.max()
        lim1 = self.margin * ref_max                        # line 24, see module doc
        lim2 = self.exit_margin * (self._ref.mean() if self.exit_limit == 'mean'
                                   else ref_max)
        self.sigma_lim1, self.sigma_lim2 = lim1, lim2
        spread = math.sqrt(self._d_var)
        quiet = d <= self._d_mean + 3.0 * spread
        if quiet:
            self._quiet_stamp = None
        elif self._quiet_stamp is None:
            self._quiet_stamp = stamp       # first sample above the quiet level: the onset
        state = self._state
        regime = self.adaptive and self._regime.count >= self.reference_window  # adapted
        limit = self.distance_threshold                     # line 26, with hysteresis:
        if state != HEALTHY:                                # a fault ends below a lower
            limit *= self.recovery_fraction                 # distance (no flicker)
        if d > limit:
            if state == DRIFT:                              # lines 30-33
                new = DRIFT if sigma > lim2 else BIAS
            else:                                           # lines 28-29, 32-33
                if state == BIAS and regime:
                    lim1 = self.margin * self._regime_max.max()
                    self.sigma_lim1 = lim1
                new = DRIFT if sigma > lim1 else BIAS
        else:
            new = HEALTHY                                   # line 36
        if new == state and self._run == 0:
            transition = None
        else:
            transition = self._settle(new, d, sigma, stamp, old_stamp)
        if transition is not None:
            self._new_regime()
        elif self._run == 0:
            if self._state == HEALTHY:
                self._learn_nominal(d, sigma, old1, old2, quiet)
            else:
                self._regime_max.push(sigma)
                self._regime.push(sigma)
        return transition

    def _new_regime(self) -> None:
        """Forget the sigmas of the fault regime just left (self-adaptive limits)."""
        self._regime_max = SlidingMax(self.reference_window)
        self._regime = SlidingWindow(self.reference_window)

    def _learn_nominal(self, d: float, sigma: float, old1: float, old2: float,
                       quiet: bool) -> None:
        """Feed the reference sigmas, the quiet-distance level and (option) the nominal.

        Only samples with ``d`` below ``freeze_fraction`` times the threshold (and, once
        ready, at the quiet level: within 3 standard deviations of the healthy distances)
        teach: the rise of a fault towards the threshold must not raise the sigma limits.
        """
        if d >= self.freeze_fraction * self.distance_threshold:
            return
        if quiet:
            self._ref_max.push(sigma)
            self._ref.push(sigma)
        a = 1.0 / (4 * self.window)
        if self._ref.updates == 1:
            self._d_mean, self._d_var = d, 0.0
        else:
            delta = d - self._d_mean
            self._d_mean += a * delta
            self._d_var = (1.0 - a) * (self._d_var + a * delta * delta)
        if self.nominal_tracking:
            a = 1.0 / self.nominal_tracking
            self._mu1 += a * (old1 - self._mu1)
            self._mu2 += a * (old2 - self._mu2)

    def _settle(self, new: int, d: float, sigma: float, stamp: Any,
                old_stamp: Any) -> Transition | None:
        """Adopt ``new`` after ``hold`` agreeing samples; return the transition if any."""
        if new == self._state:
            self._candidate, self._run = new, 0
            return None
        if new == self._candidate:
            self._run += 1
        else:
            self._candidate, self._run = new, 1
        if self._run < self.hold:
            return None
        previous, self._state = self._state, new
        self._candidate, self._run = new, 0
        if previous == HEALTHY:
            onset = stamp if self._quiet_stamp is None else self._quiet_stamp
        elif new == HEALTHY:
            onset = stamp
        else:
            onset = old_stamp           # kind changes show a window after they happen
        return Transition(previous, new, onset, stamp, d, sigma)

    def record(self) -> VsadcAxisState:
        """Return the axis's state (core/gyro_state.py); stamps must be ``(time, row)``."""
        n, w = self._n, self.window
        where = 'VsadcAxisState'
        return VsadcAxisState(
            samples=n, features=np.array(chronological(list(zip(self._buf1, self._buf2)), n, w),
                                         dtype=np.float64).reshape(-1, 2),
            stamps=stamps_record(chronological(self._stamps, n, w), f'{where}.stamps'),
            feature_sums=(self._sum1, self._sum2),
            distances=np.array(chronological(self._dbuf, max(n - w + 1, 0), self.sigma_window),
                               dtype=np.float64),
            distance_sums=(self._dsum, self._dsq), ready=self._ready,
            reference=self._ref.record(), reference_max=self._ref_max.record(),
            regime=self._regime.record(), regime_max=self._regime_max.record(),
            nominal_centre=(self._mu1, self._mu2), healthy_distance_mean=self._d_mean,
            healthy_distance_variance=self._d_var, label=self._state,
            candidate=self._candidate, run=self._run,
            quiet_since=stamp_record(self._quiet_stamp, f'{where}.quiet_since'),
            distance=self.distance, sigma=self.sigma,
            sigma_limits=(self.sigma_lim1, self.sigma_lim2))

    def check_record(self, record: VsadcAxisState, path: str) -> None:
        """Refuse a record of other window lengths or inconsistent with itself."""
        check_type(record, VsadcAxisState, path)
        check_counts(record, ('samples', 'run'), path)
        n, w, m = record.samples, self.window, self.sigma_window
        k, j = min(n, w), min(max(n - w + 1, 0), m)
        require(record.features.shape == (k, 2), f'{path}.features',
                f'expected {k} x 2 values (window {w}, {n} samples)')
        check_stamps(record.stamps, k, f'{path}.stamps')
        require(len(record.distances) == j, f'{path}.distances',
                f'expected {j} values (sigma_window {m}, {n} samples)')
        check_finite(f'{path}.features', record.features, record.feature_sums)
        check_finite(f'{path}.distances', record.distances, record.distance_sums)
        check_finite(f'{path}.nominal_centre', record.nominal_centre)
        check_finite(f'{path}.healthy_distance_mean', record.healthy_distance_mean,
                     record.healthy_distance_variance)
        require(record.healthy_distance_variance >= 0.0, f'{path}.healthy_distance_variance',
                'negative')
        for name in ('reference', 'regime'):
            window = getattr(record, name)
            self._ref.check_record(window, f'{path}.{name}')
            self._ref_max.check_record(getattr(record, f'{name}_max'), f'{path}.{name}_max')
            require(getattr(record, f'{name}_max').pushed == window.updates,
                    f'{path}.{name}_max.pushed', f'differs from {name}.updates')
        for name in ('label', 'candidate'):
            check_label(getattr(record, name), f'{path}.{name}')
        require(record.run < self.hold, f'{path}.run', f'expected below hold ({self.hold})')
        require(not record.ready or (n >= 2 * w + m and record.reference.updates
                                     >= self.reference_window), f'{path}.ready',
                'true before start-up can be over')

    def restore(self, record: VsadcAxisState) -> None:
        """Resume from ``record`` (checked first: RecordError, and the axis unchanged)."""
        self.check_record(record, type(record).__name__)
        n, w, m = record.samples, self.window, self.sigma_window
        self._buf1 = ring(record.features[:, 0].tolist(), n, w, 0.0)
        self._buf2 = ring(record.features[:, 1].tolist(), n, w, 0.0)
        self._stamps = ring(stamp_list(record.stamps), n, w, None)
        self._pos, self._n = n % w, n
        self._sum1, self._sum2 = record.feature_sums
        pushed = max(n - w + 1, 0)
        self._dbuf = ring(record.distances.tolist(), pushed, m, 0.0)
        self._dpos, self._dcount = pushed % m, min(pushed, m)
        self._dsum, self._dsq = record.distance_sums
        self._ready = record.ready
        for window, saved in ((self._ref, record.reference), (self._ref_max, record.reference_max),
                              (self._regime, record.regime),
                              (self._regime_max, record.regime_max)):
            window.restore(saved)
        self._mu1, self._mu2 = record.nominal_centre
        self._d_mean, self._d_var = record.healthy_distance_mean, record.healthy_distance_variance
        self._state, self._candidate, self._run = record.label, record.candidate, record.run
        self._quiet_stamp = record.quiet_since
        self.distance, self.sigma = record.distance, record.sigma
        self.sigma_lim1, self.sigma_lim2 = record.sigma_limits
