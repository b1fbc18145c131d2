"""The four stages chained on one window, and a bounded sliding window for streams.

:func:`extract` runs stages 1-3 (changepoints, interval LS, DP assignment, Algorithm 1)
on normalised, paper-sign signals; :func:`diagnose` converts a wheel's SI telemetry
(project sign: friction = -f^d sign(w) - f^v w), extracts, classifies, and returns the
per-wheel JSON object of DESIGN.md. :class:`SlidingWindow` keeps the last ``length``
samples of one wheel for the node.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import time as _time
from typing import Sequence

import numpy as np

from rwa_monitor.core import keys
from rwa_monitor.core.coverage import Coverage, judge, NOT_EXAMINED, UNKNOWN
from rwa_monitor.core.fss.assign import (assign_changepoints, base_dry_weights,
                                         friction_levels)
from rwa_monitor.core.fss.classify import WindowClassifier
from rwa_monitor.core.fss.model import DEFAULT_SYSTEMS, SwitchingSystem
from rwa_monitor.core.fss.segments import combination_se, fit_intervals
from rwa_monitor.core.fss.wglr import detect_changepoints
from rwa_monitor.core.params import check_int, check_real


@dataclass(frozen=True)
class FssConfig:
    """Parameters of the window diagnoser (core/schema.py FSS; same names in the YAML)."""

    wglr_window: int = 20             # wGLR half-window w (samples)
    w_bias: float = 1.0e-4            # W_b, weight of the viscous prior, eq. (11b)
    viscous_prior: float = 1.0        # f~v, normalised
    p_false: float = 1.0e-9           # false-positive probability per sample, stage 1
    dk_error: int = 10                # samples dropped each side of a changepoint (w / 2)
    beam: int = 256                   # DP states kept per stage
    torque_scale_nm: float = 2.0e-4   # one normalised torque unit (N m)
    speed_scale_rad_s: float = 400.0  # one normalised speed unit (rad/s)
    max_abs_speed: float = 1.0e5      # rad/s: samples at or beyond are not tested
    max_abs_friction: float = 1.0e3   # N m: samples at or beyond are not tested
    systems: tuple[SwitchingSystem, ...] = DEFAULT_SYSTEMS

    def __post_init__(self) -> None:
        check_int('wglr_window', self.wglr_window, 2, 100_000)
        check_real('w_bias', self.w_bias, 0.0)
        check_real('viscous_prior', self.viscous_prior)
        check_real('p_false', self.p_false, 0.0, 1.0, low_open=True, high_open=True)
        check_int('dk_error', self.dk_error, 0, 100_000)
        check_int('beam', self.beam, 1, 1_000_000)
        check_real('torque_scale_nm', self.torque_scale_nm, 0.0, low_open=True)
        check_real('speed_scale_rad_s', self.speed_scale_rad_s, 0.0, low_open=True)
        check_real('max_abs_speed', self.max_abs_speed, 0.0, low_open=True)
        check_real('max_abs_friction', self.max_abs_friction, 0.0, low_open=True)


@dataclass
class Extraction:
    """Stages 1-3 of one window (normalised units, paper sign)."""

    detected: np.ndarray          # stage-1 changepoints
    accepted: np.ndarray          # changepoints kept by the assignment
    systems_of: np.ndarray        # FSS (1-based) of each accepted changepoint
    deltas: np.ndarray            # dry-friction jump at each accepted changepoint
    base_dry: float
    viscous: float
    levels: list[list[float]]
    configs: list[list[int]]
    sigma: float
    rmse: float
    rejected: int
    iterations: int
    exact: bool
    identifiable: bool
    viscous_se: float = float('inf')    # least-squares standard error of ``viscous``
    base_dry_se: float = float('inf')   # least-squares standard error of ``base_dry``
    timings: dict[str, float] = field(default_factory=dict)       # wall time (s)
    cpu_timings: dict[str, float] = field(default_factory=dict)   # this thread's CPU (s)
    onsets: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    onset_deltas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    start: int = 0                # first sample of the part of the window diagnosed

    def features(self) -> dict:
        """Return the classifier input: base dry, viscous and levels per FSS."""
        return {'base_dry': self.base_dry, 'viscous': self.viscous, 'levels': self.levels}


# Least samples after an onset for the part after it to be diagnosed (else the part
# before it is): stage 2 then holds >= 1000 samples for two coefficients.
MIN_REGIME_SAMPLES = 1000


def extract(speed: np.ndarray, friction: np.ndarray, config: FssConfig = FssConfig()
            ) -> Extraction:
    """Run stages 1-3 on one window; diagnose the wheel's latest regime when it changed.

    An **onset** is an accepted changepoint that no FSS of the model can have made: it
    is the only jump of its FSS in the window and the level before or after it lasts
    longer than that FSS's longest residence (:func:`onsets`). It is a persistent
    change of the wheel (an anomaly beginning inside the window: a dry or a viscous
    step), not a switch of a friction source; left to the assignment it was given to
    the slow FSS at the floor score and judged an FSS-2 anomaly (docs/fss.md, "Onsets").
    When the window holds onsets, stages 1-3 run again on the samples after the last
    one (the wheel as it is now; if fewer than MIN_REGIME_SAMPLES, on those before it)
    and the result keeps the onsets (window indices) and their dry jumps.
    """
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    ext = _extract_once(speed, friction, config)
    found = onsets(ext, speed.size, config.systems)
    if found.size == 0:
        return ext
    last = int(found[-1])
    part = slice(last, None) if speed.size - last >= MIN_REGIME_SAMPLES else slice(0, last)
    sub = extract(speed[part], friction[part], config)
    shift = part.start or 0
    deltas = ext.deltas[np.searchsorted(ext.accepted, found)]
    timings = {k: v + sub.timings.get(k, 0.0) for k, v in ext.timings.items()}
    cpu = {k: v + sub.cpu_timings.get(k, 0.0) for k, v in ext.cpu_timings.items()}
    return replace(sub, detected=sub.detected + shift, accepted=sub.accepted + shift,
                   onsets=np.concatenate((found, sub.onsets + shift)),
                   onset_deltas=np.concatenate((deltas, sub.onset_deltas)),
                   start=sub.start + shift, timings=timings, cpu_timings=cpu)


def onsets(ext: Extraction, n: int, systems: Sequence[SwitchingSystem]) -> np.ndarray:
    """Return the accepted changepoints that no FSS can have made (sorted indices).

    A changepoint is one when it is the only one assigned to its FSS in the window and
    the sojourn before it (at least its index: it began before the window) or after it
    (at least to the window's end) is longer than the FSS's longest residence: the FSS
    would have had to jump again, and every FSS jump of the model is far above the noise
    (so not missed by stage 1). The assignment's floor score (LOG_FLOOR) lets such a
    jump through so that a window breaking the model still gets an explanation; here it
    is named for what it is. A window of at most twice the longest residence can hold
    no onset of that FSS at its middle (e.g. the bus's 3-hour, 43,200-sample records
    against Example 2's 30,000).
    """
    found = []
    for s, system in enumerate(systems, start=1):
        mine = ext.accepted[ext.systems_of == s]
        longest = max(hi for _, hi in system.residence)
        if mine.size == 1 and max(int(mine[0]), n - int(mine[0])) > longest:
            found.append(int(mine[0]))
    return np.array(sorted(found), dtype=np.int64)


def _extract_once(speed: np.ndarray, friction: np.ndarray, config: FssConfig
                  ) -> Extraction:
    """Run stages 1-3 on one window of normalised, paper-sign signals.

    The noise variance is estimated twice: robustly from differences for the stage-1
    threshold, then from the stage-2 residuals for the rejection costs (c_i / 2 sigma^2).
    After the assignment the intervals are refitted without the rejected changepoints,
    so that Algorithm 1 sees the merged intervals' coefficients.
    """
    if speed.shape != friction.shape or speed.ndim != 1:
        raise ValueError('speed and friction must be 1-D arrays of the same length')
    n = speed.size
    timings = {}
    t0, c0 = _time.perf_counter(), _time.thread_time()
    detected = _changepoints(speed, friction, config)
    t1, c1 = _time.perf_counter(), _time.thread_time()
    fit = fit_intervals(friction, speed, detected, dk_error=config.dk_error,
                        viscous_prior=config.viscous_prior)
    t2, c2 = _time.perf_counter(), _time.thread_time()
    sigma2 = fit.sigma2 if np.isfinite(fit.sigma2) and fit.sigma2 > 0 else 1.0
    signs = np.where(np.diff(fit.dry) >= 0, 1, -1)
    assignment = assign_changepoints(fit.changepoints, signs,
                                     fit.rejection_cost / (2.0 * sigma2), n,
                                     config.systems, beam=config.beam)
    keep = assignment.inputs > 0
    accepted = fit.changepoints[keep]
    refit = fit_intervals(friction, speed, accepted, dk_error=config.dk_error,
                          viscous_prior=config.viscous_prior)
    if refit.changepoints.size != accepted.size:  # an interval emptied by the merge
        keep = np.isin(fit.changepoints, refit.changepoints) & keep
        accepted = refit.changepoints
    inputs = assignment.inputs[keep]
    configs = np.vstack([assignment.configs[0], assignment.configs[1:][keep]])
    base, levels, qs = friction_levels(refit.dry, inputs, configs, len(config.systems))
    base_se = combination_se(refit, friction, speed,
                             base_dry_weights(refit.dry, inputs, len(config.systems)),
                             dk_error=config.dk_error)
    t3, c3 = _time.perf_counter(), _time.thread_time()
    timings.update(changepoints=t1 - t0, least_squares=t2 - t1, assignment=t3 - t2)
    cpu = {'changepoints': c1 - c0, 'least_squares': c2 - c1, 'assignment': c3 - c2}
    return Extraction(detected=detected, accepted=accepted, systems_of=inputs,
                      deltas=np.diff(refit.dry), base_dry=base, viscous=refit.viscous,
                      levels=levels, configs=qs, sigma=float(np.sqrt(refit.sigma2)),
                      rmse=refit.rmse, rejected=int(np.sum(assignment.inputs == 0)),
                      iterations=assignment.iterations, exact=assignment.exact,
                      identifiable=refit.identifiable, viscous_se=refit.viscous_se,
                      base_dry_se=base_se,
                      timings=timings, cpu_timings=cpu)


def _changepoints(speed: np.ndarray, friction: np.ndarray, config: FssConfig) -> np.ndarray:
    """Return stage 1's changepoints, the wGLR run on the finite samples only.

    Samples left out (non-finite, or skipped by a calibration: its low-speed band and
    speeds outside its range) are removed before the wGLR and the indices mapped back,
    so that a jump inside a gap is found at the first sample after it (in the full
    series a gap empties one side of the window and the statistic is 0 there: the jump
    would be missed and its two levels fitted as one).
    """
    finite = np.flatnonzero(np.isfinite(speed) & np.isfinite(friction))
    if finite.size < 4:
        return np.zeros(0, dtype=np.int64)
    cps = detect_changepoints(friction[finite], speed[finite], window=config.wglr_window,
                              w_bias=config.w_bias, viscous_prior=config.viscous_prior,
                              p_false=config.p_false)
    return finite[cps.changepoints]


def plausible(speed_rad_s: np.ndarray, friction_nm: np.ndarray, config: FssConfig
              ) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Return (speed, friction) with untestable samples NaN, and the counts by reason.

    A sample is not tested when a value is not finite (``non_finite``) or at or beyond
    the plausibility limits ``max_abs_speed`` / ``max_abs_friction`` (``out_of_range``):
    the limits and the reasons of the LLR detector (core/llr_kernel.py ``accept``), so
    that a value no wheel can produce (1e300 N m) never reaches the least squares, where
    it overflowed the sums (a viscous flag from a 1e300 column, an infinite noise
    estimate, an assignment without a finite score).
    """
    speed = np.array(speed_rad_s, dtype=float)
    friction = np.array(friction_nm, dtype=float)
    finite = np.isfinite(speed) & np.isfinite(friction)
    with np.errstate(invalid='ignore'):
        inside = (np.abs(speed) < config.max_abs_speed) & (
            np.abs(friction) < config.max_abs_friction)
    speed[~(finite & inside)] = np.nan
    friction[~(finite & inside)] = np.nan
    return speed, friction, {keys.NON_FINITE: int(np.count_nonzero(~finite)),
                             keys.OUT_OF_RANGE: int(np.count_nonzero(finite & ~inside))}


def normalise(speed_rad_s: np.ndarray, friction_nm: np.ndarray, config: FssConfig
              ) -> tuple[np.ndarray, np.ndarray]:
    """Return (speed, friction) in normalised units and paper sign from SI telemetry."""
    return (np.asarray(speed_rad_s, dtype=float) / config.speed_scale_rad_s,
            -np.asarray(friction_nm, dtype=float) / config.torque_scale_nm)


def diagnose(speed_rad_s: np.ndarray, friction_nm: np.ndarray, time_s: np.ndarray,
             classifier: WindowClassifier, config: FssConfig = FssConfig()) -> dict:
    """Return one wheel's window diagnosis (DESIGN.md "Window diagnosis"), SI units.

    Parameters
    ----------
    speed_rad_s, friction_nm, time_s : ndarray, shape (n,)
        The window's speed (rad/s), friction (N m) and stamps (s); non-finite samples
        and samples beyond the plausibility limits are skipped by the stages
        (:func:`plausible`).
    classifier : WindowClassifier
        The trained classifier (``rwa_monitor.load_fss_model()``: the shipped one).
    config : FssConfig
        The stages' parameters (core/schema.py ``FSS``).

    Returns
    -------
    dict
        ``anomalies``: one boolean per anomaly; ``estimates``: base dry (N m), viscous
        (N m s/rad) and its standard error, noise std (N m), levels per FSS (N m);
        ``rejected``: samples not tested by reason (:func:`plausible`: ``non_finite``,
        ``out_of_range``); ``changepoints``: time, index, FSS and dry jump (N m) of each accepted
        changepoint; ``onsets``: index, time and dry jump (N m) of each persistent change
        inside the window (:func:`extract`), the rest describing the part diagnosed, from
        sample ``estimates['diagnosed_from_index']``; ``timings_s``: seconds per stage.
        A window most of whose samples are not tested (non-finite, or left out by a
        calibration) is ``status: unknown`` with every flag False, ``unknown_reason`` and
        ``coverage`` (core/coverage.py): never a nominal answer; with fewer tested samples
        than :func:`samples_needed` the stages do not run (estimates None).

    Examples
    --------
    >>> import numpy as np
    >>> from rwa_monitor import load_fss_model
    >>> t = np.arange(600) * 0.1
    >>> speed = 200.0 + 150.0 * np.sin(t / 20.0)
    >>> friction = -2e-4 - 5e-7 * speed + np.random.default_rng(0).normal(0, 5e-5, 600)
    >>> result = diagnose(speed, friction, t, load_fss_model())
    >>> result['anomalies']
    {'dry': False, 'viscous': False, 'fss1': False, 'fss2': False}
    """
    speed, friction, rejected = plausible(speed_rad_s, friction_nm, config)
    speed, friction = normalise(speed, friction, config)
    time_s = np.asarray(time_s, dtype=float)
    coverage = window_coverage(speed, friction, config)
    if coverage.verdict == NOT_EXAMINED:
        estimates = dict.fromkeys(('base_dry_nm', 'viscous_nms', 'noise_std_nm'))
        return _unknown({'anomalies': dict.fromkeys(classifier_flags(classifier), False),
                         'estimates': estimates, 'changepoints': [], 'onsets': [],
                         'timings_s': {}, 'rejected': rejected},
                        coverage)
    ext = extract(speed, friction, config)
    t0 = _time.perf_counter()
    flags = classifier.predict(ext.features())
    ext.timings['classification'] = _time.perf_counter() - t0
    if not ext.identifiable:
        flags['viscous'] = False
    tq = config.torque_scale_nm
    estimates = {
        'base_dry_nm': ext.base_dry * tq,
        'viscous_nms': ext.viscous * tq / config.speed_scale_rad_s,
        'noise_std_nm': ext.sigma * tq,
        'viscous_identifiable': ext.identifiable,
        'viscous_se_nms': (ext.viscous_se * tq / config.speed_scale_rad_s
                           if np.isfinite(ext.viscous_se) else None),   # None: not identified
        'changepoints_detected': int(ext.detected.size),
        'changepoints_rejected': ext.rejected,
        'assignment_exact': ext.exact,
        'diagnosed_from_index': ext.start,
    }
    for s, system in enumerate(config.systems):
        estimates[f'{system.name}_levels_nm'] = [v * tq for v in ext.levels[s]]
        estimates[f'{system.name}_configurations'] = ext.configs[s]
    changepoints = [{'index': int(k), 'time': float(time_s[k]),
                     'fss': config.systems[int(u) - 1].name, 'delta_dry_nm': float(d) * tq}
                    for k, u, d in zip(ext.accepted, ext.systems_of, ext.deltas)]
    onset_list = [{'index': int(k), 'time': float(time_s[k]), 'delta_dry_nm': float(d) * tq}
                  for k, d in zip(ext.onsets, ext.onset_deltas)]
    result = {'anomalies': {k: bool(v) for k, v in flags.items()},
              'estimates': estimates, 'changepoints': changepoints, 'onsets': onset_list,
              'timings_s': dict(ext.timings), 'rejected': rejected}
    return result if coverage.examined else _unknown(result, coverage)


def samples_needed(config: FssConfig) -> int:
    """Return the tested samples a window needs: two changepoint windows of 2 w each.

    The stage-1 statistic at a sample compares the ``w`` samples before it with the ``w``
    after it (wGLR, ``wglr_window``); two such windows give one changepoint test with an
    interval to fit on each side.
    """
    return 4 * config.wglr_window


def window_coverage(speed: np.ndarray, friction: np.ndarray, config: FssConfig) -> Coverage:
    """Return the verdict of a window: its samples, and those tested (both finite)."""
    tested = int(np.count_nonzero(np.isfinite(speed) & np.isfinite(friction)))
    return judge(speed.size, tested, samples_needed(config), 'the window diagnosis')


def classifier_flags(classifier: WindowClassifier) -> list[str]:
    """Return the anomaly names the classifier flags (DESIGN.md: dry, viscous, fss1, fss2)."""
    return list(classifier.names)


def _unknown(result: dict, coverage: Coverage) -> dict:
    """Mark a window that was mostly not tested ``unknown``: flags False, with the counts."""
    result['anomalies'] = {k: False for k in result['anomalies']}
    result['status'] = UNKNOWN
    result['unknown_reason'] = coverage.reason
    result['coverage'] = coverage.fields()
    return result


class SlidingWindow:
    """The last ``length`` samples of one wheel; a diagnosis is due every ``period``.

    ``update(t, speed, friction)`` per sample; a stamp not after the previous one is
    dropped and counted (``non_increasing_time``), so is a non-finite stamp
    (``non_finite``); non-finite values are kept (the stages skip them) and counted
    (``non_finite``); ``dropped`` is the number of samples dropped; a step between stamps
    more than ``gap_factor`` times the first step seen is counted (``gaps``) and otherwise
    ignored: the stages count in samples, so a gap only shortens the FSS residence times
    it spans.
    Memory: three arrays of ``length``.
    """

    def __init__(self, *, length: int = 80_000, period: int = 20_000,
                 gap_factor: float = 3.0) -> None:
        self.length = check_int('length', length, 100, 10**8)
        self.period = check_int('period', period, 1, 10**8)
        self.gap_factor = check_real('gap_factor', gap_factor, 1.0, low_open=True)
        self._t = np.empty(self.length)
        self._w = np.empty(self.length)
        self._f = np.empty(self.length)
        self.reset()

    def reset(self) -> None:
        """Forget every sample and counter."""
        self._count = 0
        self._since = 0
        self._last_t = -np.inf
        self._step = None
        self.non_increasing_time = 0
        self.non_finite = 0
        self.dropped = 0
        self.gaps = 0

    @property
    def size(self) -> int:
        """Samples held (at most ``length``)."""
        return min(self._count, self.length)

    def update(self, t: float, speed: float, friction: float) -> bool:
        """Add one sample; return True when a diagnosis is due."""
        if not np.isfinite(t) or t <= self._last_t:
            if np.isfinite(t):
                self.non_increasing_time += 1
            else:
                self.non_finite += 1
            self.dropped += 1
            return False
        if not (np.isfinite(speed) and np.isfinite(friction)):
            self.non_finite += 1
        if np.isfinite(self._last_t):
            step = t - self._last_t
            if self._step is None:
                self._step = step
            elif step > self.gap_factor * self._step:
                self.gaps += 1
        i = self._count % self.length
        self._t[i], self._w[i], self._f[i] = t, speed, friction
        self._count += 1
        self._since += 1
        self._last_t = t
        if self._count >= self.length and self._since >= self.period:
            self._since = 0
            return True
        return False

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return copies of (time, speed, friction), oldest first."""
        n = self.size
        start = self._count % self.length if self._count >= self.length else 0
        order = (np.arange(n) + start) % self.length
        return self._t[order], self._w[order], self._f[order]


def window_features(windows: Sequence[tuple[np.ndarray, np.ndarray]],
                    config: FssConfig = FssConfig()) -> list[Extraction]:
    """Return the extraction of each (speed, friction) window (normalised)."""
    return [extract(w, f, config) for w, f in windows]
