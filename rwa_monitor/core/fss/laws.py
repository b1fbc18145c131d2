"""Switching laws of the FSSs estimated from nominal data (commissioning), for stage 3.

Remark 1 of the physics-informed FSS paper assumes the jump laws P^t_s and the
configuration laws P^q_s of every FSS known ("from historical data, expert knowledge, or
both"). Here only the structure is given: the number of systems, their number of
configurations, their order (the fastest first) and the family of laws (a residence time
uniform on integers [lo, hi] per configuration, contiguous moves, section III-B). The
ranges and the probability of moving up are estimated from nominal windows by hard EM
(Viterbi training, docs/fss.md "Switching laws from commissioning"):

1. stages 1-2 on every window: changepoints, their sign and size;
2. a first assignment without any law: a jump undone by the next changepoint (opposite
   sign, sizes within ``PAIR_TOLERANCE``) is an activation of the fastest system,
   every other changepoint belongs to the slowest one;
3. the ranges from the sojourns of that assignment (:func:`uniform_range`), then the
   DP of stage 3 with these laws re-assigns every changepoint; repeated ``iterations``
   times (the assignment's sojourns per configuration, pooled over the system's
   configurations when one has fewer than ``MIN_SOJOURNS``).

A sojourn still running at the end of a window, or begun before its start, is censored:
it only raises ``hi`` to at least its length. The friction-level ranges are not
estimated (the diagnoser does not use them, Remark 1): the structure's are kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rwa_monitor.core.fss.assign import assign_changepoints
from rwa_monitor.core.fss.model import SwitchingSystem
from rwa_monitor.core.fss.segments import fit_intervals
from rwa_monitor.core.fss.wglr import detect_changepoints

# A jump and the next changepoint form a fast-system activation when their sizes sum to
# less than this fraction of the smaller one (they undo each other).
PAIR_TOLERANCE = 0.5
# Fewest complete sojourns for a configuration's own range (else the system's pool).
MIN_SOJOURNS = 20
# Quantiles matched to the uniform family (robust to a few misassigned sojourns).
QUANTILES = (0.1, 0.9)


@dataclass
class WindowJumps:
    """Stages 1-2 of one nominal window: changepoints, signs, rejection costs, length."""

    times: np.ndarray
    signs: np.ndarray
    deltas: np.ndarray
    reject_cost: np.ndarray
    n: int


def window_jumps(speed: np.ndarray, friction: np.ndarray, config) -> WindowJumps:
    """Return stages 1-2 of one normalised, paper-sign window under ``config``."""
    cps = detect_changepoints(friction, speed, window=config.wglr_window,
                              w_bias=config.w_bias, viscous_prior=config.viscous_prior,
                              p_false=config.p_false)
    fit = fit_intervals(friction, speed, cps.changepoints, dk_error=config.dk_error,
                        viscous_prior=config.viscous_prior)
    sigma2 = fit.sigma2 if np.isfinite(fit.sigma2) and fit.sigma2 > 0 else 1.0
    deltas = np.diff(fit.dry)
    return WindowJumps(times=fit.changepoints.astype(np.int64),
                       signs=np.where(deltas >= 0, 1, -1), deltas=deltas,
                       reject_cost=fit.rejection_cost / (2.0 * sigma2), n=int(speed.size))


def uniform_range(complete: Sequence[int], censored: Sequence[int] = ()
                  ) -> tuple[int, int] | None:
    """Return [lo, hi] of a uniform residence law from sojourn lengths (None if none).

    Quantile matching: for a uniform law on [lo, hi] the p-quantile is lo + p (hi - lo),
    so the ``QUANTILES`` (q1, q2) of the complete sojourns give hi - lo =
    (Q2 - Q1) / (q2 - q1), then lo and hi; a censored sojourn of length d only says
    hi >= d. With fewer than 3 complete sojourns: [min, max] of them.
    """
    x = np.sort(np.asarray(complete, dtype=float))
    if x.size == 0:
        return None
    if x.size < 3:
        lo, hi = x[0], x[-1]
    else:
        p1, p2 = QUANTILES
        q1, q2 = np.quantile(x, [p1, p2])
        width = (q2 - q1) / (p2 - p1)
        lo, hi = q1 - p1 * width, q2 + (1.0 - p2) * width
    if len(censored):
        hi = max(hi, float(np.max(censored)))
    lo = max(1, int(np.floor(lo)))
    return lo, max(lo, int(np.ceil(hi)))


def _initial_inputs(jumps: WindowJumps, n_systems: int) -> np.ndarray:
    """Return a first assignment: undone jumps to system 1, the rest to system S."""
    u = np.full(jumps.times.size, n_systems, dtype=np.int64)
    i = 0
    d = jumps.deltas
    while i + 1 < d.size:
        a, b = d[i], d[i + 1]
        if a > 0 > b and abs(a + b) <= PAIR_TOLERANCE * min(abs(a), abs(b)):
            u[i] = u[i + 1] = 1
            i += 2
        else:
            i += 1
    return u


def _replay(jumps: WindowJumps, inputs: np.ndarray, system: int, n_config: int,
            q0: int | None) -> tuple[list, list, list]:
    """Return (complete (q, d), censored (q, d), moves (q, up)) of one system's jumps."""
    sel = np.flatnonzero(inputs == system)
    times, signs = jumps.times[sel], jumps.signs[sel]
    if q0 is None:  # the lowest start that keeps every configuration in range
        levels = np.concatenate(([0], np.cumsum(signs)))
        q0 = int(-levels.min())
    q = q0
    complete, censored, moves = [], [], []
    if times.size == 0:
        return complete, [(q, jumps.n)], moves
    censored.append((q, int(times[0])))
    for k in range(times.size):
        if k > 0:
            complete.append((q, int(times[k] - times[k - 1])))
        if 0 < q < n_config - 1:
            moves.append((q, signs[k] > 0))
        q = min(max(q + int(signs[k]), 0), n_config - 1)
    censored.append((q, int(jumps.n - times[-1])))
    return complete, censored, moves


