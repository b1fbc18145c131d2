"""Stage 3: maximum-likelihood assignment of changepoints, eq. (18)-(23), Algorithm 1.

Which FSS caused each changepoint, then the friction levels of each FSS.

The state after changepoint i is, per system s, its configuration q_s and the step of
its last jump (equivalently tau_s, eq. 19); the input is the system that jumped or 0 to
reject the changepoint (eq. 22). Scores are log-likelihoods, written per sojourn: the
sum over k of log(1 - P^t) followed by log P^t at the jump (eq. 20-21) telescopes into
log P(residence = d), so a jump of s after d steps adds log P_s(D = d) + log P^q, and at
the end of the window each system adds log P(D > d) (its sojourn is still running). A
system's first sojourn began before the window: tau_0 is chosen to maximise the score,
as section IV-C1 says (see :meth:`SwitchingSystem.log_first`).

Departures (docs/fss.md): eq. (23) adds c_i^rjct to a score that is maximised, which
would favour rejecting large jumps; c_i is an increase of the squared error, so the
reject input scores -c_i / (2 sigma^2), the log-likelihood lost by merging the two
intervals. Impossible events score LOG_FLOOR instead of -inf so that a window which
breaks the model still gets its most likely explanation.

Search: forward dynamic programming over stages. States with the same (q, last jumps)
are merged (the exact DP), and at most ``beam`` states are kept per stage (best
scores). When no stage holds more than ``beam`` distinct states the result is the exact
optimum (``exact`` is True). Cost: O(M * beam * (S + 1)) time and O(M * beam) memory
for M changepoints and S systems, whatever the window.
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
from typing import Sequence

import numpy as np

from rwa_monitor.core.fss.model import LOG_FLOOR, SwitchingSystem
from rwa_monitor.core.params import check_int


@dataclass(frozen=True)
class Assignment:
    """Stage-3 output: input per changepoint (0 reject, s >= 1 system s), states, score."""

    inputs: np.ndarray        # (M,)
    configs: np.ndarray       # (M + 1, S): configuration of each system on each interval
    score: float
    iterations: int           # states expanded, summed over stages
    exact: bool               # no stage was cut by the beam


class _Tables:
    """Per-system look-up arrays for the DP (the same laws as SwitchingSystem)."""

    def __init__(self, system: SwitchingSystem) -> None:
        res = np.asarray(system.residence, dtype=float)
        self.lo, self.hi = res[:, 0], res[:, 1]
        self.log_r = -np.log(self.hi - self.lo + 1.0)
        self.r = self.hi - self.lo + 1.0
        self.top = system.n_config - 1
        qs = np.arange(system.n_config)
        # log P^q of a move up / down, -inf where it leaves the range.
        self.move_up = np.where(qs < self.top, system.log_pq(qs, np.ones_like(qs)), -np.inf)
        self.move_down = np.where(qs > 0, system.log_pq(qs, -np.ones_like(qs)), -np.inf)

    def gain(self, q, last, t, d, sign) -> np.ndarray:
        """Return the score of a jump of this system (-inf if q leaves its range)."""
        first = np.where(t <= self.hi, -np.log(np.maximum(np.minimum(t, self.r), 1.0)),
                         LOG_FLOOR)
        move = self.move_up if sign > 0 else self.move_down
        later = np.where((d >= self.lo[q]) & (d <= self.hi[q]), self.log_r[q], LOG_FLOOR)
        return np.where(last == 0, first[q], later) + move[q]


def _initial(systems: Sequence[SwitchingSystem]) -> np.ndarray:
    return np.array(list(itertools.product(*[range(s.n_config) for s in systems])),
                    dtype=np.int64).reshape(-1, len(systems))


def _end_scores(systems, q, last, times_ext, n) -> np.ndarray:
    total = np.zeros(q.shape[0])
    for s, system in enumerate(systems):
        d = np.where(last[:, s] == 0, n, n - times_ext[last[:, s]])
        total += system.log_survival(q[:, s], d)
    return total


def assign_changepoints(times: np.ndarray, signs: np.ndarray, reject_cost: np.ndarray,
                        n: int, systems: Sequence[SwitchingSystem], *,
                        beam: int = 256, dominance: bool = True) -> Assignment:
    """Solve eq. (18) with the reject input, by DP with merged states and a beam.

    ``times``: changepoint steps (sorted, in 1 .. n - 1); ``signs``: sign of the dry
    friction change at each (Delta f_i, +-1); ``reject_cost``: log-likelihood lost by
    rejecting each (>= 0, c_i / (2 sigma^2)); ``n``: window length in steps.
    """
    beam = check_int('beam', beam, 1)
    times = np.asarray(times, dtype=np.int64)
    signs = np.asarray(signs, dtype=np.int64)
    reject_cost = np.asarray(reject_cost, dtype=float)
    m = times.size
    if signs.size != m or reject_cost.size != m:
        raise ValueError('times, signs and reject_cost must have the same length')
    if not np.all(np.isfinite(reject_cost) & (reject_cost >= 0.0)):
        # A state's score must stay finite: with an infinite cost every state of a
        # stage was dropped and the survivors' index was empty (IndexError).
        raise ValueError('reject_cost must be finite and >= 0')
    n_sys = len(systems)
    times_ext = np.concatenate(([-1], times))
    radix = np.array([s.n_config * (m + 1) for s in systems], dtype=np.int64)
    tables = [_Tables(system) for system in systems]
    q = _initial(systems)
    last = np.zeros_like(q)
    score = np.zeros(q.shape[0])
    parents, inputs_hist = [], []
    iterations, exact = 0, True
    for i in range(m):
        n_st = q.shape[0]
        iterations += n_st
        nq = np.concatenate((q,) * (n_sys + 1))
        nl = np.concatenate((last,) * (n_sys + 1))
        sc = np.concatenate((score,) * (n_sys + 1))
        sc[:n_st] -= reject_cost[i]
        for s, tab in enumerate(tables):
            rows = slice((s + 1) * n_st, (s + 2) * n_st)
            qs, ls = q[:, s], last[:, s]
            gain = tab.gain(qs, ls, times[i], times[i] - times_ext[ls], signs[i])
            nq[rows, s] = qs + signs[i]
            nl[rows, s] = i + 1
            sc[rows] += gain
        ok = np.isfinite(sc)
        idx = np.flatnonzero(ok)
        key = np.zeros(idx.size, dtype=np.int64)
        for s in range(n_sys):
            key = key * radix[s] + nq[idx, s] * (m + 1) + nl[idx, s]
        order = np.lexsort((-sc[idx], key))
        ks = key[order]
        keep = idx[order[np.concatenate(([True], ks[1:] != ks[:-1]))]]
        if dominance:
            # Exact pruning: a state with the same configurations and a score higher by
            # more than the bound can mimic every future of this one and lose at most
            # -LOG_FLOOR per system (each system's next sojourn-closing term).
            qkey = np.zeros(keep.size, dtype=np.int64)
            for s, system in enumerate(systems):
                qkey = qkey * system.n_config + nq[keep, s]
            best = np.full(int(np.prod([s.n_config for s in systems])), -np.inf)
            np.maximum.at(best, qkey, sc[keep])
            keep = keep[sc[keep] >= best[qkey] + n_sys * LOG_FLOOR]
        if keep.size > beam:
            exact = False
            keep = keep[np.argpartition(-sc[keep], beam - 1)[:beam]]
        q, last, score = nq[keep], nl[keep], sc[keep]
        parents.append(keep % n_st)
        inputs_hist.append(keep // n_st)
    iterations += q.shape[0]
    final = score + _end_scores(systems, q, last, times_ext, n)
    best = int(np.argmax(final))
    # Backtrack the inputs, then replay them from the initial configuration.
    u = np.zeros(m, dtype=np.int64)
    j = best
    for i in range(m - 1, -1, -1):
        u[i] = inputs_hist[i][j]
        j = parents[i][j]
    configs = np.empty((m + 1, n_sys), dtype=np.int64)
    configs[0] = _initial(systems)[j]
    for i in range(m):
        configs[i + 1] = configs[i]
        if u[i] > 0:
            configs[i + 1, u[i] - 1] += signs[i]
    return Assignment(inputs=u, configs=configs, score=float(final[best]),
                      iterations=iterations, exact=exact)


def score_assignment(times, signs, reject_cost, n, systems, q0, inputs) -> float:
    """Return the log-likelihood of one assignment, sample by sample (for checks).

    -inf when an input moves a configuration out of its range.
    """
    q = list(q0)
    last = [None] * len(systems)
    total = 0.0
    for t, d, c, u in zip(times, signs, reject_cost, inputs):
        if u == 0:
            total -= c
            continue
        s = u - 1
        system = systems[s]
        if not 0 <= q[s] + d < system.n_config:
            return float('-inf')
        if last[s] is None:
            total += float(system.log_first(np.array([q[s]]), np.array([t]))[0])
        else:
            total += float(system.log_pmf(np.array([q[s]]), np.array([t - last[s]]))[0])
        total += float(system.log_pq(np.array([q[s]]), np.array([d]))[0])
        q[s] += d
        last[s] = t
    for s, system in enumerate(systems):
        d = n if last[s] is None else n - last[s]
        total += float(system.log_survival(np.array([q[s]]), np.array([d]))[0])
    return total


def assign_bruteforce(times, signs, reject_cost, n, systems) -> tuple[float, np.ndarray]:
    """Return (best score, inputs) by enumerating every q0 and input sequence (small M)."""
    best, best_u = float('-inf'), None
    for q0 in _initial(systems):
        for u in itertools.product(range(len(systems) + 1), repeat=len(times)):
            sc = score_assignment(times, signs, reject_cost, n, systems, q0, u)
            if sc > best:
                best, best_u = sc, np.array(u)
    return best, best_u


def friction_levels(dry: np.ndarray, inputs: np.ndarray, configs: np.ndarray,
                    n_systems: int) -> tuple[float, list[list[float]], list[list[int]]]:
    """Return (base dry, levels per FSS, configurations per FSS): Algorithm 1.

    ``dry``: F-hat of the intervals between the *accepted* changepoints; ``inputs`` and
    ``configs``: the accepted changepoints' systems (1-based) and the configurations on
    each interval (len(dry) rows). Each FSS starts at 0, adds the jump of every
    changepoint assigned to it, and is shifted so that its minimum is 0; the base dry
    friction takes the shifts: base = F-hat_1 + sum_s min F_s (line 18, whose printed
    form is garbled).
    """
    levels = [[0.0] for _ in range(n_systems)]
    qs = [[int(configs[0, s])] for s in range(n_systems)]
    base = float(dry[0])
    for i in range(1, len(dry)):
        s = int(inputs[i - 1]) - 1
        levels[s].append(levels[s][-1] + float(dry[i] - dry[i - 1]))
        qs[s].append(int(configs[i, s]))
    for s in range(n_systems):
        low = min(levels[s])
        levels[s] = [v - low for v in levels[s]]
        base += low
    return base, levels, qs


def base_dry_weights(dry: np.ndarray, inputs: np.ndarray, n_systems: int) -> np.ndarray:
    """Return c with c @ dry equal to Algorithm 1's base dry friction (:func:`friction_levels`).

    Line 18 takes F-hat_1 plus, per FSS, its running sum of jumps at its minimum: with the
    minimising intervals held fixed that is a linear combination of the interval
    coefficients, so its least-squares standard error follows from theirs
    (``core/fss/segments.py`` ``combination_se``).
    """
    dry = np.asarray(dry, dtype=float)
    inputs = np.asarray(inputs, dtype=int)
    weights = np.zeros(dry.size)
    weights[0] = 1.0
    for s in range(1, n_systems + 1):
        mine = np.flatnonzero(inputs == s) + 1       # intervals entered by its jumps
        running = np.concatenate(([0.0], np.cumsum(dry[mine] - dry[mine - 1])))
        taken = mine[:int(np.argmin(running))]
        np.add.at(weights, taken, 1.0)
        np.add.at(weights, taken - 1, -1.0)
    return weights
