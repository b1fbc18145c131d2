"""Stage 1: windowed GLR changepoint detection with a viscous prior, eq. (10)-(11).

For every sample k the statistic compares a jump of the dry coefficient at k (dry f1 on
``[k - w, k)``, f2 on ``[k, k + w)``, one shared viscous f^v) with no jump, each
maximised over its parameters with the Gaussian prior on f^v. With the noise Gaussian,
log P = -RSS / (2 sigma^2); we write the penalised sum of squares
S = sum (f_k - f^d s_k - f^v w_k)^2 + W_b (f^v - f~v)^2 and
wGLR_k = min S(no jump) - min S(jump) >= 0, so that wGLR / sigma^2 is the likelihood-ratio
statistic 2 log LR. Departures from the paper, on purpose (docs/fss.md):

* the dry term multiplies s_k = sign(w_k) as in eq. (4a) (eq. 11a omits it, which is the
  same thing for a wheel that never crosses zero);
* eq. (11b) prints the prior with a + sign: it is a penalty, so we subtract it;
* the prior is a pseudo-observation of f^v without noise: under no jump and a correct
  f~v, wGLR / sigma^2 is then stochastically smaller than chi2(1), so the threshold
  sigma^2 * chi2.isf(p, 1) keeps the false-positive probability per sample <= p;
* a ridge of 1e-9 w is added to W_b so that constant speed (f^d and f^v not separable)
  gives a defined statistic instead of a singular system;
* a run maximum closer than w to a larger one is dropped: near a zero crossing or a
  large jump the statistic has side lobes above the threshold that are the same jump;
* samples with a non-finite value are left out of every sum; a window with fewer than
  w / 2 usable samples on either side gets wGLR = 0 (no decision).

Everything is vectorised with prefix sums: O(n) for the whole window. The jump model is
the no-jump model plus one regressor (s_k on the right half), so wGLR is computed as the
squared projection of the no-jump residual on it (:func:`wglr`), which equals the
difference of the two penalised minima.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from rwa_monitor.core.params import check_int, check_real


@dataclass(frozen=True)
class ChangepointResult:
    """Stage-1 output: the statistic, the threshold and the changepoints (first new sample)."""

    glr: np.ndarray
    threshold: float
    sigma: float
    changepoints: np.ndarray


def estimate_sigma(y: np.ndarray, x: np.ndarray, viscous_prior: float) -> float:
    """Return a robust noise std from first differences of f - f~v w (MAD / sqrt 2).

    The dry level is piecewise constant, so differences remove it except at the rare
    jumps, which the median ignores; the speed changes too slowly to matter.
    """
    r = np.diff(y - viscous_prior * x)
    r = r[np.isfinite(r)]
    if r.size < 2:
        return float('nan')
    return float(1.4826 * np.median(np.abs(r - np.median(r))) / np.sqrt(2.0))


def wglr(y: np.ndarray, x: np.ndarray, *, window: int, w_bias: float,
         viscous_prior: float) -> np.ndarray:
    """Return wGLR_k for every k (0 where the window does not fit), eq. (10)-(11)."""
    window = check_int('window', window, 2)
    w_bias = check_real('w_bias', w_bias, 0.0)
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    n = y.size
    out = np.zeros(n)
    if n < 2 * window:
        return out
    ok = np.isfinite(y) & np.isfinite(x)
    if ok.all():
        s, xv, yv = np.sign(x), x, y
    else:
        xv, yv = np.where(ok, x, 0.0), np.where(ok, y, 0.0)
        s = np.sign(xv)
    prefix = np.zeros((5, n + 1))
    np.cumsum(np.stack((s * s, s * xv, xv * xv, s * yv, xv * yv)), axis=1, out=prefix[:, 1:])
    w2 = 2 * window
    lo, mid, hi = prefix[:, :n - w2 + 1], prefix[:, window:n - window + 1], prefix[:, w2:]
    a2, b2, y2 = hi[0] - mid[0], hi[1] - mid[1], hi[3] - mid[3]
    a, b, yy = hi[0] - lo[0], hi[1] - lo[1], hi[3] - lo[3]
    ridge = w_bias + 1e-9 * window
    c = hi[2] - lo[2] + ridge
    r = hi[4] - lo[4] + ridge * viscous_prior
    usable = (a - a2 >= window / 2) & (a2 >= window / 2)
    # The jump adds one regressor z = s_k on the right half to the no-jump model
    # [s_k, w_k] (+ prior): wGLR = (z' e0)^2 / (z' M0 z), e0 the no-jump residual and M0
    # its residual maker; with the 2 x 2 Gram matrix G0 = [[a, b], [b, c]].
    det = a * c - b * b
    det = np.where(det > 0, det, np.inf)
    dry0 = (c * yy - b * r) / det
    visc0 = (a * r - b * yy) / det
    num = y2 - dry0 * a2 - visc0 * b2
    den = a2 - (c * a2 * a2 - 2.0 * b * a2 * b2 + a * b2 * b2) / det
    den = np.where(den > 0, den, np.inf)
    k = slice(window, n - window + 1)
    out[k] = np.where(usable, num * num / den, 0.0)
    return out


def run_maxima(glr: np.ndarray, threshold: float, separation: int = 0) -> np.ndarray:
    """Return the arg max of each run of contiguous samples above ``threshold``.

    With ``separation`` > 0, a maximum closer than ``separation`` samples to a larger
    one is dropped (a side lobe of the same jump, docs/fss.md).
    """
    idx = np.flatnonzero(glr > threshold)
    if idx.size == 0:
        return np.empty(0, dtype=int)
    run = np.cumsum(np.concatenate(([True], np.diff(idx) > 1))) - 1
    order = np.lexsort((glr[idx], run))            # by run, then by value
    last = np.concatenate((run[order][1:] != run[order][:-1], [True]))
    peaks = idx[order[last]]                       # the largest of each run, in order
    if separation <= 0 or peaks.size < 2:
        return peaks
    suppressed = np.zeros(peaks.size, dtype=bool)
    for j in np.argsort(-glr[peaks], kind='stable'):
        if suppressed[j]:
            continue
        lo = np.searchsorted(peaks, peaks[j] - separation, side='right')
        hi = np.searchsorted(peaks, peaks[j] + separation, side='left')
        suppressed[lo:hi] = True
        suppressed[j] = False
    return peaks[~suppressed]


def detect_changepoints(y: np.ndarray, x: np.ndarray, *, window: int = 20,
                        w_bias: float = 1e-4, viscous_prior: float = 1.0,
                        p_false: float = 1e-9, sigma: float | None = None,
                        suppress: bool = True) -> ChangepointResult:
    """Run stage 1 (section IV-A): wGLR, chi-square threshold, one changepoint per run.

    ``p_false`` is the false-positive probability per sample (Wilks: wGLR / sigma^2 ~
    chi2(1)); ``sigma`` is estimated from the data when not given. ``suppress`` drops a
    run maximum within ``window`` samples of a larger one (departure, docs/fss.md).
    """
    p_false = check_real('p_false', p_false, 0.0, 1.0, low_open=True, high_open=True)
    if sigma is None:
        sigma = estimate_sigma(y, x, viscous_prior)
    glr = wglr(y, x, window=window, w_bias=w_bias, viscous_prior=viscous_prior)
    if not np.isfinite(sigma) or sigma <= 0.0:
        return ChangepointResult(glr, float('inf'), float(sigma), np.empty(0, dtype=int))
    threshold = float(sigma ** 2 * stats.chi2.isf(p_false, 1))
    return ChangepointResult(glr, threshold, float(sigma),
                             run_maxima(glr, threshold, window if suppress else 0))