def _laws(structure: Sequence[SwitchingSystem], sojourns: list[dict]
          ) -> tuple[SwitchingSystem, ...]:
    """Return the systems with ranges and p_up from the sojourns of an assignment.

    Time scales are separated (the structure lists the fastest system first): a sojourn
    of a slower system shorter than the faster system's longest residence is not told
    apart from the faster system's activity, so it is left out of that system's
    estimate and its ``lo`` is at least that residence.
    """
    out: list[SwitchingSystem] = []
    for s, system in enumerate(structure):
        data = sojourns[s]
        floor = max(hi for _, hi in out[-1].residence) if out else 0
        complete = [(q, d) for q, d in data['complete'] if d > floor]
        pooled = [d for _, d in complete]
        whole = uniform_range(pooled, [d for _, d in data['censored']]) or \
            system.residence[0]
        ranges = []
        for q in range(system.n_config):
            own = [d for qq, d in complete if qq == q]
            cens = [d for qq, d in data['censored'] if qq == q]
            lo, hi = (uniform_range(own, cens) if len(own) >= MIN_SOJOURNS else None) \
                or whole
            lo = max(lo, floor + 1)
            ranges.append((lo, max(lo, hi)))
        ups = [up for _, up in data['moves']]
        p_up = float(np.clip(np.mean(ups), 0.05, 0.95)) if ups else 0.5
        out.append(SwitchingSystem(system.name, tuple(ranges), system.levels, p_up))
    return tuple(out)


def estimate_systems(windows: Sequence[tuple[np.ndarray, np.ndarray]],
                     structure: Sequence[SwitchingSystem], config, *,
                     iterations: int = 2, beam: int = 256
                     ) -> tuple[tuple[SwitchingSystem, ...], dict]:
    """Return the switching laws estimated from nominal windows, and a report.

    ``windows``: (speed, friction) normalised, paper sign, fault-free; ``structure``:
    the systems whose number of configurations, order and names are kept (their
    residence ranges and p_up are ignored); ``config``: the stage-1/2 parameters
    (core/fss/pipeline.py FssConfig). Report: changepoints used, sojourns per system
    and the laws after each iteration.
    """
    structure = tuple(structure)
    n_sys = len(structure)
    jumps = [window_jumps(np.asarray(w, float), np.asarray(f, float), config)
             for w, f in windows]
    inputs = [_initial_inputs(j, n_sys) for j in jumps]
    starts: list[list[int | None]] = [[None] * n_sys for _ in jumps]
    history = []
    laws: tuple[SwitchingSystem, ...] = structure
    for step in range(iterations + 1):
        sojourns = [{'complete': [], 'censored': [], 'moves': []} for _ in structure]
        for j, u, q0s in zip(jumps, inputs, starts):
            for s, system in enumerate(structure):
                c, cens, moves = _replay(j, u, s + 1, system.n_config, q0s[s])
                sojourns[s]['complete'] += c
                sojourns[s]['censored'] += cens
                sojourns[s]['moves'] += moves
        laws = _laws(structure, sojourns)
        history.append({'step': step, 'systems': [describe(s) for s in laws],
                        'sojourns': [len(x['complete']) for x in sojourns]})
        if step == iterations:
            break
        for k, j in enumerate(jumps):
            a = assign_changepoints(j.times, j.signs, j.reject_cost, j.n, laws, beam=beam)
            inputs[k] = a.inputs
            starts[k] = [int(q) for q in a.configs[0]]
    report = {'windows': len(jumps),
              'changepoints': int(sum(j.times.size for j in jumps)),
              'history': history}
    return laws, report


def describe(system: SwitchingSystem) -> dict:
    """Return a plain description of a system's laws (for reports and JSON)."""
    return {'name': system.name, 'residence': [list(r) for r in system.residence],
            'p_up': system.p_up}
