"""The offline peer of the LLR benchmark: penalised changepoint search on model (1).

A segment's cost is the residual sum of squares of the least-squares fit of model (1),
f = -f_c sign(w) - f_v w, on that segment (the same regressors as the online detector),
computed in O(1) from cumulative sums. The search is the ruptures library's binary
segmentation (Binseg): split where the cost falls most, while the fall exceeds the penalty.
For a single change its first split is the exact least-squares change point, the same as
PELT's (checked on the Fig. 3 runs), at a hundredth of PELT's time. Penalty: BIC-like,
``3 * noise_var * ln(n)`` (each change adds two regression parameters and a location),
with the noise variance known, as the online detector is given it in the benchmark.
"""

from __future__ import annotations

import math

import numpy as np
import ruptures as rpt
from ruptures.base import BaseCost


class FrictionRegressionCost(BaseCost):
    """Least-squares cost of model (1) on a segment, from cumulative sums."""

    model = 'friction_regression'
    min_size = 3

    def fit(self, signal: np.ndarray) -> 'FrictionRegressionCost':
        """Take a signal with columns [friction, speed]; precompute cumulative sums."""
        f, w = signal[:, 0], signal[:, 1]
        s = np.sign(w)
        terms = np.column_stack([s * s, s * w, w * w, s * f, w * f, f * f])
        self.signal = signal
        self._cum = np.vstack([np.zeros(6), np.cumsum(terms, axis=0)])
        return self

    def error(self, start: int, end: int) -> float:
        """Return the residual sum of squares of the model (1) fit on [start, end)."""
        ss, sw, ww, sf, wf, ff = (self._cum[end] - self._cum[start]).tolist()
        det = ss * ww - sw * sw
        if det > 1e-9 * max(ss * ww, 1e-300):
            rss = ff - (ww * sf * sf - 2.0 * sw * sf * wf + ss * wf * wf) / det
        elif ww > 0.0:  # regressors collinear: one-parameter fit on w
            rss = ff - wf * wf / ww
        else:
            rss = ff
        return max(rss, 0.0)


def bic_penalty(n: int, noise_var: float) -> float:
    """Return the BIC-like penalty of one change: 3 parameters x noise_var x ln(n)."""
    return 3.0 * noise_var * math.log(n)


def detect_offline(speed: np.ndarray, friction: np.ndarray, *, noise_var: float = 1.0,
                   min_size: int = 50, jump: int = 5) -> list[int]:
    """Return the change indices (first sample of each new segment) found by Binseg."""
    signal = np.column_stack([friction, speed])
    algo = rpt.Binseg(custom_cost=FrictionRegressionCost(), min_size=min_size, jump=jump)
    bkps = algo.fit(signal).predict(pen=bic_penalty(len(signal), noise_var))
    return [int(b) for b in bkps[:-1]]
