"""Candidate effects of a joint selection: one hypothesis for every sibling wheel.

A candidate's nonlinear parameters are shared (one Stribeck speed, band width, exponent
or frequency for the design; the grids of speeds span quantiles of the pooled abs(w));
its weights are each wheel's own. grid[g][k] is wheel k's parameters at grid point g
(None: the effect cannot be shown on that wheel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.consistency import sibling_name as canonical_name
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.scoring import free_parameters

POOLED_SCALES = ('stribeck', 'stribeck_hysteresis', 'presliding')


@dataclass
class JointCandidate:
    """An effect tested on every wheel at once: grid[g][k] = wheel k's parameters."""

    name: str
    kind: str
    grid: list[list[dict | None]]
    tests: int
    free: int = 0
    refine: tuple[str, float] | None = None
    skipped: str | None = None


def joint_candidates(datas: list[IdentData], residuals: list[np.ndarray]
                     ) -> tuple[list[JointCandidate], JointCandidate]:
    """Return the named joint candidates and the joint fallback."""
    per = [{canonical_name(c.name, d.wheel): c for c in fx.named_candidates(d, r)}
           for d, r in zip(datas, residuals)]
    names = list(dict.fromkeys(n for p in per for n in p))
    pooled_speed = np.concatenate([np.abs(d.speed) for d in datas])
    out = []
    for name in names:
        cands = [p.get(name) for p in per]
        ok = [c is not None and c.skipped is None for c in cands]
        first = next(c for c, good in zip(cands, ok) if good) if any(ok) else None
        kind = next(c for c in cands if c is not None).kind
        if first is None:
            reason = next(c.skipped for c in cands if c is not None)
            out.append(JointCandidate(name, kind, [], 1, skipped=reason))
            continue
        if kind in POOLED_SCALES:
            ref = _pooled_scales(kind, datas[ok.index(True)], pooled_speed)
            grid = [[dict(g) if good else None for good in ok] for g in ref.grid]
            refine = (ref.extra['refine'], ref.extra['ratio']) if 'refine' in ref.extra \
                else None
            out.append(JointCandidate(name, kind, grid, ref.tests, free_parameters(ref),
                                      refine))
        elif kind == 'periodic':
            freqs = sorted({g['frequency_hz'] for c, good in zip(cands, ok) if good
                            for g in c.grid})
            grid = [[{**c.grid[0], 'frequency_hz': f} if good else None
                     for c, good in zip(cands, ok)] for f in freqs]
            out.append(JointCandidate(name, kind, grid,
                                      sum(c.tests for c, good in zip(cands, ok) if good),
                                      1 if len(freqs) > 1 else 0))
        else:
            grid = [[c.grid[g] if good and g < len(c.grid) else None
                     for c, good in zip(cands, ok)] for g in range(len(first.grid))]
            out.append(JointCandidate(name, kind, grid, first.tests, free_parameters(first)))
    backs = [fx.fallback_candidate(d) for d in datas]
    fallback = JointCandidate(fx.FALLBACK, 'smooth_speed', [[b.grid[0] for b in backs]],
                              backs[0].tests)
    return out, fallback


def _pooled_scales(kind: str, data: IdentData, pooled_speed: np.ndarray) -> fx.Candidate:
    if kind == 'stribeck':
        return fx.stribeck_candidate(pooled_speed[pooled_speed != 0])
    if kind == 'stribeck_hysteresis':
        return fx.hysteresis_candidate(data, pooled_speed)
    return fx.presliding_candidate(data, pooled_speed)
