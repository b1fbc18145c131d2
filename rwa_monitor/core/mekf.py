"""Baseline gyro-bias estimator: a multiplicative EKF with star-tracker updates, then CUSUM.

The estimator AOCS engineers run on board (the MEKF of the spacecraft attitude
determination literature): state the attitude quaternion ``q`` and the gyro bias ``b``;
error state ``(dtheta, db)``. Gyro model ``g = w + b + v``, ``v`` white (angle random walk
``sigma_v``, rad/s^0.5), ``b`` a random walk (``sigma_u``, rad/s^1.5). Propagation with
the trapezoid rate ``w = (g_{k-1} + g_k)/2 - b``: ``q <- q (x) exp(w dt)``. Update with a
star-tracker quaternion ``q_m``: residual ``r = 2 vec(conj(q) (x) q_m)`` (hemisphere
``w >= 0``), ``dtheta = K_theta r``, ``db = K_b r``, ``q <- q (x) exp(dtheta)``.

Departure, on purpose: the gains are the steady-state ones (a fixed-gain MEKF, common on
board when the star tracker runs at a fixed rate): per axis the discrete algebraic Riccati
equation of ``Phi = [[1, -dt], [0, 1]]``, ``H = [1, 0]``,
``Q = diag(sigma_v^2 dt, sigma_u^2 dt)``, ``R = sigma_st^2`` (scipy). The body-rate
coupling ``-[w x] dt`` of the full covariance is left out of the gains (0.0075 rad per
step at 0.03 rad/s); the full covariance form ran at 150 s per 3-hour record in Python,
too slow for a bench of many records, and converges to these gains within minutes.

Tuning (docs/vsadc.md): ``sigma_v`` and ``sigma_st`` are the sensors' (1e-5 rad/s per
sample at 4 Hz, 5 arcsec); ``sigma_u`` is 10 times the nominal bias walk so that the
estimate follows a fault within about a minute. The CUSUM (:func:`cusum_alarms`) watches
``b`` every ``block`` samples against a slowly tracked reference.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg import solve_discrete_are

from rwa_monitor.core.attitude import valid
from rwa_monitor.core.params import check_int, check_real

MEKF_DEFAULTS: dict[str, float] = {
    'sigma_v': 5.0e-6,          # rad/s^0.5: 1e-5 rad/s per sample at 4 Hz
    'sigma_u': 2.0e-7,          # rad/s^1.5: 10 x the bus's nominal bias walk (2e-8)
    'sigma_st': 2.42e-5,        # rad: 5 arcsec per axis
}


def steady_gains(dt: float, sigma_v: float, sigma_u: float, sigma_st: float
                 ) -> tuple[float, float]:
    """Return the steady-state Kalman gains (attitude, bias) of one axis (1, 1/s)."""
    phi = np.array([[1.0, -dt], [0.0, 1.0]])
    h = np.array([[1.0], [0.0]])
    q = np.diag([sigma_v ** 2 * dt, sigma_u ** 2 * dt])
    p = solve_discrete_are(phi.T, h, q, np.array([[sigma_st ** 2]]))  # predicted cov
    gain = p @ h / (p[0, 0] + sigma_st ** 2)
    return float(gain[0, 0]), float(gain[1, 0])


def _qmul(p: tuple, q: tuple) -> tuple:
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return (pw * qx + px * qw + py * qz - pz * qy, pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw, pw * qw - px * qx - py * qy - pz * qz)


def _rotvec_q(x: float, y: float, z: float) -> tuple:
    angle = math.sqrt(x * x + y * y + z * z)
    s = 0.5 - angle * angle / 48.0 if angle < 1e-6 else math.sin(0.5 * angle) / angle
    return (x * s, y * s, z * s, math.cos(0.5 * angle))


def mekf_bias(time: np.ndarray, gyro: np.ndarray, quaternions: np.ndarray, *,
              max_gap: float = 1.0, **tuning: float) -> np.ndarray:
    """Return the MEKF's gyro-bias estimate after each row (n, 3), rad/s.

    Rows without a valid quaternion are propagated only; a non-finite gyro row, a stamp
    not after the last or a gap above ``max_gap`` restarts the attitude from the next
    quaternion (the bias is kept). NaN before the first update.
    """
    bad = sorted(set(tuning) - set(MEKF_DEFAULTS))
    if bad:
        raise ValueError(f'unknown MEKF tuning: {", ".join(bad)}')
    p = {k: check_real(k, v, 0.0, low_open=True)
         for k, v in {**MEKF_DEFAULTS, **tuning}.items()}
    time = np.asarray(time, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    quaternions = np.asarray(quaternions, dtype=float)
    steps = np.diff(time[np.isfinite(time)])
    steps = steps[steps > 0]
    dt_nominal = float(np.median(steps)) if len(steps) else 1.0
    k_att, k_bias = steady_gains(dt_nominal, p['sigma_v'], p['sigma_u'], p['sigma_st'])
    ok_q = valid(quaternions).tolist()
    qs = quaternions.tolist()
    out = np.full((len(time), 3), np.nan)
    bx = by = bz = 0.0
    q = None
    g_prev = None
    last_t = -math.inf
    started = False
    for k, (t, g) in enumerate(zip(time.tolist(), gyro.tolist())):
        if not (math.isfinite(t) and t > last_t) or not all(math.isfinite(v) for v in g):
            q = g_prev = None
            if started:
                out[k] = (bx, by, bz)
            continue
        dt = t - last_t
        last_t = t
        if q is not None and dt > max_gap:
            q = None
        if q is not None:
            wx = 0.5 * (g_prev[0] + g[0]) - bx
            wy = 0.5 * (g_prev[1] + g[1]) - by
            wz = 0.5 * (g_prev[2] + g[2]) - bz
            q = _qmul(q, _rotvec_q(wx * dt, wy * dt, wz * dt))
        g_prev = g
        if ok_q[k]:
            m = qs[k]
            n = math.sqrt(sum(v * v for v in m))
            m = (m[0] / n, m[1] / n, m[2] / n, m[3] / n)
            if q is None:
                q = m
            else:
                dq = _qmul((-q[0], -q[1], -q[2], q[3]), m)
                sign = 2.0 if dq[3] >= 0 else -2.0
                rx, ry, rz = sign * dq[0], sign * dq[1], sign * dq[2]
                q = _qmul(q, _rotvec_q(k_att * rx, k_att * ry, k_att * rz))
                n = math.sqrt(sum(v * v for v in q))
                q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
                bx += k_bias * rx                     # k_bias < 0: dtheta = -dt db
                by += k_bias * ry
                bz += k_bias * rz
                started = True
        if started:
            out[k] = (bx, by, bz)
    return out


def cusum_alarms(bias: np.ndarray, time: np.ndarray, *, block: int = 40,
                 spread_rad_s: float, drift_k: float = 0.5, threshold: float = 8.0,
                 nominal_blocks: int = 6, tracking_blocks: int = 30, guard_blocks: int = 3,
                 freeze_rad_s: float = 1.4e-5, warmup_blocks: int = 30
                 ) -> list[dict[str, Any]]:
    """Two-sided CUSUM on the block-sampled bias estimate of each axis; return alarms.

    Every ``block`` rows after ``warmup_blocks`` (the estimate converging from zero),
    ``z = (b - b_ref) / spread_rad_s``; ``S+ = max(0, S+ + z - k)``,
    ``S- = max(0, S- - z - k)``; an alarm when either exceeds ``threshold``, after which
    the sums and the reference restart. The reference is tracked as the residual
    diagnosis tracks its nominal (:mod:`rwa_monitor.core.gyro_diagnosis`), so that the
    two differ by their statistic only: the mean of the first ``nominal_blocks`` samples,
    then a running mean over ``tracking_blocks`` of the sample ``guard_blocks`` back while
    the last ``guard_blocks + 1`` samples lie within ``freeze_rad_s`` of it. Alarms:
    ``axis`` (0-2), ``time`` (s), ``onset`` (s, the last time the alarming sum was zero),
    ``statistic``.
    """
    block = check_int('block', block, 1)
    check_real('spread_rad_s', spread_rad_s, 0.0, low_open=True)
    alarms: list[dict[str, Any]] = []
    bias = np.asarray(bias, dtype=float)
    time = np.asarray(time, dtype=float)
    idx = np.arange(block - 1, len(time), block)
    idx = idx[np.isfinite(bias[idx]).all(axis=1)][warmup_blocks:]
    for axis in range(bias.shape[1]):
        b = bias[idx, axis]
        ts = time[idx]
        ref, n_ref = 0.0, 0
        hi = lo = 0.0
        hi_zero = lo_zero = ts[0] if len(ts) else 0.0
        for j in range(len(b)):
            if n_ref < nominal_blocks:
                n_ref += 1
                ref += (b[j] - ref) / n_ref
                hi_zero = lo_zero = ts[j]
                continue
            z = (b[j] - ref) / spread_rad_s
            hi = max(0.0, hi + z - drift_k)
            lo = max(0.0, lo - z - drift_k)
            if hi == 0.0:
                hi_zero = ts[j]
            if lo == 0.0:
                lo_zero = ts[j]
            if hi > threshold or lo > threshold:
                alarms.append({'axis': axis, 'time': float(ts[j]),
                               'onset': float(hi_zero if hi > threshold else lo_zero),
                               'statistic': float(max(hi, lo))})
                hi = lo = 0.0
                ref, n_ref = 0.0, 0
                continue
            recent = b[max(j - guard_blocks, 0):j + 1]
            if tracking_blocks and np.all(np.abs(recent - ref) < freeze_rad_s):
                ref += (recent[0] - ref) / tracking_blocks
    return alarms
