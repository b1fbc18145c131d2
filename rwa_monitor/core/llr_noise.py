"""The noise model of the LLR detector: AR prewhitening and a level growing with speed.

Not in the paper (whose Lemma 1 assumes white noise of known level; docs/llr.md "Noise
beyond white", "Noise growing with speed"): the model is fitted on the first accepted
samples (:func:`fit_noise_model`), which wait in a buffer meanwhile; every sample is then
divided by the modelled level and AR-filtered before it enters the sums (for the paper's
model in the compiled kernel, core/llr_kernel.py). The buffering and replay are
core/llr_samples.py; this module is the model's arithmetic only.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from rwa_monitor.core import llr_stats
from rwa_monitor.core.jit import njit
from rwa_monitor.core.schema import LLR_AUTO_AR_ORDER

# The order of ``noise_ar_max_order`` auto (its range: core/schema.py).
DEFAULT_AR_ORDER = LLR_AUTO_AR_ORDER
# Noise growing with speed (docs/llr.md "Noise growing with speed"): the fit segment is
# extended until |w| spans at least this fraction of its largest value, or this many times
# noise_fit_samples; the slope of the noise level is used only if its t value exceeds
# SPEED_SLOPE_Z; the modelled level is floored at its value at the slowest fitted sample
# and at SPEED_FLOOR x its value at the mean |w|.
SPEED_SPREAD = 0.5
SPEED_FIT_CAP = 20
SPEED_SLOPE_Z = 3.2905267314918945
SPEED_FLOOR = 0.1


@dataclass(frozen=True)
class NoiseModel:
    """Autoregressive model of the friction residual fitted on the first reference (a record).

    ``e_l = sum_i ar[i] e_(l-1-i) + u_l``; ``innovation_std`` = std of ``u``,
    ``residual_std`` = std of ``e``, ``long_run_ratio`` = long-run variance of ``e`` over
    its variance (``sigma_u^2 / (1 - sum ar)^2 / sigma_e^2``; 1 for white noise): the factor
    by which the plain statistic would be too large for slowly varying regressors.
    ``speed_std = (a, b, floor)``: the noise level is ``max(a + b |w|, floor)`` (relative
    units; None: constant), each sample is divided by it before the AR filter.
    """

    ar: tuple[float, ...]
    innovation_std: float
    residual_std: float
    long_run_ratio: float
    speed_std: tuple[float, float, float] | None = None


def fit_noise_model(h: np.ndarray, f: np.ndarray, max_order: int,
                    abs_speed: np.ndarray | None = None) -> NoiseModel:
    """Fit the friction model and an AR model of its residual; order by BIC.

    Not in the paper (whose Lemma 1 assumes white noise). ``h``: regressor rows ``(n,
    p)``, ``f``: friction ``(n,)``. Least squares ``x`` (eq. (2)), residual ``e = f - h
    x``, then for each order ``q <= max_order`` the conditional least-squares AR fit of
    ``e[Q:]`` on its ``q`` lags (common targets, ``Q = max_order``) and
    ``BIC_q = (n - Q) log(RSS_q / (n - Q)) + q log(n - Q)``; the order with the smallest
    BIC whose characteristic roots lie inside the unit circle is kept (0: white noise,
    the paper's case). With ``abs_speed`` (``|w|`` of the rows) the noise level is first
    modelled against it (:func:`fit_speed_std`) and rows, friction and residual are divided
    by that level (weighted least squares) before the AR fit. Deterministic for given
    arrays, so the streaming and the batch path fit the same model.
    """
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float)
    speed_std = None
    if abs_speed is not None:
        speed_std = fit_speed_std(h, f, np.asarray(abs_speed, dtype=float))
        if speed_std is not None:
            scale = speed_scale(np.asarray(abs_speed, dtype=float), speed_std)
            h = h / scale[:, None]
            f = f / scale
    pi = h.T @ h
    x = llr_stats.solve_scaled(pi, h.T @ f)
    return residual_noise_model(f - h @ x, h.shape[1], max_order, speed_std)


def residual_noise_model(e: np.ndarray, fitted: int, max_order: int,
                         speed_std: tuple[float, float, float] | None = None) -> NoiseModel:
    """Return the AR model of a least-squares residual ``e`` (``fitted`` parameters).

    The order selection of :func:`fit_noise_model` (:func:`noise_model_from_gram` on the
    residual's :func:`lag_gram`).
    """
    e = np.asarray(e, dtype=float)
    top = lag_top(e.size, max_order)
    return noise_model_from_gram(lag_gram(e, top), e.size, float(e @ e), fitted, speed_std)


def lag_top(n: int, max_order: int) -> int:
    """Return the highest AR order tried on ``n`` residuals (at least 10 per order)."""
    return int(min(max_order, max((n - 10) // 10, 0)))


def lag_gram(e: np.ndarray, top: int) -> np.ndarray:
    """Return ``gram[i, j]``: over the common targets ``e[top:]``, e lagged i times e lagged j."""
    n = e.size
    lagged = np.column_stack([e[top - i:n - i] for i in range(top + 1)])
    return lagged.T @ lagged


def noise_model_from_gram(gram: np.ndarray, n: int, sum_squares: float, fitted: int,
                          speed_std: tuple[float, float, float] | None = None
                          ) -> NoiseModel:
    """Return the AR model of a residual of ``n`` samples from its lag Gram matrix.

    The order by :func:`select_ar_order`; ``sum_squares`` is ``e @ e``, ``fitted`` the
    parameters the residual was fitted with.
    """
    ar, s2u = select_ar_order(np.ascontiguousarray(gram, dtype=float), int(n))
    coefficients = tuple(float(a) for a in ar)
    s2e = max(sum_squares / max(n - fitted, 1), 1e-300)
    ratio = s2u / (1.0 - sum(coefficients)) ** 2 / s2e
    return NoiseModel(coefficients, math.sqrt(s2u), math.sqrt(s2e), ratio, speed_std)


@njit('Tuple((float64[::1], float64))(float64[:, ::1], int64)', cache=True)
def select_ar_order(gram: np.ndarray, n: int) -> tuple:
    """Return the AR coefficients and innovation variance of the order BIC selects.

    Conditional least squares of ``e[Q:]`` on its ``q`` lags for each ``q <= Q`` (``Q`` =
    ``gram``'s size - 1; common targets), solved by the normal equations of the lag Gram
    matrix (the lags of a residual are far from collinear, so this equals the orthogonal
    solution to rounding, at a fraction of its cost); ``BIC_q`` as in
    :func:`fit_noise_model`; an order is kept only if its characteristic roots lie inside
    the unit circle (checked only for an order whose BIC would win); a singular order is
    skipped. Compiled (the detector's calibration and every pass level of the fleet's
    trend call it): 21 -> 4 us for ``Q = 3`` against the same steps in numpy calls, the
    same floats (20,000 random lag Gram matrices).
    """
    top = gram.shape[0] - 1
    m = n - top
    best_bic = np.inf
    best = np.zeros(0)
    best_s2 = 0.0
    for q in range(top + 1):
        if q == 0:
            coef = np.zeros(0)
            rss = gram[0, 0]
        else:
            lags = np.ascontiguousarray(gram[1:q + 1, 1:q + 1])
            right = np.ascontiguousarray(gram[1:q + 1, 0])
            try:
                coef = np.linalg.solve(lags, right)
            except Exception:  # noqa: BLE001 - singular: this order is not fitted
                continue
            rss = gram[0, 0] - 2.0 * np.dot(coef, right) + np.dot(np.dot(coef, lags), coef)
        s2 = max(rss / m, 1e-300)
        bic = m * math.log(s2) + q * math.log(m)
        if bic < best_bic and (q == 0 or _stationary(coef)):
            best_bic, best, best_s2 = bic, coef, s2
    return best, best_s2


@njit(cache=True)
def _stationary(coef: np.ndarray) -> bool:
    """Return True if the roots of ``1 - sum coef[i] z^-(i+1)`` lie inside |z| < 0.999."""
    polynomial = np.empty(coef.size + 1, dtype=np.complex128)
    polynomial[0] = 1.0
    for i in range(coef.size):
        polynomial[i + 1] = -coef[i]
    return bool(np.all(np.abs(np.roots(polynomial)) < 0.999))


def fit_speed_std(h: np.ndarray, f: np.ndarray, abs_speed: np.ndarray
                  ) -> tuple[float, float, float] | None:
    """Return ``(a, b, floor)`` of a noise level growing with speed, or None if constant.

    Not in the paper. Least-squares residual ``e`` of the model, then ``|e|`` regressed on
    ``(1, |w|)``: ``E|e| = sqrt(2 / pi) (a' + b' |w|)`` for Gaussian noise whose std is
    linear in ``|w|``, so ``a + b |w|`` is proportional to the std (the scale is irrelevant:
    the level itself is estimated by the detector). Kept only if ``b`` is significant
    (``t > SPEED_SLOPE_Z``, one-sided 5e-4) and positive. ``floor``: the level at the
    smallest ``|w|`` of the fit (no extrapolation towards rest, where the intercept is
    least certain: slower samples are weighted as if at that speed, the conservative
    side), at least ``SPEED_FLOOR (a + b mean|w|)`` (positive).
    """
    x = llr_stats.solve_scaled(h.T @ h, h.T @ f)
    y = np.abs(f - h @ x)
    design = np.column_stack([np.ones_like(abs_speed), abs_speed])
    gram = design.T @ design
    if not np.linalg.det(gram) > 1e-12 * gram[0, 0] * gram[1, 1]:
        return None
    coef = np.linalg.solve(gram, design.T @ y)
    resid = y - design @ coef
    dof = max(y.size - 2, 1)
    s2 = float(resid @ resid) / dof
    se_b = math.sqrt(s2 * float(np.linalg.inv(gram)[1, 1]))
    a, b = float(coef[0]), float(coef[1])
    if not (se_b > 0.0 and b / se_b > SPEED_SLOPE_Z):
        return None
    floor = max(a + b * float(np.min(abs_speed)),
                SPEED_FLOOR * (a + b * float(np.mean(abs_speed))))
    return a, b, floor


def speed_scale(abs_speed, speed_std: tuple[float, float, float]):
    """Return the modelled noise level ``max(a + b |w|, floor)`` (scalar or array)."""
    a, b, floor = speed_std
    if isinstance(abs_speed, np.ndarray):
        return np.maximum(a + b * abs_speed, floor)
    level = a + b * abs_speed
    return level if level > floor else floor


def speed_fit_ready(count: int, fit_n: int, low: float, high: float) -> bool:
    """Return True when ``count`` buffered samples may fit a speed-dependent noise model.

    At least ``fit_n`` samples, and ``|w|`` spanning ``[low, high]`` with ``high - low >=
    SPEED_SPREAD high`` (a slope needs speeds), or ``SPEED_FIT_CAP fit_n`` samples.
    """
    return count >= fit_n and (high - low >= SPEED_SPREAD * high
                               or count >= SPEED_FIT_CAP * fit_n)


def speed_fit_done(count: int, fit_n: int, model: NoiseModel) -> bool:
    """Return True if a fit on ``count`` samples is final (else retry ``fit_n`` later).

    Final when the noise level was found to grow with speed, or at ``SPEED_FIT_CAP
    fit_n`` samples (a constant level then, as without the speed model).
    """
    return model.speed_std is not None or count >= SPEED_FIT_CAP * fit_n


def whiten(values: np.ndarray, ar: tuple[float, ...]) -> np.ndarray:
    """Return ``v_l - sum_i ar[i] v_(l-1-i)`` along axis 0 (missing lags omitted).

    The operations and their order are those of the streaming detector's per-sample
    filter (subtract lag 1, then lag 2, ...), so both paths whiten to the same floats.
    """
    values = np.asarray(values, dtype=float)
    out = values.copy()
    for i, a in enumerate(ar):
        out[i + 1:] -= a * values[:values.shape[0] - i - 1]
    return out
