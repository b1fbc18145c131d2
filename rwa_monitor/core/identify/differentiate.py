"""Friction from speed: local-polynomial differentiation with its noise propagated.

Implements eq. (1b) of the physics-informed paper, f = J dw/dt - K_T I, with one
departure: the paper's central difference (w[k+1] - w[k-1]) / (t[k+1] - t[k-1]) is
replaced by the slope of a local polynomial (order 2, 2h+1 samples, any spacing). The
central difference is the h = 1, order 1 case; a wider window trades bias (curvature of
the speed over the window) for noise. The derivative is linear in the speeds,
dw/dt[i] = sum_j g[i, j] w[j], so white speed noise of standard deviation s gives
derivative noise of standard deviation s * sqrt(sum_j g[i, j]^2): that gain is returned
with every derivative and propagated to the friction noise floor. The derivative noise is
correlated over 2h samples (overlapping windows); docs/identify.md says how the
whiteness test allows for it.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.params import check_int

_MAD_TO_STD = 1.4826


def _uniform(time: np.ndarray) -> bool:
    """Return True when the samples are equally spaced (to 1e-9 of the step)."""
    step = np.diff(time)
    return bool(len(step) and np.ptp(step) <= 1e-9 * abs(float(np.mean(step))))


def _local_fit_weights(time: np.ndarray, half_width: int, order: int, force: bool = False
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Return (window indices (n, m), weights (n, order + 1, m)) of local polynomial fits.

    Row i of the weights maps the window's values to the polynomial's coefficients in
    powers of (t - t[i]); windows are shifted inward at the ends (same width).
    """
    n = len(time)
    m = 2 * half_width + 1
    start = np.clip(np.arange(n) - half_width, 0, n - m)
    idx = start[:, None] + np.arange(m)[None, :]
    if not force and n > 2 * m and _uniform(time):
        # Uniform sampling: every interior row has the same weights; compute one record
        # of 2m samples (left edges, interior, right edges) and broadcast the interior.
        _, few = _local_fit_weights(time[:2 * m], half_width,
                                    order, force=True)
        coef = np.empty((n, order + 1, m))
        coef[:half_width] = few[:half_width]
        coef[half_width:n - half_width] = few[half_width]
        coef[n - half_width:] = few[2 * m - half_width:]
        return idx, coef
    dt = time[idx] - time[:, None]
    scale = np.max(np.abs(dt), axis=1)
    scale[scale == 0] = 1.0
    u = dt / scale[:, None]
    powers = u[:, :, None] ** np.arange(order + 1)[None, None, :]      # (n, m, q)
    gram = np.einsum('nmp,nmq->npq', powers, powers)
    try:
        coef = np.linalg.solve(gram, np.transpose(powers, (0, 2, 1)))  # (n, q, m)
    except np.linalg.LinAlgError:
        # A window whose times are degenerate at double precision (a stamp 1e300 s
        # away from its neighbours): the least-norm fit keeps every weight finite.
        coef = np.linalg.pinv(powers)                                  # (n, q, m)
    coef /= scale[:, None, None] ** np.arange(order + 1)[None, :, None]
    return idx, coef


