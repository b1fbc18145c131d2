"""Stage 2: least squares over the intervals between changepoints, eq. (12)-(17).

One dry coefficient per interval and one shared viscous coefficient, fitted on the
samples that lie at least ``dk_error`` from a changepoint (eq. 12-13). H^T H is block
structured, so the normal equations are solved by eliminating the dry coefficients:
O(n) with per-interval sums. Departures (docs/fss.md): the dry term multiplies
sign(w_k) (eq. 4a); an interval shorter than 2 dk_error + ``min_samples`` keeps a
smaller margin (the middle ``min_samples`` samples at least); an interval left with no
usable sample (all NaN or zero speed) merges with its right neighbour (the changepoint
between them is dropped); when the speed does not vary enough to separate dry from
viscous friction the viscous coefficient is fixed at the prior and ``identifiable`` is
False. The viscous coefficient's standard error is that of least squares with white
noise: sqrt(sigma^2 / S), S the speed's sum of squares left after the per-interval
means of sign(w) (the Schur complement of the dry block).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rwa_monitor.core.params import check_int


@dataclass(frozen=True)
class IntervalFit:
    """Stage-2 output (eq. 14-17) plus the fit's noise estimate and RMSE (eq. 28)."""

    changepoints: np.ndarray   # the changepoints kept (those of empty intervals dropped)
    dry: np.ndarray            # F-hat, one per interval (len = len(changepoints) + 1)
    viscous: float
    hth: np.ndarray            # diagonal of H^T H for the dry coefficients
    rejection_cost: np.ndarray  # c_i^rjct per changepoint, eq. (17)
    sigma2: float              # residual variance RSS / (n - p)
    rmse: float                # eq. (28)
    identifiable: bool
    viscous_se: float = float('inf')   # standard error of ``viscous``: sqrt(sigma2 / S)


