"""Friction over a wheel's life: per-pass levels and their trend in time (docs/fleet.md).

Not in the papers. :func:`pass_levels` fits the dry and viscous levels of one downlink
pass of one wheel by least squares on model (1) of the llr-realtime paper (eq. (1)-(2),
``f = -f_d sign(w) - f_v w + e``; with a calibration, on ``f`` minus the nominal model, so
the levels are the change against nominal). :func:`wheel_trend` fits a straight line to a
wheel's pass levels by weighted least squares, tests a zero slope and projects the time
at which the line crosses a limit.

scipy is imported by the trend's functions when they run: a fleet worker calls
:func:`pass_levels` only. Student t's tail and quantile come from scipy.special (the
functions scipy.stats' ``t`` calls, the same floats), whose import costs a fraction of
scipy.stats' (about 0.6 s of CPU a process, which every fleet command paid).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

from rwa_monitor.core.jit import kernel_array
from rwa_monitor.core.llr_noise import DEFAULT_AR_ORDER
from rwa_monitor.core.params import check_int, check_real
from rwa_monitor.core.trend_sums import (ESTIMATED, FIT_FIELDS, NOT_EXCITED, pass_fit,
                                         TOO_FEW_SAMPLES)

SECONDS_PER_DAY = 86400.0
# Samples slower than this are dropped from a pass fit: at rest sign(w) carries no dry
# information, and near zero real wheels leave model (1) (stiction, the low-speed band of
# docs/calibration.md).
MIN_SPEED_RAD_S = 1.0
# A pass needs this many usable samples, and dry and viscous columns that are not nearly
# collinear (det of their correlation matrix above MIN_EXCITATION, as the detector's
# min_excitation), for its levels to be estimated.
MIN_PASS_SAMPLES = 20
MIN_EXCITATION = 1.0e-6
# Two-sided level of the crossing-time interval.
CROSSING_LEVEL = 0.95


@dataclass(frozen=True)
class PassLevels:
    """Dry (N m) and viscous (N m s/rad) levels of one pass of one wheel, with standard errors.

    ``samples``: samples used; ``nonfinite`` and ``slow`` (``|w| < min_speed``): samples
    dropped. Levels and errors are NaN when the pass cannot separate them (``reason``
    says why: ``too_few_samples`` or ``not_excited``; empty when estimated).
    """

    t_start: float
    t_end: float
    samples: int
    dry: float
    dry_se: float
    viscous: float
    viscous_se: float
    nonfinite: int = 0
    slow: int = 0
    ar_order: int = 0
    reason: str = ''


@dataclass(frozen=True)
class Crossing:
    """Projected time (s, telemetry time) at which a trend line reaches ``limit``.

    ``low``/``high``: the interval of times at which the line's two-sided
    ``CROSSING_LEVEL`` confidence band contains the limit (``-inf``/``inf`` where the band
    never leaves it: the slope is not known well enough to bound the crossing).
    """

    limit: float
    time: float
    low: float
    high: float


@dataclass(frozen=True)
class Trend:
    """Straight-line trend of one wheel's pass levels.

    ``slope`` per day (level units / day) with ``slope_se``; ``p_value``: two-sided test
    of a zero slope (Student t, ``dof = passes - 2``); ``intercept``: the line's level at
    time 0 of the time axis; ``scale``: the factor fitted on the given standard errors
    (sqrt of the reduced chi-square; 1 when they describe the scatter exactly);
    ``crossing``: the projection onto ``limit`` (None without limit or with a zero slope).
    NaN statistics when fewer than 3 passes have finite levels. With steps:
    ``step_times`` (s) of the steps fitted, ``step_sizes`` their sizes; ``intercept``
    and ``crossing`` are those of the line after the last step.
    """

    slope: float
    slope_se: float
    p_value: float
    intercept: float
    passes: int
    dof: int
    scale: float
    crossing: Crossing | None = None
    step_times: tuple[float, ...] = ()
    step_sizes: tuple[float, ...] = ()


def pass_levels(time: np.ndarray, speed: np.ndarray, friction: np.ndarray,
                nominal_friction: np.ndarray | None = None, *,
                min_speed: float = MIN_SPEED_RAD_S,
                max_ar_order: int = DEFAULT_AR_ORDER) -> PassLevels:
    """Return the least-squares dry and viscous levels of one pass (eq. (2)).

    Rows ``h = -[sign(w), w]`` (eq. (1), core/friction.py), target ``friction -
    nominal_friction`` (or ``friction``). Samples with any non-finite value, or ``|w| <
    min_speed``, are dropped and counted. Standard errors: the residual of the fit gets
    the project's AR noise model (llr_noise.noise_model_from_gram, fit_noise_model's order
    selection by BIC up to ``max_ar_order``); the whole fit runs compiled
    (core/trend_sums.py ``pass_fit``); the covariance is ``sigma_LR^2 (H^T H)^-1``
    with ``sigma_LR^2`` the long-run variance of the residual (its variance times
    ``long_run_ratio``), which is the sandwich covariance of least squares under serially
    correlated noise when the regressors vary slowly against the noise's correlation time
    (a wheel's speed does; white noise gives the textbook ``s^2 (H^T H)^-1``).
    """
    t, w, f = (_column(a) for a in (time, speed, friction))
    if nominal_friction is not None:
        f = f - _column(nominal_friction)
    if not t.size == w.size == f.size:
        raise ValueError(f'time, speed, friction (and nominal_friction) must have one length; '
                         f'got {t.size}, {w.size}, {f.size}')
    min_speed = check_real('min_speed', min_speed, 0.0)
    max_ar_order = check_int('max_ar_order', max_ar_order, 0, 10)
    fit = pass_fit(t, w, f, min_speed, max_ar_order, MIN_PASS_SAMPLES, MIN_EXCITATION)
    (kept, nonfinite, slow, t_min, t_max, dry, viscous, s2u, s2e, inverse_dry,
     inverse_viscous, order, code) = fit[:len(FIT_FIELDS)].tolist()
    n = int(kept)
    span = (t_min, t_max) if n else (
        (float(np.nanmin(t)), float(np.nanmax(t))) if np.isfinite(t).any() else
        (math.nan, math.nan))
    counts = {'nonfinite': int(nonfinite), 'slow': int(slow)}
    if code != ESTIMATED:
        nan = math.nan
        return PassLevels(*span, n, nan, nan, nan, nan, **counts, reason=_REASONS[int(code)])
    ar = fit[len(FIT_FIELDS):len(FIT_FIELDS) + int(order)].tolist()
    # noise_model_from_gram's long-run ratio and residual_std ** 2, in Python's floats.
    ratio = s2u / (1.0 - sum(ar)) ** 2 / s2e
    variance = math.sqrt(s2e) ** 2 * ratio
    return PassLevels(*span, n, dry, math.sqrt(variance * inverse_dry), viscous,
                      math.sqrt(variance * inverse_viscous), **counts, ar_order=int(order))


_REASONS = {ESTIMATED: '', TOO_FEW_SAMPLES: 'too_few_samples', NOT_EXCITED: 'not_excited'}


def _column(values: np.ndarray) -> np.ndarray:
    """Return ``values`` as a contiguous, writable 1-D float array (the kernels' input).

    Itself when it is one already; a read-only array is copied (jit ``kernel_array``).
    """
    if (isinstance(values, np.ndarray) and values.dtype == np.float64 and values.ndim == 1
            and values.flags.c_contiguous and values.flags.writeable):
        return values
    return kernel_array(np.asarray(values, dtype=float).reshape(-1))


def wheel_trend(times: np.ndarray, levels: np.ndarray, standard_errors: np.ndarray,
                limit: float | None = None, steps: Sequence[float] = ()) -> Trend:
    """Return the weighted least-squares line through a wheel's pass levels.

    ``times`` in s (e.g. each pass's mid time), ``levels`` and ``standard_errors`` from
    :func:`pass_levels`; passes with a non-finite value or a standard error <= 0 are left
    out. Model: ``level_i = a + b t_i + e_i``, ``e_i`` independent normal with variance
    ``sigma^2 se_i^2`` and ``sigma`` unknown (fitted: the reduced chi-square), so the
    t statistic ``b / se(b)`` has a Student t distribution with ``passes - 2`` degrees of
    freedom under a zero slope (exact under the model; docs/fleet.md lists what breaks
    it). With ``limit``: :class:`Crossing` of the line, its interval by inverting the
    confidence band of the line (Fieller's method). ``steps``: times (s) of known steps
    in the level (a confirmed step change): ``level_i = a + b t_i + sum_j c_j [t_i >=
    s_j] + e_i``, one slope through every pass and a jump at each step, so that a step
    is not read as a slope and a wear keeps all its passes (:func:`_stepped_trend`).
    """
    t = np.asarray(times, dtype=float).reshape(-1)
    y = np.asarray(levels, dtype=float).reshape(-1)
    se = np.asarray(standard_errors, dtype=float).reshape(-1)
    if not t.size == y.size == se.size:
        raise ValueError(f'times, levels and standard_errors must have one length; got '
                         f'{t.size}, {y.size}, {se.size}')
    if limit is not None:
        limit = check_real('limit', limit)
    ok = np.isfinite(t) & np.isfinite(y) & np.isfinite(se) & (se > 0)
    t, y, se = t[ok], y[ok], se[ok]
    n = int(t.size)
    columns = _step_columns(t, steps)
    if columns:
        return _stepped_trend(t, y, se, columns, limit)
    if n < 3 or np.ptp(t) == 0:
        nan = math.nan
        return Trend(nan, nan, nan, nan, n, max(n - 2, 0), nan)
    weight = 1.0 / se ** 2
    centre = float(np.sum(weight * t) / np.sum(weight))
    days = (t - centre) / SECONDS_PER_DAY
    root_w = np.sqrt(weight)
    design = np.column_stack([root_w, root_w * days])
    import scipy.linalg
    level_c, slope = scipy.linalg.lstsq(design, root_w * y)[0]
    resid = root_w * (y - level_c - slope * days)
    dof = n - 2
    scale2 = float(resid @ resid) / dof
    # Centred at the weighted mean time the two estimates are uncorrelated.
    var_c = scale2 / float(np.sum(weight))
    var_b = scale2 / float(np.sum(weight * days ** 2))
    return _trend(float(level_c), float(slope), var_c, var_b, 0.0, centre, scale2, n, dof,
                  limit)


def _trend(level_c: float, slope: float, var_c: float, var_b: float, cov_cb: float,
           centre: float, scale2: float, n: int, dof: int, limit: float | None,
           steps: tuple[float, ...] = (), sizes: tuple[float, ...] = ()) -> Trend:
    """Return the Trend of a fitted line: its t test, intercept and crossing.

    ``level_c``: the line's level at time ``centre`` (s), ``var_c``, ``var_b`` and
    ``cov_cb`` the variances of it and of the slope and their covariance.
    """
    from scipy.special import stdtr
    slope_se = math.sqrt(var_b)
    # Student t's survival function, stdtr(dof, -t) (scipy.stats' t.sf calls the same).
    p_value = (float(2.0 * stdtr(dof, -abs(slope) / slope_se)) if slope_se > 0
               else (0.0 if slope != 0 else 1.0))
    intercept = float(level_c - slope * centre / SECONDS_PER_DAY)
    crossing = None
    if limit is not None and slope != 0:
        crossing = _crossing(limit, level_c, slope, var_c, var_b, dof, centre, cov_cb)
    return Trend(slope, slope_se, p_value, intercept, n, dof, math.sqrt(scale2), crossing,
                 steps, sizes)


def _step_columns(t: np.ndarray, steps: Sequence[float]) -> dict[float, np.ndarray]:
    """Return step time -> its column ``[t >= s]``, for the steps with passes on both sides.

    A step before every pass or after the last one is not in the data; of steps with no
    pass between them, the last stands for all (their columns are equal).
    """
    out: dict[float, np.ndarray] = {}
    seen: set[bytes] = set()
    for when in sorted({float(x) for x in steps if math.isfinite(float(x))}, reverse=True):
        column = (t >= when).astype(float)
        if 0 < column.sum() < t.size and column.tobytes() not in seen:
            seen.add(column.tobytes())
            out[when] = column
    return dict(sorted(out.items()))


def _stepped_trend(t: np.ndarray, y: np.ndarray, se: np.ndarray,
                   columns: dict[float, np.ndarray], limit: float | None) -> Trend:
    """Return the trend with a jump at each step: one slope through every pass.

    Weighted least squares as :func:`wheel_trend`'s line, with a column ``[t >= s_j]``
    per step; the covariance ``sigma^2 (X' W X)^-1``, ``sigma^2`` the reduced chi-square
    with ``passes - 2 - steps`` degrees of freedom, and the t test of the slope on them.
    Time is centred at the weighted mean time after the last step, where the line's level
    (intercept plus every jump) is the one a crossing is projected from; its covariance
    with the slope enters the crossing's band. NaN statistics when the passes cannot
    separate a slope from the jumps (no segment with two distinct times, or no degree of
    freedom left).
    """
    n, k = int(t.size), len(columns)
    weight = 1.0 / se ** 2
    last = np.column_stack(list(columns.values()))[:, -1] > 0
    centre = float(np.sum(weight[last] * t[last]) / np.sum(weight[last]))
    days = (t - centre) / SECONDS_PER_DAY
    design = np.column_stack([np.ones(n), days, *columns.values()])
    root_w = np.sqrt(weight)
    weighted = design * root_w[:, None]
    dof = n - 2 - k
    times = tuple(columns)
    if dof < 1 or np.linalg.matrix_rank(weighted) < 2 + k:
        nan = math.nan
        return Trend(nan, nan, nan, nan, n, max(dof, 0), nan, None, times, (nan,) * k)
    import scipy.linalg
    beta = scipy.linalg.lstsq(weighted, root_w * y)[0]
    resid = root_w * y - weighted @ beta
    scale2 = float(resid @ resid) / dof
    cov = scale2 * scipy.linalg.inv(weighted.T @ weighted)
    slope, var_b = float(beta[1]), float(cov[1, 1])
    now = np.ones(2 + k)
    now[1] = 0.0                                        # the level after the last step
    level_c = float(now @ beta)
    var_c, cov_cb = float(now @ cov @ now), float(now @ cov[:, 1])
    return _trend(level_c, slope, var_c, var_b, cov_cb, centre, scale2, n, dof, limit,
                  times, tuple(float(c) for c in beta[2:]))


def _crossing(limit: float, level_c: float, slope: float, var_c: float, var_b: float,
              dof: int, centre: float, cov_cb: float = 0.0) -> Crossing:
    """Fieller interval of the time where ``level_c + slope u`` (u in days) equals ``limit``.

    The times ``u`` at which the limit lies inside the confidence band: ``(level_c + slope
    u - limit)^2 <= q^2 (var_c + 2 u cov_cb + u^2 var_b)``, ``q`` the two-sided t
    quantile; a quadratic ``A u^2 + B u + C <= 0``. ``A > 0`` (slope significant at that
    level): a finite interval; otherwise the set is unbounded on the side(s) the slope
    cannot exclude. ``cov_cb``: 0 for the line centred at its weighted mean time.
    """
    from scipy.special import stdtrit
    q = float(stdtrit(dof, 0.5 + CROSSING_LEVEL / 2.0))     # Student t's quantile
    gap = level_c - limit
    u_hat = -gap / slope
    a = slope ** 2 - q ** 2 * var_b
    b = 2.0 * slope * gap - 2.0 * q ** 2 * cov_cb
    c = gap ** 2 - q ** 2 * var_c
    disc = b * b - 4.0 * a * c
    if a > 0 and disc >= 0:
        roots = sorted(((-b - math.sqrt(disc)) / (2 * a), (-b + math.sqrt(disc)) / (2 * a)))
        low, high = roots
    elif a < 0 and disc > 0:
        # The band contains the limit outside the two roots: unbounded on both sides
        # of the gap; the side holding the estimate is reported.
        roots = sorted(((-b - math.sqrt(disc)) / (2 * a), (-b + math.sqrt(disc)) / (2 * a)))
        low, high = (roots[1], math.inf) if u_hat >= roots[1] else (-math.inf, roots[0])
    else:
        low, high = -math.inf, math.inf
    to_s = SECONDS_PER_DAY
    return Crossing(limit, centre + u_hat * to_s, centre + low * to_s, centre + high * to_s)
