"""The sums of one pass's level fit (core/trend.py ``pass_levels``), compiled.

``level_sums`` walks a pass once: it counts the samples left out (a non-finite value, or
``|w| < min_speed``) and accumulates, over the samples kept, the Gram matrix ``H^T H``
and ``H^T y`` of eq. (1)'s rows ``h = -[sign(w), w]``. ``residual_lag_gram`` walks it
again with the fitted levels: the residual's lag Gram matrix for the AR order selection
(llr_noise ``noise_model_from_gram``) and its sum of squares. The same sums as numpy's
matrix products, in one pass each instead of about thirty array operations
(``pass_levels`` 0.15 -> 0.09 ms of CPU on a pass of 6000 samples, this machine); they
differ from them only in rounding (relative 3e-11 at most on the levels of 300 random
passes).
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.jit import njit

__all__ = ['level_sums', 'residual_lag_gram']

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
