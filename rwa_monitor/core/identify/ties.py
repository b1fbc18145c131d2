"""Ties between named effects that explain one structure (select.py, joint_scoring.py).

Two named effects can explain the same structure equally well (on the bus, a narrow
Stribeck term and the pre-sliding band both approximate a tanh-smoothed Coulomb term
near zero). When their fitted contributions have a cosine above SAME_STRUCTURE and
Vuong's test for non-nested models cannot tell them apart at the step's level, the one
with the least structure is taken (PRECEDENCE), so that identical wheels do not tell
different stories because of noise.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design

SAME_STRUCTURE = 0.9
# When two named effects are alternative explanations of one structure (their fitted
# contributions have a cosine above SAME_STRUCTURE) and the data cannot tell them apart
# (Vuong's test), the one with the least structure is taken: the pre-sliding band only
# reshapes the Coulomb term at zero speed, Stribeck adds the lubricant film's speed
# scale, hysteresis a memory on top of it.
PRECEDENCE = ('presliding', 'stribeck', 'presliding_state', 'frictional_lag',
              'stribeck_hysteresis', 'stick', 'asymmetric_coulomb', 'drag', 'inertia',
              'gravity_load', 'load_dry', 'aux', 'gear_ripple', 'drift', 'periodic')
# Effects with a state or a position (effects_motion.py) sit after the static speed
# effects they refine, and the position effects before the time effects: on a record
# that repeats one path, a structure tied to the path is periodic in time too.


def _training_residual(design: Design, scored: dict) -> np.ndarray:
    """Return a candidate's fit residual on the training rows."""
    fit, p = scored['fit'], design.X.shape[1]
    return (design.y - design.X @ fit.coef[:p] - scored['columns'] @ fit.coef[p:])[
        design.train]


def _contribution(design: Design, scored: dict) -> np.ndarray:
    """Return what a candidate's columns add to the fit, on the training rows."""
    p = design.X.shape[1]
    return (scored['columns'] @ scored['fit'].coef[p:])[design.train]


def same_structure(design: Design, a: dict, b: dict) -> float:
    """Return the cosine between two candidates' fitted contributions (training rows)."""
    ca, cb = _contribution(design, a), _contribution(design, b)
    norm = float(np.sqrt(np.dot(ca, ca) * np.dot(cb, cb)))
    return abs(float(np.dot(ca, cb))) / norm if norm > 0 else 0.0


def vuong_z(design: Design, a: dict, b: dict, stride: int = 1) -> float:
    """Return Vuong's z for two non-nested fits (positive: ``a`` fits better).

    Per training row, the log-likelihood difference of the two Gaussian fits is
    proportional to r_b^2 - r_a^2 (common variance); z = sqrt(m) mean / sd over every
    stride-th row (m of them) is N(0, 1) when the two fit equally well (Vuong 1989).
    """
    d = (_training_residual(design, b) ** 2 - _training_residual(design, a) ** 2)[::stride]
    sd = float(np.std(d))
    return float(np.sqrt(len(d)) * np.mean(d) / sd) if sd > 0 else 0.0


def preferred(design: Design, data: IdentData, winners: list[dict], level: float,
              record: dict) -> dict:
    """Return the significant named effect to add.

    The smallest validation RSS wins unless another candidate explains the same structure
    (:func:`same_structure` above SAME_STRUCTURE), is indistinguishable from it and
    comes earlier in PRECEDENCE: then that one (identical wheels must not tell different
    stories because of noise). Indistinguishable: Vuong's two-sided test at the step's
    Bonferroni level ``level`` (a preference is claimed only with the evidence a finding
    needs).
    """
    best = min(winners, key=lambda s: s['fit'].rss_validation)
    critical = float(stats.norm.isf(level / 2))
    ties = []
    for s in winners:
        if s is best:
            ties.append(s)
            continue
        cosine = same_structure(design, best, s)
        if cosine < SAME_STRUCTURE:
            continue
        z = vuong_z(design, best, s, max(1, data.stride))
        if abs(z) < critical:
            ties.append(s)
    rank = {k: i for i, k in enumerate(PRECEDENCE)}
    chosen = min(ties, key=lambda s: rank.get(s['candidate'].kind, len(rank)))
    record['vuong_critical'] = critical
    record['indistinguishable'] = [s['candidate'].name for s in ties]
    return chosen
