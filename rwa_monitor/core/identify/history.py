"""The speed's history at every sample: direction of change, zero passages, memory.

Friction may depend on more than the present speed. Near zero speed a bearing's friction
has a memory: leaving rest, the contact breaks away and friction follows the Stribeck
curve; approaching rest, the lubricant film still carries the load and friction stays
near the Coulomb level (the hysteresis loop of friction against speed). The quantities
here describe that history from the sampled speed alone, so that the residual can be
tested against them (residuals.py) and the hysteresis effect can be built (effects.py):

- ``rate``: dw/dt (local polynomial slope, differentiate.py);
- ``receding``: abs(w) rising (sign(w) dw/dt above the rate's noise), the wheel moving
  away from zero speed; ``approaching``: abs(w) falling (below minus the noise);
- ``zero_passage``: the speed changed sign between two samples, or a sample lies within
  one typical low-speed step of zero (the path may have touched zero in between);
- ``since_zero_s``: time since the last zero passage (inf before the first);
- ``left_zero``: a zero passage happened at or after the last sample at which abs(w)
  fell: the wheel has been moving away from zero ever since it passed it (the branch
  of the loop that carries the breakaway peak);
- ``position``: the integral of the speed (motion.py), the angle up to an offset;
- ``since_reversal_s`` / ``distance_since_reversal``: time and distance travelled since
  the direction of motion last changed (the direction keeps its value while abs(w) is
  below its 5 % quantile, so noise about zero in a stop is not a reversal), and
  ``previous_direction``: the direction before that reversal (the sign history).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rwa_monitor.core.identify.motion import position, reversals

RATE_NOISE_SIGMAS = 3.0
REVERSAL_BAND_QUANTILE = 0.05


@dataclass
class History:
    """History features of the speed, one value per sample."""

    rate: np.ndarray
    receding: np.ndarray
    approaching: np.ndarray
    zero_passage: np.ndarray
    since_zero_s: np.ndarray
    left_zero: np.ndarray
    position: np.ndarray
    since_reversal_s: np.ndarray
    distance_since_reversal: np.ndarray
    previous_direction: np.ndarray

    @property
    def passages(self) -> int:
        """Return the number of zero passages."""
        return int(np.sum(self.zero_passage))


def zero_passages(speed: np.ndarray) -> np.ndarray:
    """Return the samples at which the speed passes through (or touches) zero."""
    speed = np.asarray(speed, dtype=float)
    n = len(speed)
    out = np.zeros(n, dtype=bool)
    if n < 2:
        return out
    sign = np.sign(speed)
    out[1:] = (sign[1:] * sign[:-1] < 0) | ((sign[1:] == 0) & (sign[:-1] != 0))
    step = np.abs(np.diff(speed))
    low = np.abs(speed[1:]) <= np.quantile(np.abs(speed), 0.05)
    touch = float(np.median(step[low])) if np.any(low) else 0.0
    aw = np.abs(speed)
    local_min = np.zeros(n, dtype=bool)
    local_min[1:-1] = (aw[1:-1] <= aw[:-2]) & (aw[1:-1] <= aw[2:])
    out |= local_min & (aw <= touch) & (sign != 0)
    return out


def history(time: np.ndarray, speed: np.ndarray, rate: np.ndarray,
            rate_noise: np.ndarray | float = 0.0) -> History:
    """Return the history features of a speed record (``rate`` = dw/dt per sample)."""
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    rate = np.asarray(rate, dtype=float)
    tol = RATE_NOISE_SIGMAS * np.asarray(rate_noise, dtype=float)
    outward = np.sign(speed) * rate
    receding = outward > tol
    approaching = outward < -tol
    passage = zero_passages(speed)
    n = len(speed)
    idx = np.arange(n)
    last_zero = np.maximum.accumulate(np.where(passage, idx, -1))
    last_fall = np.maximum.accumulate(np.where(approaching, idx, -1))
    left_zero = (last_zero >= 0) & (last_zero >= last_fall) & (speed != 0)
    since = np.where(last_zero >= 0, time - time[np.maximum(last_zero, 0)], np.inf)
    band = float(np.quantile(np.abs(speed), REVERSAL_BAND_QUANTILE)) if n else 0.0
    turns = reversals(time, speed, band)
    return History(rate=rate, receding=receding, approaching=approaching,
                   zero_passage=passage, since_zero_s=since, left_zero=left_zero,
                   position=position(time, speed), since_reversal_s=turns.since_s,
                   distance_since_reversal=turns.distance,
                   previous_direction=turns.previous)
