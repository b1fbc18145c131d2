"""Step or ramp: the kind decision of the residual diagnosis (docs/vsadc.md).

Alg. 1 lines 27-34 of the vsadc-gyro-drift paper decide drift or bias from the spread of
the distances against self-adapted limits; the residual diagnosis
(core/gyro_residual.py) compares instead how well a step (bias) and a ramp (drift), each
with its onset fitted, explain the recent half-block means, whitened with the calibrated
noise model (:func:`whitener`). Pure functions of arrays: the axis holds the state.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.vsadc_axis import BIAS, DRIFT


def whitener(k: int, lag1_correlation: float) -> np.ndarray:
    """Return ``W`` (k, k) with ``W C W^T = I``, C the covariance of k half-block means.

    Noise model (docs/vsadc.md): a mean over a span is white gyro noise plus the
    difference of the star-tracker angle noise at its two ends divided by the span. In
    block variances, with ``rho`` the calibrated lag-1 correlation of block means
    (clipped to [MIN_LAG1, 0] by the axis), ``s_a = -rho`` and ``s_g = 1 + 2 rho``;
    halving the span doubles the gyro part and quadruples the star-tracker part:
    ``C = 2 s_g I + 4 s_a (2 I - offdiag)``. A step or a ramp lives at low frequencies,
    where the telescoping star-tracker noise is small: whitened, they stand out earlier
    than under a white-noise model.
    """
    s_a = -lag1_correlation
    s_g = 1.0 - 2.0 * s_a
    off = np.eye(k, k=1) + np.eye(k, k=-1)
    cov = 2.0 * s_g * np.eye(k) + 4.0 * s_a * (2.0 * np.eye(k) - off)
    return np.linalg.inv(np.linalg.cholesky(cov))


def step_or_ramp(d: np.ndarray, times: np.ndarray, whiten: np.ndarray, block_std: float,
                 decide_chi2: float, force: bool) -> tuple[int | None, int]:
    """Return the better fit of the distances (DRIFT, BIAS or None) and its onset sample.

    ``d`` are the half-block distances (2 K) of K blocks whose sample times are ``times``
    (K, block); ``whiten`` is :func:`whitener` of 2 K. Per onset candidate (every quarter
    block) the regressor of a step is the share of each half block's samples after the
    onset, that of a ramp the half-block mean of ``max(0, t - onset)``. Data and
    regressors are whitened; the explained sum of squares ``(x.d)^2 / x.x`` of the best
    onset of each model is compared in block variances (``block_std`` rad/s): a margin
    above ``decide_chi2`` decides, and ``force`` takes the better one. The onset is the
    index of its sample in ``times.ravel()``.
    """
    block = times.shape[1]
    half = block // 2
    step = max(block // 4, 1)
    candidates = times.ravel()[::step]

    def regressors(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rel = t[None, :, :] - candidates[:, None, None]
        return (rel >= 0).mean(axis=2), np.maximum(rel, 0.0).mean(axis=2)

    s1, r1 = regressors(times[:, :half])
    s2, r2 = regressors(times[:, half:])
    x_step = np.stack([s1, s2], axis=2).reshape(len(candidates), -1)
    x_ramp = np.stack([r1, r2], axis=2).reshape(len(candidates), -1)
    d = whiten @ d

    def best(x: np.ndarray) -> tuple[float, int]:
        x = x @ whiten.T
        xx = np.einsum('ck,ck->c', x, x)
        xd = x @ d
        with np.errstate(invalid='ignore', divide='ignore'):
            explained = np.where(xx > 0, xd * xd / np.where(xx > 0, xx, 1.0), 0.0)
        i = int(np.argmax(explained))
        return float(explained[i]), i

    step_fit, i_step = best(x_step)
    ramp_fit, i_ramp = best(x_ramp)
    margin = (ramp_fit - step_fit) / block_std ** 2
    if margin > decide_chi2 or (force and margin > 0):
        return DRIFT, i_ramp * step
    if margin < -decide_chi2 or force:
        return BIAS, i_step * step
    return None, -1