def local_polynomial_derivative(time: np.ndarray, values: np.ndarray, half_width: int = 5,
                                order: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Return (dvalues/dt, noise gain sqrt(sum g^2)) at every sample.

    ``time`` must be strictly increasing and finite, ``values`` finite, and there must be
    at least 2 * half_width + 1 samples.
    """
    half_width = check_int('half_width', half_width, 1, 1000)
    order = check_int('order', order, 1, 2 * half_width)
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    if len(time) < 2 * half_width + 1:
        raise ValueError(f'need at least {2 * half_width + 1} samples to differentiate, '
                         f'got {len(time)}')
    idx, coef = _local_fit_weights(time, half_width, order)
    slope = coef[:, 1, :]
    return np.sum(slope * values[idx], axis=1), np.sqrt(np.sum(slope ** 2, axis=1))


def local_polynomial_smooth(time: np.ndarray, values: np.ndarray, half_width: int,
                            order: int = 2) -> np.ndarray:
    """Return the local polynomial's value at every sample (windows shifted at the ends)."""
    time = np.asarray(time, dtype=float)
    idx, coef = _local_fit_weights(time, half_width, order)
    return np.sum(coef[:, 0, :] * np.asarray(values, dtype=float)[idx], axis=1)


def local_noise_std(time: np.ndarray, values: np.ndarray, half_width: int = 5,
                    order: int = 2, block: int = 0, exclude: np.ndarray | None = None
                    ) -> np.ndarray:
    """Return a robust estimate of the white-noise standard deviation of ``values``.

    The residual of each sample from the local polynomial through its window has variance
    s^2 (1 - 2 g_ii + sum_j g_ij^2) under white noise; its median absolute value (times
    1.4826) over the whole record, or over blocks of ``block`` samples when block > 0,
    estimates s robustly (jumps and rare spikes do not move a median). Returned per
    sample (constant when block == 0). Samples flagged in ``exclude`` (e.g. windows that
    straddle a zero crossing of the speed, where friction jumps by 2 x dry) are left out
    of the medians unless a block would keep fewer than 20 samples.
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    idx, coef = _local_fit_weights(time, half_width, order)
    level = coef[:, 0, :]
    n = len(time)
    own = level[np.arange(n), np.arange(n) - idx[:, 0]]
    factor = np.sqrt(np.maximum(1.0 - 2.0 * own + np.sum(level ** 2, axis=1), 1e-12))
    scaled = np.abs(values - np.sum(level * values[idx], axis=1)) / factor
    use = np.ones(n, dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)

    def robust(part: slice) -> float:
        kept = scaled[part][use[part]]
        return _MAD_TO_STD * float(np.median(kept if len(kept) >= 20 else scaled[part]))
    if block <= 0 or block >= n:
        return np.full(n, robust(slice(0, n)))
    out = np.empty(n)
    for start in range(0, n, block):
        stop = start + block if n - (start + block) >= block // 2 else n
        out[start:stop] = robust(slice(start, stop))
        if stop == n:
            break
    return out


HALF_WIDTHS = (2, 3, 4, 5, 7, 9, 12, 15, 20, 25)


def choose_half_width(time: np.ndarray, values: np.ndarray,
                      candidates: tuple[int, ...] = HALF_WIDTHS) -> tuple[int, dict]:
    """Return the differentiator half width with the least estimated error, and the table.

    Mean squared error of the local-quadratic slope = noise + bias^2. Noise: s^2 sum_j
    g_ij^2 (s the speed noise, robust, from local-quadratic residuals). Bias: the
    quadratic slope is exact up to the cubic term, so bias_i = c3_i sum_j g_ij (t_j -
    t_i)^3 with c3 = w'''/6 from a local cubic over the widest window; since c3 is itself
    noisy, E[c3^2] = c3^2 + var(c3), the estimate of c3^2 is reduced by var(c3) = s^2 sum
    g3_ij^2 (and clipped at 0). Both are averaged over the samples (RMS). **Decision:**
    the identification fits a few coefficients to the whole record, so the noise averages
    down over its m = n / (2h + 1) independent windows while the bias does not: the
    chosen width minimises noise^2 / m + bias^2 (the error of a record-wide fit, not of
    one sample; minimising the per-sample error chose windows whose bias the residual
    tests then took for an effect).
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    n = len(time)
    usable = [h for h in candidates if 2 * h + 1 <= n]
    if not usable:
        raise ValueError(f'need at least {2 * min(candidates) + 1} samples to differentiate')
    wide = min(max(usable) * 2, (n - 1) // 2)
    noise = float(np.median(local_noise_std(time, values, 2, 2, 0)))
    if wide >= 3:
        idx3, coef3 = _local_fit_weights(time, wide, 3)
        c3 = np.sum(coef3[:, 3, :] * values[idx3], axis=1)
        c3_sq = np.maximum(c3 ** 2 - noise ** 2 * np.sum(coef3[:, 3, :] ** 2, axis=1), 0.0)
    else:
        c3_sq = np.zeros(n)
    table = {}
    for h in usable:
        idx, coef = _local_fit_weights(time, h, 2)
        slope = coef[:, 1, :]
        dt = time[idx] - time[:, None]
        bias_sq = c3_sq * np.sum(slope * dt ** 3, axis=1) ** 2
        var = noise ** 2 * np.sum(slope ** 2, axis=1)
        m = n / (2 * h + 1)
        table[h] = {'noise_rms': float(np.sqrt(np.mean(var))),
                    'bias_rms': float(np.sqrt(np.mean(bias_sq))),
                    'error_rms': float(np.sqrt(np.mean(var) / m + np.mean(bias_sq)))}
    best = min(table, key=lambda h: table[h]['error_rms'])
    return best, table
