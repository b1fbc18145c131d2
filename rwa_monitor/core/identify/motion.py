"""Quantities simulated along the record from the speed alone: position, lags, stick.

Friction with a memory is not a function of the present speed: its state is simulated
along the record from the measured speed (the input) and the friction it predicts is
compared with the measured friction (the output), as an output-error model is; the
measured friction never enters the state. The states here are driven by the speed only:

- ``position``: the integral of the speed (trapezoid rule), the joint angle up to an
  offset (a speed bias makes it drift by bias x time);
- ``first_order_lag``: s' = (x - s) / T, exact for an input held over each sample
  interval (s_k = a_k s_(k-1) + (1 - a_k) x_k, a_k = exp(-dt_k / T)), any sampling;
- ``dahl``: Dahl's pre-sliding state, dz/dq = (sign(dq) - z) / d: the same recurrence
  in the distance travelled instead of time (z approaches +-1 exponentially over the
  breakaway displacement d after a reversal);
- ``maxwell_slip``: one elastoplastic (Maxwell-slip) element, z = clip(z + dq / d, -1,
  1): it sticks and deforms linearly until its displacement reaches d, then slides;
- ``stick_episodes``: the stops in which the joint rests (the speed averaged over a few
  samples stays within a band of zero), with the direction before and after each and
  the normalised time u = (t - t_start) / (t_end - t_start) inside it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.ndimage import uniform_filter1d

# exp(-EXPONENT_BLOCK) stays far above the smallest double: blocks of the lag recurrence
# end before the cumulative decay reaches it (see first_order_lag).
EXPONENT_BLOCK = 300.0
# One step's decay is capped here: exp(-50) = 2e-22, a state forgotten to double
# precision (a time gap far longer than the lag); without the cap exp(decay) overflows.
MAX_DECAY = 50.0


def position(time: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Return the integral of the speed from the first sample (rad; trapezoid rule)."""
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    out = np.zeros(len(speed))
    if len(speed) > 1:
        out[1:] = np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(time))
    return out


def _affine(decay: np.ndarray, drive: np.ndarray, start: float) -> np.ndarray:
    """Return s with s_k = a_k s_(k-1) + b_k (s_(-1) = ``start``), a_k = exp(-decay_k).

    Vectorised in blocks: within a block s_k = A_k (s_0 + sum_j b_j / A_j), A_k the
    product of the a_j; a block ends before -log A_k exceeds EXPONENT_BLOCK, so 1 / A_j
    never overflows. ``decay`` >= 0.
    """
    n = len(decay)
    out = np.empty(n)
    total = np.cumsum(decay)
    i, s = 0, float(start)
    while i < n:
        base = total[i] - decay[i]
        j = int(np.searchsorted(total, base + EXPONENT_BLOCK, side='right'))
        j = max(j, i + 1)
        log_a = total[i:j] - base        # -log A_k within the block
        inv = np.exp(log_a)
        out[i:j] = (s + np.cumsum(drive[i:j] * inv)) / inv
        s = float(out[j - 1])
        i = j
    return out


def first_order_lag(time: np.ndarray, values: np.ndarray, lag_s: float) -> np.ndarray:
    """Return ``values`` through the first-order lag s' = (x - s) / T (T = ``lag_s``).

    Exact for an input held over each interval; starts at the first value (no
    transient). Uneven sampling is handled sample by sample.
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    if len(values) == 0:
        return values.copy()
    decay = np.minimum(np.concatenate([[0.0], np.diff(time)]) / float(lag_s), MAX_DECAY)
    return _affine(decay, -np.expm1(-decay) * values, values[0])


def dahl(travel: np.ndarray, breakaway: float) -> np.ndarray:
    """Return Dahl's normalised pre-sliding state along a path (z in [-1, 1]).

    ``travel``: the position at each sample. dz/dq = (sign(dq) - z) / d with d =
    ``breakaway``: exact per interval, z_k = a_k z_(k-1) + (1 - a_k) sign(dq_k),
    a_k = exp(-|dq_k| / d). Starts at 0 (no memory before the record).
    """
    travel = np.asarray(travel, dtype=float)
    step = np.concatenate([[0.0], np.diff(travel)])
    decay = np.minimum(np.abs(step) / float(breakaway), MAX_DECAY)
    return _affine(decay, -np.expm1(-decay) * np.sign(step), 0.0)


def maxwell_slip(travel: np.ndarray, breakaway: float) -> np.ndarray:
    """Return one Maxwell-slip element's normalised state, z = clip(z + dq / d, -1, 1)."""
    travel = np.asarray(travel, dtype=float)
    step = (np.concatenate([[0.0], np.diff(travel)]) / float(breakaway)).tolist()
    out = [0.0] * len(step)
    z = 0.0
    for k, dz in enumerate(step):
        z = min(1.0, max(-1.0, z + dz))
        out[k] = z
    return np.asarray(out)


