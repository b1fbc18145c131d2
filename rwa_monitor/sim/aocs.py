"""Seeded AOCS telemetry: gyro, star tracker and guidance reference rate, with gyro faults.

A rigid spacecraft (vsadc-gyro-drift paper, Table 2: inertia diag(14.5, 14.5, 14.5) kg m^2,
PD gains (Kp, Kd) = (0.2 N m/rad, 0.7 N m s/rad), attitude-estimator gain 0.66, 4 Hz)
tracks a guidance reference (inertial hold and slow slews) with three orthogonal reaction
wheels. The gyro reads the true body rate plus a constant bias, a rate random walk, an
orbital thermal bias, white noise (angle random walk) and the injected fault; the star
tracker reads the true attitude with arc-second noise and occasional dropouts (NaN rows).
The estimator propagates with the gyro and is pulled towards the star tracker with the
Table 2 gain; the controller (feed-forward of the reference plus PD on the estimate and the
gyro rate) closes the loop, so a gyro fault also moves the true attitude, as on board.

Faults (docs/simulators.md, ``## AOCS``): a drift ramps the gyro error of one axis with a
constant slope from ``time_s`` until it reaches ``level`` and then holds it (the bias-like
state after a drift); a bias is a step of ``level``. Truth per sample: 0 healthy, 1 drift
(the error is changing), 2 bias (the error is constant and non-zero).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math

import numpy as np

from rwa_monitor.core.params import check_choice, check_int, check_real
from rwa_monitor.telemetry import Telemetry

AXES = ('x', 'y', 'z')
ARCSEC = math.pi / (180.0 * 3600.0)
#: Final fault level (rad/s) of the named scenarios: about 41 deg/h.
DEFAULT_LEVEL = 2.0e-4
#: Drift slopes (rad/s per s) of the named speeds; time to reach DEFAULT_LEVEL: 40/200/1000 s.
DRIFT_SLOPES = {'fast': 5.0e-6, 'medium': 1.0e-6, 'slow': 2.0e-7}
FAULT_NAMES = (*DRIFT_SLOPES, 'bias')
HEALTHY, DRIFT, BIAS = 0, 1, 2


@dataclass(frozen=True)
class GyroFault:
    """A gyro fault on ``axis`` (0, 1, 2) starting at ``time_s`` (s from the first sample).

    ``slope`` (rad/s per s) > 0 makes a drift that ramps to ``level`` (rad/s, signed) and
    holds it; ``slope`` = 0 makes a bias step of ``level``.
    """

    axis: int
    time_s: float
    level: float = DEFAULT_LEVEL
    slope: float = 0.0

    @property
    def drift_duration_s(self) -> float:
        """Return how long the drift ramps (0 for a bias step)."""
        return abs(self.level) / self.slope if self.slope > 0 else 0.0


def named_fault(name: str, axis: int | str = 0, time_s: float = 600.0,
                level: float = DEFAULT_LEVEL) -> GyroFault:
    """Return the fault of a named scenario: ``fast``/``medium``/``slow`` drift or ``bias``."""
    check_choice('fault', name, FAULT_NAMES)
    if isinstance(axis, str):
        axis = AXES.index(check_choice('axis', axis, AXES))
    check_int('axis', axis, 0, 2)
    check_real('time_s', time_s, 0.0)
    check_real('level', level)
    return GyroFault(axis, time_s, level, DRIFT_SLOPES.get(name, 0.0))


@dataclass(frozen=True)
class Slew:
    """A guidance slew about body ``axis``: cosine ramps of ``ramp_s`` to ``rate`` (rad/s)."""

    axis: int
    start_s: float
    duration_s: float
    rate: float
    ramp_s: float = 60.0


@dataclass(frozen=True)
class AocsConfig:
    """Spacecraft, sensor and actuator parameters (SI units; defaults in docs/simulators.md)."""

    inertia: float = 14.5                 # kg m^2, diagonal (Table 2)
    kp: float = 0.2                       # N m/rad (Table 2)
    kd: float = 0.7                       # N m s/rad (Table 2)
    estimator_gain: float = 0.66          # star-tracker correction per sample (Table 2)
    rate_hz: float = 4.0                  # Table 2: 250 ms
    gyro_arw: float = 5.0e-6              # rad/sqrt(s): 1e-5 rad/s white noise at 4 Hz
    gyro_bias_std: float = 1.0e-5         # rad/s, constant bias per axis ~ N(0, std^2)
    gyro_rrw: float = 2.0e-8              # rad/s/sqrt(s), rate random walk
    gyro_thermal: float = 1.0e-6          # rad/s amplitude of the orbital thermal bias
    orbit_period_s: float = 5800.0
    st_noise_arcsec: float = 5.0          # 1-sigma per axis
    st_dropouts_per_hour: float = 2.0
    st_dropout_max_s: float = 5.0
    st_sign_flip_probability: float = 0.0  # chance a sample is output as -q
    wheel_torque_max: float = 0.05        # N m per wheel
    disturbance_torque: float = 2.0e-6    # N m, constant per axis ~ N(0, value^2)
    slews: tuple[Slew, ...] = field(default_factory=tuple)

    def validated(self) -> 'AocsConfig':
        """Return self after checking every value; ValueError names the bad one."""
        for name in ('inertia', 'kp', 'kd', 'rate_hz', 'orbit_period_s', 'wheel_torque_max'):
            check_real(name, getattr(self, name), 0.0, low_open=True)
        for name in ('gyro_arw', 'gyro_bias_std', 'gyro_rrw', 'gyro_thermal',
                     'st_noise_arcsec', 'st_dropouts_per_hour', 'st_dropout_max_s',
                     'disturbance_torque'):
            check_real(name, getattr(self, name), 0.0)
        check_real('estimator_gain', self.estimator_gain, 0.0, 1.0)
        check_real('st_sign_flip_probability', self.st_sign_flip_probability, 0.0, 1.0)
        return self


def default_slews(duration_s: float) -> tuple[Slew, ...]:
    """Return one slow slew (0.05 deg/s about z) in the middle third of a run."""
    start = duration_s / 3.0
    return (Slew(axis=2, start_s=start, duration_s=min(600.0, duration_s / 3.0),
                 rate=math.radians(0.05)),)


def _smooth_step(x: np.ndarray, ramp: float) -> tuple[np.ndarray, np.ndarray]:
    """Return a cosine step from 0 (x <= 0) to 1 (x >= ramp) and its derivative in x."""
    inside = (x > 0) & (x < ramp)
    value = np.where(x <= 0, 0.0, np.where(inside, 0.5 - 0.5 * np.cos(np.pi * x / ramp), 1.0))
    slope = np.where(inside, 0.5 * np.pi / ramp * np.sin(np.pi * x / ramp), 0.0)
    return value, slope


def reference_rate(time: np.ndarray, slews: tuple[Slew, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Return the guidance body rate (rad/s) and its derivative per sample, shape (n, 3)."""
    t = np.asarray(time, dtype=float) - time[0]
    rate = np.zeros((len(t), 3))
    accel = np.zeros((len(t), 3))
    for s in slews:
        ramp = max(min(s.ramp_s, s.duration_s / 2.0), 1e-9)
        up, d_up = _smooth_step(t - s.start_s, ramp)
        down, d_down = _smooth_step(s.start_s + s.duration_s - t, ramp)
        rate[:, s.axis] += s.rate * up * down
        accel[:, s.axis] += s.rate * (d_up * down - up * d_down)
    return rate, accel


