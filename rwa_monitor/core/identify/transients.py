"""External torque episodes in a speed record: a touch or a brake is not friction.

When friction is derived from speed (eq. 1b, f = J dw/dt - K_T I), any torque the model
does not know acts through dw/dt: a hand or a tool touching a coasting body for a few
seconds, a brake at the end of a coast. Such an episode is not a friction jump (the
friction law is the same before and after it; the detectors look for steps that
persist) and no friction effect explains it: left in, it passes for one or two jumps
whose segments give model (1) a piecewise fit of the speed's curvature (the baseline's
error then looks small on a different footing), and it shortens the differentiator
chosen from the data (its kink looks like a large third derivative).

Found in two steps on each run without gaps:

1. Samples whose friction estimate departs from the record's trend: dw/dt from the
   finest local quadratic (``HALF_WIDTH`` = 2: a few samples long, so a short episode is
   not smeared), standardised by the propagated noise, against two trends over
   ``TREND_SAMPLES``: the running median (it keeps a friction step, and only episodes
   shorter than half its window stand out; at the run's ends it is extended linearly)
   and the local quadratic (it follows a smooth extremum, which a median flattens). A
   sample is flagged when its departure from both exceeds the two-sided Bonferroni
   level alpha / n. Neighbouring flagged samples (closer than one window) form one
   episode.
2. An episode is external when it carries a net impulse: the speed after it is offset
   from the speed before it. A cubic in time plus a kink (a friction step at the
   episode, allowed) plus a step (the impulse) is fitted to ``TREND_SAMPLES`` speed
   samples on each side, weighted by the speed noise; the step's z beyond the same
   level marks the episode. A timing glitch of one pulse shifts one speed sample up and
   the next one down (the two intervals share the glitched pulse): no net impulse, kept.
   An episode too close to a run's end (fewer than half the samples on its far side)
   cannot be tested this way: the run is trimmed to exclude it (the coast is taken to
   start after it, or to end before it: a lift-off at the start, a brake at the end).

Only runs whose speed keeps one sign (coasts) are searched: where the speed passes zero,
friction's own structure is as fast as a touch (the sign flip, the breakaway and the
Stribeck peak on leaving zero carry a net impulse too) and this test cannot tell them
apart. Episodes longer than half the trend window are not found.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import stats

from rwa_monitor.core.identify.differentiate import local_noise_std
from rwa_monitor.core.identify.differentiate import local_polynomial_derivative
from rwa_monitor.core.identify.differentiate import local_polynomial_smooth

HALF_WIDTH = 2
TREND_SAMPLES = 51
NOISE_BLOCK = 200


@dataclass
class Episode:
    """An external torque episode: rows first..last (inclusive) of one run, and why."""

    first: int
    last: int
    kind: str            # 'impulse' (inside the run) or 'edge' (run trimmed)
    peak_z: float        # largest standardised departure of dw/dt from the trend
    impulse_rad_s: float | None = None
    impulse_z: float | None = None


def running_median(values: np.ndarray, width: int) -> np.ndarray:
    """Return the centred running median; the ends continue the trend linearly.

    Within half a window of an end the median of a shorter window would lean on the
    samples under test, and the first full window's median is a value from its centre:
    both hide or invent departures there, so the ends extrapolate the first (last) full
    median along its slope over half a window.
    """
    values = np.asarray(values, dtype=float)
    n, h = len(values), width // 2
    if n < 2 * width:
        return np.full(n, float(np.median(values)))
    out = np.empty(n)
    out[h:n - h] = np.median(sliding_window_view(values, 2 * h + 1), axis=1)
    head = (out[2 * h] - out[h]) / h
    tail = (out[n - 1 - h] - out[n - 1 - 2 * h]) / h
    out[:h] = out[h] + head * (np.arange(h) - h)
    out[n - h:] = out[n - 1 - h] + tail * (np.arange(n - h, n) - (n - 1 - h))
    return out


def _impulse(time: np.ndarray, speed: np.ndarray, noise: np.ndarray, first: int,
             last: int, side: int) -> tuple[float, float]:
    """Return (speed step across rows first..last, its z) from the samples either side."""
    lo, hi = max(0, first - side), min(len(time), last + 1 + side)
    rows = np.r_[lo:first, last + 1:hi]
    tau = (time[rows] - time[first]) / (time[hi - 1] - time[lo])
    X = np.column_stack([tau ** k for k in range(4)]
                        + [np.maximum(tau, 0.0), (rows > last).astype(float)])
    Xw = X / noise[rows, None]
    coef, *_ = np.linalg.lstsq(Xw, speed[rows] / noise[rows], rcond=None)
    cov = np.linalg.pinv(Xw.T @ Xw)
    return float(coef[-1]), float(coef[-1] / np.sqrt(max(cov[-1, -1], 1e-300)))


def external_torques(time: np.ndarray, speed: np.ndarray, alpha: float = 1e-3,
                     samples: int | None = None) -> list[Episode]:
    """Return the external torque episodes of one run (rows of ``time``, no gaps).

    ``samples`` is the record's size for the Bonferroni level (default: this run's).
    """
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    n = len(time)
    if n < 2 * TREND_SAMPLES or np.any(speed > 0) and np.any(speed < 0):
        return []
    level = float(stats.norm.isf(alpha / (2 * (samples or n))))
    rate, gain = local_polynomial_derivative(time, speed, HALF_WIDTH)
    noise = local_noise_std(time, speed, HALF_WIDTH, 2, NOISE_BLOCK)
    scale = np.maximum(gain * noise, 1e-300)
    to_median = (rate - running_median(rate, TREND_SAMPLES)) / scale
    to_smooth = (rate - local_polynomial_smooth(time, rate, TREND_SAMPLES // 2)) / scale
    z = np.where(np.abs(to_median) < np.abs(to_smooth), to_median, to_smooth)
    flagged = np.flatnonzero(np.abs(z) > level)
    if not len(flagged):
        return []
    out = []
    side = TREND_SAMPLES
    for group in np.split(flagged, np.flatnonzero(np.diff(flagged) > 2 * HALF_WIDTH + 1) + 1):
        first = max(int(group[0]) - HALF_WIDTH, 0)
        last = min(int(group[-1]) + HALF_WIDTH, n - 1)
        peak = float(np.max(np.abs(z[group])))
        if first < side // 2:
            out.append(Episode(0, last, 'edge', peak))
        elif n - 1 - last < side // 2:
            out.append(Episode(first, n - 1, 'edge', peak))
        else:
            step, step_z = _impulse(time, speed, noise, first, last, side)
            if abs(step_z) > level:
                out.append(Episode(first, last, 'impulse', peak, step, step_z))
    return out