def smoothed(values: np.ndarray, half_width: int) -> np.ndarray:
    """Return the centred moving average over 2 h + 1 samples (ends: nearest values)."""
    return uniform_filter1d(np.asarray(values, dtype=float), 2 * int(half_width) + 1,
                            mode='nearest')


class Stick(NamedTuple):
    """Stick episodes: mask, normalised time inside, direction before and after each."""

    mask: np.ndarray
    u: np.ndarray
    before: np.ndarray
    after: np.ndarray
    count: int


def stick_episodes(time: np.ndarray, speed: np.ndarray, band: float, half_width: int,
                   min_samples: int | None = None) -> Stick:
    """Return the episodes in which the joint rests: |speed averaged over 2h+1| < band.

    An episode lasts at least ``min_samples`` (default 3 (2h + 1)) samples, so that a
    passage through zero is not a stop. ``before`` / ``after``: the sign of the summed
    speed over the 2 (2h + 1) samples before / after the episode (0 at the record's ends);
    ``u`` in [0, 1) runs from the episode's first sample to the one after its last. Rows
    outside episodes have u = 0 and directions 0.
    """
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    n = len(speed)
    width = 2 * int(half_width) + 1
    min_samples = 3 * width if min_samples is None else int(min_samples)
    still = np.abs(smoothed(speed, half_width)) < band
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
    mask = np.zeros(n, dtype=bool)
    u = np.zeros(n)
    before = np.zeros(n)
    after = np.zeros(n)
    count = 0
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a < min_samples:
            continue
        count += 1
        end = time[b] if b < n else time[-1] + (time[-1] - time[a]) / max(b - a - 1, 1)
        span = max(end - time[a], 1e-300)
        mask[a:b] = True
        u[a:b] = (time[a:b] - time[a]) / span
        before[a:b] = np.sign(np.sum(speed[max(a - 2 * width, 0):a]))
        after[a:b] = np.sign(np.sum(speed[b:b + 2 * width]))
    return Stick(mask, u, before, after, count)


class Reversals(NamedTuple):
    """Per sample: time and distance since the last reversal, and the direction before."""

    since_s: np.ndarray
    distance: np.ndarray
    previous: np.ndarray


def reversals(time: np.ndarray, speed: np.ndarray, band: float = 0.0) -> Reversals:
    """Return the memory of the last reversal of the direction of motion.

    The direction is sign(w) outside |w| <= ``band`` and keeps its last value inside; a
    reversal is a change of that direction. ``since_s`` and ``distance`` (|position|
    travelled, rad) count from the last reversal (inf before the first); ``previous`` is
    the direction before it (0 before the first).
    """
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    n = len(speed)
    raw = np.where(np.abs(speed) > band, np.sign(speed), 0.0)
    idx = np.arange(n)
    last = np.maximum.accumulate(np.where(raw != 0, idx, -1))
    direction = np.where(last >= 0, raw[np.maximum(last, 0)], 0.0)
    change = np.zeros(n, dtype=bool)
    change[1:] = (direction[1:] != direction[:-1]) & (direction[:-1] != 0)
    at = np.maximum.accumulate(np.where(change, idx, -1))
    since = np.where(at >= 0, time - time[np.maximum(at, 0)], np.inf)
    pos = position(time, speed)
    distance = np.where(at >= 0, np.abs(pos - pos[np.maximum(at, 0)]), np.inf)
    previous = np.where(at >= 1, direction[np.maximum(at - 1, 0)], 0.0)
    return Reversals(since, distance, previous)