def fault_profile(time: np.ndarray, fault: GyroFault | None) -> tuple[np.ndarray, np.ndarray]:
    """Return the fault's gyro error (rad/s) on its axis and the truth label per sample."""
    t = np.asarray(time, dtype=float) - time[0]
    n = len(t)
    if fault is None:
        return np.zeros(n), np.zeros(n, dtype=int)
    dt = t - fault.time_s
    started = dt >= 0
    if fault.slope > 0:
        ramp = np.sign(fault.level) * fault.slope * np.maximum(dt, 0.0)
        error = np.where(np.abs(ramp) < abs(fault.level), ramp, fault.level)
        labels = np.where(~started, HEALTHY,
                          np.where(dt < fault.drift_duration_s, DRIFT, BIAS))
    else:
        error = np.where(started, fault.level, 0.0)
        labels = np.where(started, BIAS, HEALTHY)
    return error * started, labels.astype(int)


def _dropout_mask(time: np.ndarray, cfg: AocsConfig, rng: np.random.Generator) -> np.ndarray:
    t = np.asarray(time, dtype=float) - time[0]
    mask = np.zeros(len(t), dtype=bool)
    duration = t[-1] if len(t) else 0.0
    count = rng.poisson(cfg.st_dropouts_per_hour * duration / 3600.0)
    for start, length in zip(rng.uniform(0.0, duration, count),
                             rng.uniform(1.0, max(cfg.st_dropout_max_s, 1.0), count)):
        mask |= (t >= start) & (t < start + length)
    return mask


