"""Quaternion helpers and the star-tracker body rate (vsadc-gyro-drift paper, eqs. (4)-(6)).

Quaternions are ``[x, y, z, w]`` (scalar last, as the telemetry schema), Hamilton
product, body-to-inertial: the attitude propagates as ``q_k = q_{k-1} (x) dq`` with ``dq``
the body-frame rotation over the step. ``q`` and ``-q`` are the same attitude; every
function here is invariant under that flip.
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core.gyro_state import (
    check_counts, check_finite, check_type, require, StarTrackerState)
from rwa_monitor.core.params import check_real

#: A quaternion whose norm is outside ``[1 - tol, 1 + tol]`` is rejected, not normalised.
DEFAULT_NORM_TOLERANCE = 0.1


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Return the Hamilton product ``p (x) q`` of quaternions ``[..., 4]`` (scalar last)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    px, py, pz, pw = np.moveaxis(p, -1, 0)
    qx, qy, qz, qw = np.moveaxis(q, -1, 0)
    return np.stack([pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw,
                     pw * qw - px * qx - py * qy - pz * qz], axis=-1)


def conjugate(q: np.ndarray) -> np.ndarray:
    """Return the quaternion conjugate, which inverts a unit quaternion."""
    q = np.array(q, dtype=float)
    q[..., :3] *= -1.0
    return q


def from_rotation_vector(rotvec: np.ndarray) -> np.ndarray:
    """Return the unit quaternion of rotation vector(s) ``[..., 3]`` (axis times angle, rad)."""
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1)
    half = 0.5 * angle
    # sin(a/2)/a, with its series near 0 so that tiny rotations stay exact.
    small = angle < 1e-6
    scale = np.where(small, 0.5 - angle ** 2 / 48.0,
                     np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([rotvec * scale[..., None], np.cos(half)[..., None]], axis=-1)


def to_rotation_vector(q: np.ndarray) -> np.ndarray:
    """Return the rotation vector (rad) of unit quaternion(s), the shortest of q and -q.

    At exactly 180 degrees (``w = 0``) both signs of the axis are the same rotation; the
    axis is returned as stored.
    """
    q = np.asarray(q, dtype=float)
    sign = np.where(q[..., 3] < 0.0, -1.0, 1.0)
    vec = q[..., :3] * sign[..., None]
    w = q[..., 3] * sign
    s = np.linalg.norm(vec, axis=-1)
    angle = 2.0 * np.arctan2(s, w)
    small = s < 1e-9
    scale = np.where(small, 2.0 / np.where(small, np.maximum(w, 1e-300), 1.0),
                     angle / np.where(small, 1.0, s))
    return vec * scale[..., None]


def valid(q: np.ndarray, tolerance: float = DEFAULT_NORM_TOLERANCE) -> np.ndarray:
    """Return True where ``q`` is finite with a norm within ``tolerance`` of 1."""
    q = np.asarray(q, dtype=float)
    norm = np.linalg.norm(q, axis=-1)
    with np.errstate(invalid='ignore'):
        return np.isfinite(norm) & (np.abs(norm - 1.0) <= tolerance)


def rate_between(q_prev: np.ndarray, q: np.ndarray, dt: np.ndarray | float) -> np.ndarray:
    """Return the mean body rate (rad/s) that turns ``q_prev`` into ``q`` in ``dt`` seconds.

    Paper eqs. (5)-(6): ``dq = conj(q_{k-1}) (x) q_k`` and ``w_sst = 2 vec(dq) / Ts``.
    Departures, both on purpose: (a) ``dq`` is taken in the hemisphere ``w >= 0`` so that
    a star tracker that outputs ``-q`` instead of ``q`` gives the same rate (without it a
    sign flip reads as a 360-degree turn); (b) the exact rotation vector
    ``2 atan2(|v|, w) v/|v|`` replaces the small-angle ``2 v``; the two agree to third order
    in the angle (1e-9 relative at 4 Hz and 1 deg/s) and the exact form stays right for
    large steps and gaps. ``dt`` comes from the stamps, not a nominal ``Ts``.
    """
    q_prev = np.asarray(q_prev, dtype=float)
    q = np.asarray(q, dtype=float)
    q_prev = q_prev / np.linalg.norm(q_prev, axis=-1, keepdims=True)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    dq = multiply(conjugate(q_prev), q)
    return to_rotation_vector(dq) / np.asarray(dt, dtype=float)[..., None]


def star_tracker_rates(time: np.ndarray, quaternions: np.ndarray, max_gap: float,
                       tolerance: float = DEFAULT_NORM_TOLERANCE) -> np.ndarray:
    """Return the star-tracker rate per row (rad/s), NaN where there is none.

    Row ``k`` gets the rate between the previous valid quaternion and row ``k`` when row
    ``k`` is valid and the two stamps are at most ``max_gap`` seconds apart; the same
    rule as :class:`StarTrackerRate`, vectorised (the tests check both agree).
    """
    max_gap = check_real('max_gap', max_gap, 0.0, low_open=True)
    time = np.asarray(time, dtype=float)
    quaternions = np.asarray(quaternions, dtype=float)
    out = np.full((len(time), 3), np.nan)
    ok = np.flatnonzero(valid(quaternions, tolerance) & np.isfinite(time))
    if len(ok) < 2:
        return out
    # Drop rows whose stamp is not after the last kept one (out of order or duplicate).
    keep = [ok[0]]
    for i in ok[1:]:
        if time[i] > time[keep[-1]]:
            keep.append(i)
    keep = np.asarray(keep)
    prev, cur = keep[:-1], keep[1:]
    dt = time[cur] - time[prev]
    near = dt <= max_gap
    out[cur[near]] = rate_between(quaternions[prev[near]], quaternions[cur[near]], dt[near])
    return out


class StarTrackerRate:
    """Streaming star-tracker rate: one quaternion in, one body rate (or None) out.

    Invalid quaternions (NaN/Inf, norm off by more than ``norm_tolerance``) and stamps not
    after the last accepted one are dropped and counted; a quaternion more than
    ``max_gap`` seconds after the previous one restarts the differencing (no rate for that
    sample, counted as a gap) so that a dropout never yields a rate averaged over it.
    """

    def __init__(self, *, max_gap: float = 1.0,
                 norm_tolerance: float = DEFAULT_NORM_TOLERANCE) -> None:
        self.max_gap = check_real('max_gap', max_gap, 0.0, low_open=True)
        self.norm_tolerance = check_real('norm_tolerance', norm_tolerance, 0.0, 1.0,
                                         low_open=True, high_open=True)
        self.reset()

    def reset(self) -> None:
        """Forget the previous quaternion and zero the counters."""
        self._prev: tuple[float, float, float, float] | None = None
        self._prev_time = -math.inf
        self.invalid = 0
        self.non_increasing_time = 0
        self.gaps = 0

    @property
    def last_time(self) -> float:
        """Return the stamp of the last accepted quaternion (-inf before any)."""
        return self._prev_time

    def update(self, t: float, q) -> tuple[float, float, float] | None:
        """Take the quaternion ``q`` stamped ``t``; return the rate since the last one."""
        x, y, z, w = q
        norm = math.sqrt(x * x + y * y + z * z + w * w)
        if not abs(norm - 1.0) <= self.norm_tolerance or not math.isfinite(t):
            self.invalid += 1
            return None
        if t <= self._prev_time:
            self.non_increasing_time += 1
            return None
        x, y, z, w = x / norm, y / norm, z / norm, w / norm
        prev, dt = self._prev, t - self._prev_time
        self._prev, self._prev_time = (x, y, z, w), t
        if prev is None:
            return None
        if dt > self.max_gap:
            self.gaps += 1
            return None
        return _rate_scalar(prev, (x, y, z, w), dt)

    def record(self) -> StarTrackerState:
        """Return the last accepted quaternion (normalised), its stamp and the counters."""
        return StarTrackerState(self._prev, self._prev_time, self.invalid,
                                self.non_increasing_time, self.gaps)

    def check_record(self, record: StarTrackerState, path: str) -> None:
        """Refuse negative counters, a quaternion that is not unit, a stamp without one."""
        check_type(record, StarTrackerState, path)
        check_counts(record, ('invalid', 'non_increasing_time', 'gaps'), path)
        if record.previous is None:
            require(record.previous_time == -math.inf, f'{path}.previous_time',
                    'a stamp without a quaternion')
            return
        check_finite(f'{path}.previous', record.previous, record.previous_time)
        norm = math.sqrt(sum(v * v for v in record.previous))
        require(abs(norm - 1.0) <= 1e-9, f'{path}.previous', f'norm {norm!r}, not 1')

    def restore(self, record: StarTrackerState) -> None:
        """Put ``record`` back (checked first: RecordError, and the differencer unchanged)."""
        self.check_record(record, type(record).__name__)
        self._prev, self._prev_time = record.previous, record.previous_time
        self.invalid, self.gaps = record.invalid, record.gaps
        self.non_increasing_time = record.non_increasing_time


def _rate_scalar(p, q, dt: float) -> tuple[float, float, float]:
    """Return :func:`rate_between` for one pair, in plain floats (the streaming hot path)."""
    px, py, pz, pw = -p[0], -p[1], -p[2], p[3]
    qx, qy, qz, qw = q
    dx = pw * qx + px * qw + py * qz - pz * qy
    dy = pw * qy - px * qz + py * qw + pz * qx
    dz = pw * qz + px * qy - py * qx + pz * qw
    dw = pw * qw - px * qx - py * qy - pz * qz
    if dw < 0.0:
        dx, dy, dz, dw = -dx, -dy, -dz, -dw
    s = math.sqrt(dx * dx + dy * dy + dz * dz)
    scale = 2.0 / dw if s < 1e-9 else 2.0 * math.atan2(s, dw) / s
    scale /= dt
    return dx * scale, dy * scale, dz * scale
