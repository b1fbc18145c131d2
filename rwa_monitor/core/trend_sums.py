"""One pass's level fit (core/trend.py ``pass_levels``), compiled.

``level_sums`` walks a pass once: it counts the samples left out (a non-finite value, or
``|w| < min_speed``) and accumulates, over the samples kept, the Gram matrix ``H^T H``
and ``H^T y`` of eq. (1)'s rows ``h = -[sign(w), w]``. ``residual_lag_gram`` walks it
again with the fitted levels: the residual's lag Gram matrix for the AR order selection
(llr_noise ``noise_model_from_gram``) and its sum of squares. The same sums as numpy's
matrix products, in one pass each instead of about thirty array operations
(``pass_levels`` 0.15 -> 0.09 ms of CPU on a pass of 6000 samples, this machine); they
differ from them only in rounding (relative 3e-11 at most on the levels of 300 random
passes). ``pass_fit`` is the whole fit in one call: both walks, the 2x2 normal equations,
the AR order (llr_noise ``select_ar_order``) and the parts of the standard errors, in
the order and with the LAPACK calls of the numpy steps it replaced, so the floats are
theirs (all 3,360 pass-wheels of bench fleet's archive): ``pass_levels`` 41 -> 30 us on a
pass of 6000 samples alone, bench fleet's trend levels inside the steps 0.29 -> 0.14 s.
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core.jit import njit
from rwa_monitor.core.llr_noise import select_ar_order

__all__ = ['ESTIMATED', 'FIT_FIELDS', 'MAX_AR_ORDER', 'NOT_EXCITED', 'TOO_FEW_SAMPLES',
           'level_sums', 'pass_fit', 'residual_lag_gram']

# pass_fit's result: these floats, then the AR coefficients (``ar_order`` of them).
FIT_FIELDS = ('kept', 'nonfinite', 'slow', 't_min', 't_max', 'dry', 'viscous',
              'innovation_variance', 'residual_variance', 'inverse_dry', 'inverse_viscous',
              'ar_order', 'reason')
MAX_AR_ORDER = 10
ESTIMATED, TOO_FEW_SAMPLES, NOT_EXCITED = 0, 1, 2

# Lags whose autocorrelation sums _autocorrelation keeps in scalars (more: an array).
UNROLLED_LAGS = 3


@njit('UniTuple(float64, 10)(float64[::1], float64[::1], float64[::1], float64)',
      cache=True)
def level_sums(t: np.ndarray, w: np.ndarray, y: np.ndarray, min_speed: float) -> tuple:
    """Return (kept, nonfinite, slow, t_min, t_max, g00, g01, g11, b0, b1).

    ``g`` = ``H^T H`` and ``b`` = ``H^T y`` over the kept samples, ``h = -[sign(w), w]``.
    """
    kept = 0
    nonfinite = 0
    slow = 0
    t_min = np.inf
    t_max = -np.inf
    g00 = 0.0
    g01 = 0.0
    g11 = 0.0
    b0 = 0.0
    b1 = 0.0
    for i in range(t.size):
        ti = t[i]
        wi = w[i]
        yi = y[i]
        if not (np.isfinite(ti) and np.isfinite(wi) and np.isfinite(yi)):
            nonfinite += 1
            continue
        if abs(wi) < min_speed:
            slow += 1
            continue
        kept += 1
        t_min = min(t_min, ti)
        t_max = max(t_max, ti)
        h0 = -1.0 if wi > 0.0 else (1.0 if wi < 0.0 else 0.0)
        h1 = -wi
        g00 += h0 * h0
        g01 += h0 * h1
        g11 += h1 * h1
        b0 += h0 * yi
        b1 += h1 * yi
    return (float(kept), float(nonfinite), float(slow), t_min, t_max, g00, g01, g11, b0,
            b1)


@njit('float64[:, ::1](float64[::1], float64[::1], float64[::1], float64, float64, '
      'float64, int64, int64)', cache=True)
def residual_lag_gram(t: np.ndarray, w: np.ndarray, y: np.ndarray, min_speed: float,
                      dry: float, viscous: float, kept: int, top: int) -> np.ndarray:
    """Return the residual's lag Gram matrix with its sum of squares in one more row.

    Residual ``e = y - h x`` over the samples :func:`level_sums` kept, in order.
    ``out[i, j]`` (``i, j <= top``) = sum over ``k = top .. kept-1`` of ``e[k-i] e[k-j]``
    (llr_noise ``lag_gram``); ``out[top + 1, 0]`` = ``e @ e``.
    """
    e = np.empty(kept)
    k = 0
    for i in range(t.size):
        ti = t[i]
        wi = w[i]
        yi = y[i]
        if not (np.isfinite(ti) and np.isfinite(wi) and np.isfinite(yi)):
            continue
        if abs(wi) < min_speed:
            continue
        h0 = -1.0 if wi > 0.0 else (1.0 if wi < 0.0 else 0.0)
        e[k] = yi - (h0 * dry - wi * viscous)
        k += 1
    r = _autocorrelation(e, top)
    out = np.zeros((top + 2, top + 1))
    for a in range(top + 1):
        for b in range(a, top + 1):
            lag = b - a
            acc = r[lag]
            for u in range(lag, top - a):
                acc -= e[u] * e[u - lag]
            for u in range(kept - a, kept):
                acc -= e[u] * e[u - lag]
            out[a, b] = acc
            out[b, a] = acc
    out[top + 1, 0] = r[0]
    return out


@njit(cache=True, inline='always')
def _autocorrelation(e: np.ndarray, top: int) -> np.ndarray:
    """Return ``r[l]`` = sum over ``u = l .. e.size-1`` of ``e[u] e[u-l]``, ``l <= top``.

    Each ``r[l]`` adds its terms in increasing ``u``, one addition after the other (the
    same floats as any loop order that keeps that). Up to ``UNROLLED_LAGS`` lags (the AR
    orders the trend tries, llr_noise.DEFAULT_AR_ORDER) the sums live in four scalars
    walked together: 4 us instead of 18 us for 6000 samples, where the sums kept in an
    array were stored and reloaded at every term (``pass_levels`` 83 -> 71 us a pass, median
    of 9 runs over 840 pass-wheels of bench fleet's archive; the same floats on all).
    """
    n = e.size
    r = np.zeros(top + 1)
    if top > UNROLLED_LAGS:
        for u in range(n):
            eu = e[u]
            for lag in range(min(top, u) + 1):
                r[lag] += eu * e[u - lag]
        return r
    r0 = r1 = r2 = r3 = 0.0
    for u in range(n):
        eu = e[u]
        r0 += eu * eu
        if u >= 1:
            r1 += eu * e[u - 1]
        if u >= 2:
            r2 += eu * e[u - 2]
        if u >= 3:
            r3 += eu * e[u - 3]
    for lag, value in enumerate((r0, r1, r2, r3)):
        if lag <= top:
            r[lag] = value
    return r


@njit('float64[::1](float64[::1], float64[::1], float64[::1], float64, int64, int64, '
      'float64)', cache=True)
def pass_fit(t: np.ndarray, w: np.ndarray, y: np.ndarray, min_speed: float,
             max_ar_order: int, min_samples: int, min_excitation: float) -> np.ndarray:
    """Return one pass's levels and what their standard errors are made of.

    The values of ``FIT_FIELDS`` then the AR coefficients, NaN where not reached.
    Levels: the normal equations of eq. (2) scaled to a unit diagonal, refused when fewer
    than ``min_samples`` are kept (``reason`` TOO_FEW_SAMPLES) or when the correlation of
    the two columns has a determinant below ``min_excitation`` (NOT_EXCITED). Noise: the
    residual's AR model as llr_noise ``select_ar_order`` picks it (up to ``max_ar_order``,
    at least 10 residuals per order, llr_noise ``lag_top``), its innovation variance and
    the residual's variance (2 parameters fitted); ``inverse_*``: the diagonal of ``(H^T
    H)^-1``. core/trend.py combines them in Python's own float powers, as
    llr_noise ``noise_model_from_gram`` does (compiled, ``x ** 2`` is ``x * x``, which
    C's ``pow`` does not always round alike).
    """
    kept, nonfinite, slow, t_min, t_max, g00, g01, g11, b0, b1 = level_sums(
        t, w, y, min_speed)
    out = np.full(len(FIT_FIELDS) + MAX_AR_ORDER, np.nan)
    out[0], out[1], out[2], out[3], out[4] = kept, nonfinite, slow, t_min, t_max
    n = int(kept)
    if n < min_samples:
        out[12] = TOO_FEW_SAMPLES
        return out
    d0, d1 = math.sqrt(g00), math.sqrt(g11)
    if not (d0 > 0 and d1 > 0):
        out[12] = NOT_EXCITED
        return out
    correlation = np.empty((2, 2))
    correlation[0, 0], correlation[0, 1] = g00 / (d0 * d0), g01 / (d0 * d1)
    correlation[1, 0], correlation[1, 1] = g01 / (d1 * d0), g11 / (d1 * d1)
    if np.linalg.det(correlation) < min_excitation:
        out[12] = NOT_EXCITED
        return out
    right = np.empty(2)
    right[0], right[1] = b0 / d0, b1 / d1
    scaled = np.linalg.solve(correlation, right)
    dry, viscous = scaled[0] / d0, scaled[1] / d1
    top = min(max_ar_order, MAX_AR_ORDER, max((n - 10) // 10, 0))
    lags = residual_lag_gram(t, w, y, min_speed, dry, viscous, n, top)
    ar, s2u = select_ar_order(np.ascontiguousarray(lags[:top + 1]), n)
    gram = np.empty((2, 2))
    gram[0, 0], gram[0, 1], gram[1, 0], gram[1, 1] = g00, g01, g01, g11
    inverse = np.linalg.solve(gram, np.eye(2))     # as numpy's inv (gesv on I)
    out[5], out[6], out[7] = dry, viscous, s2u
    out[8] = max(lags[top + 1, 0] / max(n - 2, 1), 1e-300)
    out[9], out[10], out[11], out[12] = inverse[0, 0], inverse[1, 1], ar.size, ESTIMATED
    out[13:13 + ar.size] = ar
    return out