def simulate_aocs(duration_s: float = 3600.0, *, fault: GyroFault | None = None,
                  config: AocsConfig | None = None, seed: int = 0,
                  time: np.ndarray | None = None) -> Telemetry:
    """Simulate the closed loop; return telemetry with gyro, q, ref and truth columns.

    ``time`` (s, strictly increasing) replaces the uniform ``config.rate_hz`` time base
    (used to add gyro channels to an existing record). Truth columns: ``gyro_x/y/z``
    (labels 0/1/2), ``gyro_error_x/y/z`` (injected fault, rad/s), ``rate_x/y/z`` (true
    body rate, rad/s), ``st_valid`` (1 where the star tracker delivered).
    """
    cfg = (config or AocsConfig()).validated()
    if time is None:
        check_real('duration_s', duration_s, 0.0, low_open=True)
        time = np.arange(int(round(duration_s * cfg.rate_hz)) + 1) / cfg.rate_hz
    time = np.asarray(time, dtype=float)
    if len(time) < 2 or not np.all(np.diff(time) > 0):
        raise ValueError('time must have at least 2 strictly increasing stamps')
    if fault is not None:
        check_int('fault.axis', fault.axis, 0, 2)
        check_real('fault.slope', fault.slope, 0.0)
    rng = np.random.default_rng(seed)
    n = len(time)
    dt = np.diff(time, append=time[-1] + (time[-1] - time[-2]))
    slews = cfg.slews if cfg.slews else default_slews(time[-1] - time[0])
    w_ref, dw_ref = reference_rate(time, slews)

    error = np.empty((n, 3))
    bias0 = rng.normal(0.0, cfg.gyro_bias_std, 3)
    phase = rng.uniform(0.0, 2.0 * np.pi, 3)
    rrw = np.cumsum(rng.normal(size=(n, 3)) * cfg.gyro_rrw * np.sqrt(dt)[:, None], axis=0)
    white = rng.normal(size=(n, 3)) * (cfg.gyro_arw / np.sqrt(dt))[:, None]
    t_rel = time - time[0]
    for i in range(3):
        error[:, i] = (bias0[i] + rrw[:, i] + white[:, i] + cfg.gyro_thermal
                       * np.sin(2.0 * np.pi * t_rel / cfg.orbit_period_s + phase[i]))
    labels = np.zeros((n, 3), dtype=int)
    fault_error = np.zeros((n, 3))
    if fault is not None:
        fault_error[:, fault.axis], labels[:, fault.axis] = fault_profile(time, fault)
    error += fault_error
    st_noise = from_rotvec_rows(rng.normal(size=(n, 3)) * cfg.st_noise_arcsec * ARCSEC)
    dropout = _dropout_mask(time, cfg, rng)
    disturbance = rng.normal(0.0, cfg.disturbance_torque, 3)
    flips = rng.random(n) < cfg.st_sign_flip_probability

    gyro, q_meas, rate = _closed_loop(time, dt, cfg, w_ref, dw_ref, error, st_noise,
                                      dropout, disturbance)
    q_meas[flips] *= -1.0
    q_meas[dropout] = np.nan
    truth = {}
    for i, a in enumerate(AXES):
        truth[f'gyro_{a}'] = labels[:, i].astype(float)
    for i, a in enumerate(AXES):
        truth[f'gyro_error_{a}'] = fault_error[:, i]
    for i, a in enumerate(AXES):
        truth[f'rate_{a}'] = rate[:, i]
    truth['st_valid'] = (~dropout).astype(float)
    return Telemetry(time=time, gyro=gyro, attitude=q_meas, reference_rate=w_ref, truth=truth)


def from_rotvec_rows(rotvec: np.ndarray) -> np.ndarray:
    """Return unit quaternions [x, y, z, w] of rotation vectors, row by row."""
    angle = np.linalg.norm(rotvec, axis=1)
    scale = np.where(angle > 1e-12, np.sin(0.5 * angle) / np.maximum(angle, 1e-300), 0.5)
    return np.column_stack([rotvec * scale[:, None], np.cos(0.5 * angle)])


