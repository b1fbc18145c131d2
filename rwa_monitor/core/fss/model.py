"""Friction switching systems (FSS): the known part of the model, eq. (5)-(8).

A system has ``n_config`` configurations q = 0 .. n_config - 1, jumps only between
contiguous ones (section III-B), and stays in configuration q for a residence time drawn
uniformly from the integers ``[lo_q, hi_q]``. That is exactly the hazard form of the
paper's examples: P^t(q, tau) = 1 / (hi_q + 1 - tau) for tau >= lo_q (0 before), whose
residence time is uniform on [lo_q, hi_q]. The friction-level distribution P^f(f | q) is
uniform on ``levels[q]``; it is used by the simulator only, since the diagnoser does not
know it (Remark 1).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

# Log-probability given to an event the model calls impossible (docs/fss.md): keeps
# every assignment finite so that windows that break the model still get one.
LOG_FLOOR = -20.0


@dataclass(frozen=True)
class SwitchingSystem:
    """One FSS: residence ranges (steps) and level ranges per configuration."""

    name: str
    residence: tuple[tuple[int, int], ...]
    levels: tuple[tuple[float, float], ...]
    p_up: float = 0.5

    def __post_init__(self) -> None:
        if len(self.residence) < 2 or len(self.residence) != len(self.levels):
            raise ValueError(f'{self.name}: residence and levels must list the same number '
                             f'(>= 2) of configurations')
        for lo, hi in self.residence:
            if not (1 <= lo <= hi):
                raise ValueError(f'{self.name}: residence range must have 1 <= lo <= hi, '
                                 f'got {(lo, hi)}')
        for lo, hi in self.levels:
            if not lo <= hi:
                raise ValueError(f'{self.name}: level range must have lo <= hi')
        if not 0.0 < self.p_up < 1.0:
            raise ValueError(f'{self.name}: p_up must be in (0, 1), got {self.p_up}')

    @property
    def n_config(self) -> int:
        return len(self.residence)

    def with_levels(self, levels: tuple[tuple[float, float], ...]) -> 'SwitchingSystem':
        """Return the same system with another friction-level distribution, eq. (9b)."""
        return SwitchingSystem(self.name, self.residence, tuple(levels), self.p_up)

    def log_pq(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Return log P^q(q + dq | q) (eq. 6): contiguous jumps only, LOG_FLOOR if not."""
        q = np.asarray(q)
        dq = np.asarray(dq)
        top = self.n_config - 1
        new = q + dq
        out = np.full(np.broadcast(q, dq).shape, LOG_FLOOR)
        ok = (np.abs(dq) == 1) & (new >= 0) & (new <= top)
        interior = (q > 0) & (q < top)
        p = np.where(interior, np.where(dq > 0, self.p_up, 1.0 - self.p_up), 1.0)
        out[ok] = np.log(p[ok]) if np.ndim(p) else math.log(float(p))
        return out

    def _ranges(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        res = np.asarray(self.residence, dtype=float)
        return res[q, 0], res[q, 1]

    def log_pmf(self, q: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Return log P(residence = d) in configuration q (a completed sojourn)."""
        lo, hi = self._ranges(np.asarray(q))
        ok = (d >= lo) & (d <= hi)
        return np.where(ok, -np.log(hi - lo + 1.0), LOG_FLOOR)

    def log_first(self, q: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Return the log-likelihood of a first jump d steps into the window.

        The sojourn began before the window, tau_0 steps earlier; as section IV-C1 says,
        tau_0 is chosen to maximise the score: max over tau_0 >= 0 of
        P(D = tau_0 + d) / P(D > tau_0), which for a uniform residence is 1 / min(d, R)
        (R = hi - lo + 1) when d <= hi, and impossible otherwise.
        """
        lo, hi = self._ranges(np.asarray(q))
        d = np.asarray(d, dtype=float)
        ok = (d >= 1) & (d <= hi)
        return np.where(ok, -np.log(np.maximum(np.minimum(d, hi - lo + 1.0), 1.0)),
                        LOG_FLOOR)

    def log_survival(self, q: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Return log P(residence > d): no jump for the last d steps of the window."""
        lo, hi = self._ranges(np.asarray(q))
        d = np.asarray(d, dtype=float)
        surv = np.where(d < lo, 1.0, (hi - d) / (hi - lo + 1.0))
        with np.errstate(divide='ignore'):
            return np.where(surv > 0, np.log(np.maximum(surv, 1e-300)), LOG_FLOOR).clip(
                LOG_FLOOR, 0.0)

    def sample_residence(self, q: int, rng: np.random.Generator) -> int:
        """Draw one residence time (steps) in configuration q."""
        lo, hi = self.residence[q]
        return int(rng.integers(lo, hi + 1))

    def sample_next(self, q: int, rng: np.random.Generator) -> int:
        """Draw the next configuration from P^q(. | q)."""
        if q == 0:
            return 1
        if q == self.n_config - 1:
            return q - 1
        return q + 1 if rng.random() < self.p_up else q - 1


# Example 1 (eq. 7): short-lived oil-pocket jumps. The text says the system "stays
# inactive most of the time, getting activated only for a few steps", while eq. (7b) as
# printed gives the inactive configuration the short residence: we follow the text and
# give q = 0 (inactive) up to 2000 steps and q = 1 (active) up to 200 (docs/fss.md).
EXAMPLE_1 = SwitchingSystem('fss1', residence=((1, 2000), (1, 200)),
                            levels=((0.0, 0.1), (0.3, 0.4)))

# Example 2 (eq. 8): three cage configurations, the same residence law for each:
# P^t = 1 / (30000 - tau) for tau > 10000 (eq. 8b writes x for tau), i.e. uniform on
# [10001, 30000]. Levels uniform on (0.5 q, 0.5 q + 0.4); eq. (8a) prints a density of
# 1.5 which does not integrate to one on a width of 0.4: we read it as uniform.
EXAMPLE_2 = SwitchingSystem('fss2', residence=((10001, 30000),) * 3,
                            levels=((0.0, 0.4), (0.5, 0.9), (1.0, 1.4)))

DEFAULT_SYSTEMS = (EXAMPLE_1, EXAMPLE_2)
