"""Gyro-minus-star-tracker residual and its commissioning calibration (docs/vsadc.md).

The residual of one step is ``e_k = (g_{k-1} + g_k) / 2 - w_st,k``: the trapezoid mean of
the two gyro samples that bound the step minus the star-tracker rate over the same step
(vsadc paper eqs. (4)-(6), :func:`rwa_monitor.core.attitude.star_tracker_rates`). Both
measure the true body rate, which cancels; what is left is the gyro error (bias, drift,
noise) and the star-tracker noise. It is the paper's two residuals subtracted:
``res_sst - res_gyr = w_gyro - w_sst``, the direction of the paper's 2-D feature space
that carries no guidance reference and no true-rate disturbance.

:func:`calibrate_gyro` is the commissioning step: fault-free arrays in, a plain dict per
axis out, the ``gyro:`` block of calibration.yaml (DESIGN.md, Calibration). Its keys are
stable; :class:`rwa_monitor.core.gyro_diagnosis.GyroDiagnosis` reads them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rwa_monitor.core.attitude import DEFAULT_NORM_TOLERANCE, star_tracker_rates
from rwa_monitor.core.params import check_int, check_real

AXES = ('x', 'y', 'z')
#: Samples per block mean (10 s at 4 Hz): the statistic the diagnosis tests.
DEFAULT_BLOCK = 40
#: Threshold factors on the calibrated block standard deviation (docs/vsadc.md).
DEFAULT_LEVEL_K = 6.0
DEFAULT_SLOPE_K = 5.0
#: Level change the nominal tracking may lag behind a slow thermal wander (rad/s).
DEFAULT_WANDER_RAD_S = 5.0e-6
#: Blocks in the slope fit of the drift/bias decision.
DEFAULT_FIT_BLOCKS = 12
#: Blocks of the centred running mean removed before the block spread is measured.
DETREND_BLOCKS = 31
CALIBRATION_VERSION = 1


def step_residuals(time: np.ndarray, gyro: np.ndarray, quaternions: np.ndarray,
                   max_gap: float = 1.0,
                   tolerance: float = DEFAULT_NORM_TOLERANCE) -> np.ndarray:
    """Return the per-row residual ``(g_{k-1} + g_k)/2 - w_st,k`` (n, 3), rad/s; NaN if none.

    A row has a residual when it has a star-tracker rate (valid quaternions, stamps at
    most ``max_gap`` apart) and both its gyro row and the previous one are finite.
    """
    time = np.asarray(time, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) != len(time):
        raise ValueError(f'gyro must be (n, 3) with n = len(time); got {gyro.shape}')
    rate = star_tracker_rates(time, quaternions, max_gap, tolerance)
    out = np.full((len(time), 3), np.nan)
    if len(time) < 2:
        return out
    mean_gyro = 0.5 * (gyro[1:] + gyro[:-1])
    out[1:] = mean_gyro - rate[1:]
    out[~np.isfinite(out)] = np.nan
    return out


def block_means(residual: np.ndarray, block: int) -> np.ndarray:
    """Return the means of consecutive blocks of ``block`` valid residuals (m, 3).

    NaN rows are skipped, as the streaming diagnosis skips them (one axis at a time).
    """
    block = check_int('block', block, 1)
    residual = np.asarray(residual, dtype=float).reshape(len(residual), -1)
    cols = []
    for col in residual.T:
        ok = col[np.isfinite(col)]
        m = len(ok) // block
        cols.append(ok[:m * block].reshape(m, block).mean(axis=1))
    m = min(len(c) for c in cols)
    return np.column_stack([c[:m] for c in cols]) if m else np.empty((0, residual.shape[1]))


def _detrended(x: np.ndarray, span: int) -> np.ndarray:
    """Return ``x`` minus its centred running mean over ``span`` values (ends shortened)."""
    half = span // 2
    csum = np.concatenate([[0.0], np.cumsum(x)])
    idx = np.arange(len(x))
    lo = np.maximum(idx - half, 0)
    hi = np.minimum(idx + half + 1, len(x))
    return x - (csum[hi] - csum[lo]) / (hi - lo)


def slope_std(block_std: float, blocks: int, block_s: float) -> float:
    """Return the standard deviation of a least-squares slope over ``blocks`` white means.

    ``sigma sqrt(12 / (K (K^2 - 1))) / T_block`` (rad/s per s).
    """
    k = float(blocks)
    return block_std * np.sqrt(12.0 / (k * (k * k - 1.0))) / block_s


def calibrate_gyro(time: np.ndarray, gyro: np.ndarray, quaternions: np.ndarray, *,
                   block: int = DEFAULT_BLOCK, level_k: float = DEFAULT_LEVEL_K,
                   slope_k: float = DEFAULT_SLOPE_K,
                   wander_rad_s: float = DEFAULT_WANDER_RAD_S,
                   fit_blocks: int = DEFAULT_FIT_BLOCKS,
                   max_gap: float = 1.0) -> dict[str, dict[str, Any]]:
    """Return the per-axis gyro calibration from fault-free telemetry arrays.

    ``time`` (n,) s, ``gyro`` (n, 3) rad/s, ``quaternions`` (n, 4) ``[x, y, z, w]``.
    Per axis ``x``, ``y``, ``z`` a dict of floats (SI units in the keys):

    - ``bias_rad_s``: mean residual (the gyro bias seen by the star tracker);
    - ``noise_std_rad_s``: standard deviation of the per-step residual;
    - ``block_samples``, ``block_s``: the block of the statistic (samples, seconds);
    - ``block_std_rad_s``: standard deviation of block means around a running mean of
      ``DETREND_BLOCKS`` blocks (slow bias wander removed, as the diagnosis tracks it);
    - ``block_lag1_correlation``: correlation of successive block means (negative: the
      star-tracker noise enters differenced, so it telescopes across blocks);
    - ``correlation_time_s``: integral time scale of the block means (>= 0);
    - ``level_threshold_rad_s`` = ``level_k`` x block std + ``wander_rad_s``;
    - ``quiet_level_rad_s`` = 3 x block std (the onset of an excursion);
    - ``slope_threshold_rad_s2`` = ``slope_k`` x the std of a slope fitted on
      ``fit_blocks`` block means (:func:`slope_std`);
    - ``samples``: residuals used.

    ValueError when there are fewer than ``2 * DETREND_BLOCKS`` blocks per axis.
    """
    block = check_int('block', block, 2)
    check_real('level_k', level_k, 0.0, low_open=True)
    check_real('slope_k', slope_k, 0.0, low_open=True)
    check_real('wander_rad_s', wander_rad_s, 0.0)
    fit_blocks = check_int('fit_blocks', fit_blocks, 3)
    time = np.asarray(time, dtype=float)
    res = step_residuals(time, gyro, quaternions, max_gap)
    steps = np.diff(time[np.isfinite(time)])
    steps = steps[steps > 0]
    if len(steps) == 0:
        raise ValueError('calibration needs increasing time stamps')
    dt = float(np.median(steps))
    means = block_means(res, block)
    if len(means) < 2 * DETREND_BLOCKS:
        raise ValueError(f'calibration needs at least {2 * DETREND_BLOCKS} blocks of '
                         f'{block} star-tracker/gyro steps per axis; got {len(means)}')
    out: dict[str, dict[str, Any]] = {}
    for i, axis in enumerate(AXES):
        col = res[:, i]
        col = col[np.isfinite(col)]
        dev = _detrended(means[:, i], DETREND_BLOCKS)
        std = float(np.std(dev))
        rho = [float(np.corrcoef(dev[:-k], dev[k:])[0, 1]) for k in range(1, 6)]
        total = 1.0
        for r in rho:
            if r <= 0.0 and total > 1.0:
                break
            total += 2.0 * r
        block_s = block * dt
        out[axis] = {
            'bias_rad_s': float(np.mean(col)),
            'noise_std_rad_s': float(np.std(col)),
            'block_samples': block,
            'block_s': block_s,
            'block_std_rad_s': std,
            'block_lag1_correlation': rho[0],
            'correlation_time_s': max(total, 0.0) * block_s,
            'level_threshold_rad_s': level_k * std + wander_rad_s,
            'quiet_level_rad_s': 3.0 * std,
            'slope_threshold_rad_s2': float(slope_k * slope_std(std, fit_blocks, block_s)),
            'samples': int(len(col)),
        }
    return out