def _qmul(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return (pw * qx + px * qw + py * qz - pz * qy, pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw, pw * qw - px * qx - py * qy - pz * qz)


def _qexp(wx, wy, wz, dt):
    """Return the quaternion of body rotation ``w dt`` (plain floats)."""
    angle = math.sqrt(wx * wx + wy * wy + wz * wz) * dt
    s = 0.5 * dt if angle < 1e-12 else math.sin(0.5 * angle) * dt / angle
    return (wx * s, wy * s, wz * s, math.cos(0.5 * angle))


def _normalised(q):
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm)


def _small_angle_error(q_from, q_to):
    """Return 2 vec(conj(q_from) (x) q_to), taken in the hemisphere w >= 0."""
    e = _qmul((-q_from[0], -q_from[1], -q_from[2], q_from[3]), q_to)
    s = 2.0 if e[3] >= 0 else -2.0
    return e[0] * s, e[1] * s, e[2] * s


def _closed_loop(time, dt, cfg, w_ref, dw_ref, error, st_noise, dropout, disturbance):
    """Integrate the loop sample by sample in plain floats (a few microseconds a step)."""
    n = len(time)
    big_j, kp, kd, gain, tmax = (cfg.inertia, cfg.kp, cfg.kd, cfg.estimator_gain,
                                 cfg.wheel_torque_max)
    gyro_out = np.empty((n, 3))
    q_out = np.empty((n, 4))
    rate_out = np.empty((n, 3))
    w = [float(v) for v in w_ref[0]]
    h = [0.0, 0.0, 0.0]
    q_true = q_ref = q_est = (0.0, 0.0, 0.0, 1.0)
    ref_l, dref_l, err_l = w_ref.tolist(), dw_ref.tolist(), error.tolist()
    noise_l, drop_l, dt_l = st_noise.tolist(), dropout.tolist(), dt.tolist()
    dist = [float(v) for v in disturbance]
    for k in range(n):
        step = dt_l[k]
        ek, rk, ak = err_l[k], ref_l[k], dref_l[k]
        g = (w[0] + ek[0], w[1] + ek[1], w[2] + ek[2])
        q_st = _qmul(q_true, noise_l[k])
        gyro_out[k] = g
        q_out[k] = q_st if q_st[3] >= 0 else (-q_st[0], -q_st[1], -q_st[2], -q_st[3])
        rate_out[k] = w
        if not drop_l[k]:
            c = _small_angle_error(q_est, q_st)
            half = 0.5 * gain
            q_est = _normalised(_qmul(q_est, (half * c[0], half * c[1], half * c[2], 1.0)))
        th = _small_angle_error(q_ref, q_est)
        hx, hy, hz = big_j * g[0] + h[0], big_j * g[1] + h[1], big_j * g[2] + h[2]
        gyroscopic = (g[1] * hz - g[2] * hy, g[2] * hx - g[0] * hz, g[0] * hy - g[1] * hx)
        u = [big_j * ak[i] + gyroscopic[i] - kp * th[i] - kd * (g[i] - rk[i])
             for i in range(3)]
        u = [tmax if v > tmax else (-tmax if v < -tmax else v) for v in u]
        hx, hy, hz = big_j * w[0] + h[0], big_j * w[1] + h[1], big_j * w[2] + h[2]
        cross = (w[1] * hz - w[2] * hy, w[2] * hx - w[0] * hz, w[0] * hy - w[1] * hx)
        w_new = [w[i] + step * (u[i] - cross[i] + dist[i]) / big_j for i in range(3)]
        for i in range(3):
            h[i] -= step * u[i]
        mid = (0.5 * (w[0] + w_new[0]), 0.5 * (w[1] + w_new[1]), 0.5 * (w[2] + w_new[2]))
        q_true = _normalised(_qmul(q_true, _qexp(*mid, step)))
        q_ref = _normalised(_qmul(q_ref, _qexp(*rk, step)))
        q_est = _normalised(_qmul(q_est, _qexp(*g, step)))
        w = w_new
    return gyro_out, q_out, rate_out


def add_gyro_channels(tele: Telemetry, *, fault: GyroFault | None = None, seed: int = 0,
                      config: AocsConfig | None = None) -> Telemetry:
    """Return a copy of ``tele`` with simulated gyro, star-tracker, ref and truth columns.

    The AOCS loop runs on ``tele.time`` (any strictly increasing time base); existing
    truth columns are kept. Used to put a gyro fault into the demo's bundled telemetry.
    """
    aocs = simulate_aocs(fault=fault, config=config, seed=seed, time=tele.time)
    return replace(tele, gyro=aocs.gyro, attitude=aocs.attitude,
                   reference_rate=aocs.reference_rate, truth={**tele.truth, **aocs.truth})