def _labels(n: int, cps: np.ndarray, dk_error: int, min_samples: int) -> np.ndarray:
    bounds = np.concatenate(([0], cps, [n])).astype(int)
    label = np.full(n, -1, dtype=np.int64)
    for i in range(bounds.size - 1):
        a, b = bounds[i], bounds[i + 1]
        margin = min(dk_error, max(0, (b - a - min_samples) // 2))
        lo = a + (margin if i > 0 else 0)
        hi = b - (margin if i < bounds.size - 2 else 0)
        label[lo:hi] = i
    return label


def fit_intervals(y: np.ndarray, x: np.ndarray, changepoints: np.ndarray, *,
                  dk_error: int = 10, min_samples: int = 3, viscous_prior: float = 1.0,
                  min_speed_spread: float = 1e-3) -> IntervalFit:
    """Fit eq. (14) by least squares and return the rejection costs of eq. (17).

    ``min_speed_spread``: the viscous coefficient is identifiable when the residual
    spread of the speed after removing the per-interval means of sign(w) exceeds it
    (root mean square, normalised speed units).
    """
    dk_error = check_int('dk_error', dk_error, 0)
    min_samples = check_int('min_samples', min_samples, 1)
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    n = y.size
    ok = np.isfinite(y) & np.isfinite(x)
    s = np.where(ok, np.sign(np.where(ok, x, 0.0)), 0.0)
    cps = np.unique(np.asarray(changepoints, dtype=int))
    cps = cps[(cps > 0) & (cps < n)]
    while True:
        label = _labels(n, cps, dk_error, min_samples)
        use = ok & (label >= 0)
        m = cps.size + 1
        a = np.bincount(label[use], weights=s[use] ** 2, minlength=m)
        empty = np.flatnonzero(a < 0.5)
        if empty.size == 0 or cps.size == 0:
            break
        i = int(empty[0])
        cps = np.delete(cps, min(i, cps.size - 1))
    lu, su, xu, yu = label[use], s[use], x[use], y[use]
    b = np.bincount(lu, weights=su * xu, minlength=m)
    yy = np.bincount(lu, weights=su * yu, minlength=m)
    a_safe = np.where(a > 0, a, 1.0)
    sxx = float(np.sum(xu * xu))
    denom = sxx - float(np.sum(b * b / a_safe))
    count = int(use.sum())
    identifiable = count > 0 and denom > (min_speed_spread ** 2) * count
    if identifiable:
        viscous = (float(np.sum(xu * yu)) - float(np.sum(b * yy / a_safe))) / denom
    else:
        viscous = float(viscous_prior)
    dry = np.where(a > 0, (yy - b * viscous) / a_safe, np.nan)
    resid = yu - dry[lu] * su - viscous * xu
    rss = float(np.sum(resid ** 2))
    dof = max(count - m - (1 if identifiable else 0), 1)
    cost = a[:-1] * a[1:] / np.maximum(a[:-1] + a[1:], 1e-12) * (dry[:-1] - dry[1:]) ** 2
    se = float(np.sqrt(rss / dof / denom)) if identifiable else float('inf')
    return IntervalFit(changepoints=cps, dry=dry, viscous=viscous, hth=a,
                       rejection_cost=np.nan_to_num(cost), sigma2=rss / dof,
                       rmse=float(np.sqrt(rss / max(count, 1))), identifiable=identifiable,
                       viscous_se=se)


def combination_se(fit: IntervalFit, y: np.ndarray, x: np.ndarray, weights: np.ndarray, *,
                   dk_error: int = 10, min_samples: int = 3) -> float:
    """Return the least-squares standard error of ``weights @ fit.dry`` (white noise).

    ``fit``: :func:`fit_intervals` of ``y`` on speed ``x`` with the same ``dk_error``
    and ``min_samples``. Cov(F-hat) = sigma^2 (A^-1 + A^-1 b b^T A^-1 / S) with A the diagonal
    of H^T H for the dry coefficients, b the per-interval sums of sign(w) w and S the
    Schur complement of the viscous coefficient (sigma^2 A^-1 when it is not identified):
    the Cramer-Rao bound of the combination under eq. (14) with Gaussian noise, the
    changepoints and the assignment taken as known.
    """
    x = np.asarray(x, dtype=float)
    weights = np.asarray(weights, dtype=float)
    a = fit.hth
    if weights.shape != a.shape:
        raise ValueError(f'weights must have {a.size} entries (one per interval)')
    if np.any((a <= 0) & (weights != 0)):
        return float('inf')
    a_safe = np.where(a > 0, a, 1.0)
    var = float(np.sum(weights ** 2 / a_safe))
    if fit.identifiable:
        label = _labels(x.size, fit.changepoints, dk_error, min_samples)
        use = np.isfinite(np.asarray(y, dtype=float)) & np.isfinite(x) & (label >= 0)
        s = np.sign(x[use])
        b = np.bincount(label[use], weights=s * x[use], minlength=a.size)
        denom = float(np.sum(x[use] ** 2)) - float(np.sum(b * b / a_safe))
        var += float(np.sum(weights * b / a_safe)) ** 2 / denom
    return float(np.sqrt(fit.sigma2 * var))


# fit_extra_columns: least usable samples, and least part of a column beyond model (1).
MIN_EXTRA_SAMPLES = 100
MIN_EXTRA_PART = 1.0e-3


def fit_extra_columns(y: np.ndarray, x: np.ndarray, changepoints: np.ndarray,
                      columns: np.ndarray, *, dk_error: int = 10, min_samples: int = 3,
                      rcond: float = 1.0e-9) -> tuple[np.ndarray, np.ndarray]:
    """Fit eq. (14) with extra regressor columns beside it; return their fitted part.

    Least squares of ``y`` on one dry coefficient per interval (times sign(x)), one
    viscous coefficient (times x) and ``columns`` (n, p), on the samples stage 2 uses
    (finite, at least ``dk_error`` from a changepoint). Before the fit the columns lose
    their projection on sign(x) and x over those samples, so that what model (1) can
    hold stays with the dry and viscous coefficients; a column left with less than
    MIN_EXTRA_PART of its RMS is model (1) on these samples and gets 0; columns are
    scaled to unit RMS and directions the samples cannot tell apart are cut (relative
    singular values below ``rcond``). Fewer than MIN_EXTRA_SAMPLES usable samples (or
    four per coefficient): nothing is fitted. Return (coefficients of ``columns``,
    coefficients of [sign(x), x]) such that ``columns @ c + [sign(x), x] @ d`` is the
    fitted extra part (zero projection on sign(x) and x). This is how a calibration
    learns what a wheel's nominal holds beyond model (1) without taking the FSS jumps
    for effects of speed (docs/fss.md, "Calibrated").
    """
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    columns = np.asarray(columns, dtype=float).reshape(y.size, -1)
    n, p = columns.shape
    cps = np.unique(np.asarray(changepoints, dtype=int))
    cps = cps[(cps > 0) & (cps < n)]
    label = _labels(n, cps, check_int('dk_error', dk_error, 0),
                    check_int('min_samples', min_samples, 1))
    use = np.isfinite(y) & np.isfinite(x) & np.all(np.isfinite(columns), axis=1)
    use &= (label >= 0) & (x != 0.0)
    if p == 0 or np.count_nonzero(use) < max(MIN_EXTRA_SAMPLES, 4 * (p + cps.size + 2)):
        return np.zeros(p), np.zeros(2)
    s, xu, yu, e = np.sign(x[use]), x[use], y[use], columns[use]
    model1 = np.column_stack([s, xu])
    proj = np.linalg.lstsq(model1, e, rcond=None)[0]
    perp = e - model1 @ proj
    scale = np.sqrt(np.mean(perp ** 2, axis=0))
    keep = scale > MIN_EXTRA_PART * np.sqrt(np.mean(e ** 2, axis=0))
    intervals = np.unique(label[use])
    dummies = (label[use][:, None] == intervals[None, :]) * s[:, None]
    design = np.column_stack([dummies, xu, perp[:, keep] / scale[keep]])
    coef = np.linalg.lstsq(design, yu, rcond=rcond)[0]
    c = np.zeros(p)
    c[keep] = coef[intervals.size + 1:] / scale[keep]
    return c, -proj @ c
