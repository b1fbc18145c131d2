"""Scoring candidate effects on sibling wheels at once: pooled evidence, one step.

Pooled evidence of a candidate: the sum of the wheels' likelihood ratios,
LR = sum_k n_k log(RSS_0,k / RSS_1,k), chi^2 with sum_k dof_k degrees of freedom when
the effect is absent from every wheel (independent noises, each wheel its own noise
variance); grid points are profiled on this pooled LR and the continuous parameter
refined between grid neighbours on it. The validation LR and the BIC gain are summed the
same way, the shared nonlinear parameters paid once (select.py's three tests).
"""

from __future__ import annotations

import copy

import numpy as np
from scipy import optimize, stats

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.baseline import Segments
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design, split_rows
from rwa_monitor.core.identify.joint_candidates import joint_candidates, JointCandidate
from rwa_monitor.core.identify.scoring import likelihood_ratio, NO_ADMISSIBLE_FIT
from rwa_monitor.core.identify.scoring import significant
from rwa_monitor.core.identify.ties import PRECEDENCE, SAME_STRUCTURE


class Wheels:
    """The wheels' data, designs and current fits during the joint loop."""

    def __init__(self, datas: list[IdentData], segments: list[Segments]) -> None:
        self.datas = datas
        self.segments = segments
        self.designs = [Design(d.friction, s.columns(d.speed), split_rows(len(d), d.stride))
                        for d, s in zip(datas, segments)]
        self.base = [dz.fit() for dz in self.designs]
        self.current = list(self.base)

    def with_effects(self, added: list[dict], skip: dict | None = None) -> 'Wheels':
        """Return the wheels with designs of the baseline and ``added`` (less ``skip``)."""
        other = copy.copy(self)
        other.designs, other.current = [], []
        for k, (data, seg) in enumerate(zip(self.datas, self.segments)):
            cols = [seg.columns(data.speed)] + [a['per'][k]['columns'] for a in added
                                                if a is not skip and a['per'][k] is not None]
            design = Design(data.friction, np.hstack(cols), split_rows(len(data), data.stride))
            other.designs.append(design)
            other.current.append(design.fit())
        return other

    def columns_of(self, added: list[dict], effect: dict, k: int) -> slice:
        """Return the columns of ``effect`` in wheel k's design (built by with_effects)."""
        start = len(self.segments[k].names())
        for a in added:
            if a['per'][k] is None:
                continue
            width = a['per'][k]['columns'].shape[1]
            if a is effect:
                return slice(start, start + width)
            start += width
        raise KeyError(effect['candidate'].name)

    def evaluate(self, kind: str, point: list[dict | None]) -> list[dict | None] | None:
        """Return each wheel's fit with the effect's columns at ``point`` (None: skipped)."""
        out: list[dict | None] = []
        for data, design, params in zip(self.datas, self.designs, point):
            if params is None:
                out.append(None)
                continue
            cols = fx.evaluate(kind, params, data)
            if not np.all(np.isfinite(cols)):
                return None
            out.append({'params': params, 'fit': design.fit(cols), 'columns': cols})
        weights = [s['fit'].coef[d.X.shape[1]:] for s, d in zip(out, self.designs)
                   if s is not None]
        if kind in fx.POSITIVE_WEIGHT and weights and not fx.physical_weights(
                kind, np.mean(weights, axis=0)):
            return None   # the wheels' mean weight has the unphysical sign
        return out

    def pooled_lr(self, per: list[dict | None]) -> float:
        """Return the summed training likelihood ratio of a candidate's fits."""
        return sum(likelihood_ratio(s['fit'].n_train_eff, cur.rss_train, s['fit'].rss_train)
                   for s, cur in zip(per, self.current) if s is not None)


def score_joint(wheels: Wheels, cand: JointCandidate) -> dict | None:
    """Return the candidate's best shared grid point with its pooled evidence, or None."""
    best, best_lr = None, -np.inf
    for point in cand.grid:
        per = wheels.evaluate(cand.kind, point)
        if per is not None and wheels.pooled_lr(per) > best_lr:
            best, best_lr = per, wheels.pooled_lr(per)
    if best is None:
        return None
    if cand.refine is not None:
        best = _refine(wheels, cand, best)
    lr = lr_held = gain = 0.0
    dof, n_total, own = 0, 0, {}
    for data, s, cur in zip(wheels.datas, best, wheels.current):
        if s is None:
            continue
        fit = s['fit']
        k = max(int(fit.rank - cur.rank), 0)
        lr_k = likelihood_ratio(fit.n_train_eff, cur.rss_train, fit.rss_train)
        held_k = likelihood_ratio(fit.n_validation_eff, cur.rss_validation, fit.rss_validation)
        lr, lr_held, dof, n_total = lr + lr_k, lr_held + held_k, dof + k, n_total + fit.n_train_eff
        gain += lr_k - k * float(np.log(fit.n_train_eff))
        own[data.wheel] = {'lr': lr_k, 'dof': k, 'lr_validation': held_k,
                           'rmse_validation': fit.rmse_validation}
    if dof <= 0:
        return None
    evidence = {'lr': lr, 'dof': dof, 'p_value': float(stats.chi2.sf(lr, dof)),
                'lr_validation': lr_held, 'parameters': dof + cand.free,
                'bic_gain': gain - cand.free * float(np.log(n_total)),
                'rmse_validation': float(np.sqrt(np.mean(
                    [v['rmse_validation'] ** 2 for v in own.values()]))),
                'wheels': own}
    return {'candidate': cand, 'per': best, 'evidence': evidence}


def _refine(wheels: Wheels, cand: JointCandidate, best: list[dict | None]) -> list:
    """Refine the shared continuous parameter between grid neighbours (pooled LR)."""
    key, ratio = cand.refine
    centre = float(next(s for s in best if s is not None)['params'][key])

    def at(log_value: float):
        point = [None if s is None else {**s['params'], key: float(np.exp(log_value))}
                 for s in best]
        return wheels.evaluate(cand.kind, point)

    def loss(log_value: float) -> float:
        per = at(log_value)
        return np.inf if per is None else -wheels.pooled_lr(per)
    with np.errstate(invalid='ignore'):   # inf - inf at inadmissible points: golden step
        res = optimize.minimize_scalar(loss, bounds=(np.log(centre / ratio),
                                                     np.log(centre * ratio)),
                                       method='bounded', options={'xatol': 1e-3})
    per = at(res.x)
    return per if per is not None and wheels.pooled_lr(per) > wheels.pooled_lr(best) \
        else best


def _weighted_rows(wheels: Wheels, scored: dict, what: str) -> np.ndarray:
    """Return a candidate's training-row contributions or squared residuals, all wheels.

    Each wheel's rows are divided by its noise floor (squared for residuals), so that
    every wheel weighs by its information, every stride-th row.
    """
    parts = []
    for data, design, s in zip(wheels.datas, wheels.designs, scored['per']):
        if s is None:
            continue
        p = design.X.shape[1]
        contribution = s['columns'] @ s['fit'].coef[p:]
        if what == 'contribution':
            rows = contribution[design.train] / data.noise_floor
        else:
            resid = design.y - design.X @ s['fit'].coef[:p] - contribution
            rows = resid[design.train] ** 2 / data.noise_floor ** 2
        parts.append(rows[::max(1, data.stride)])
    return np.concatenate(parts) if parts else np.zeros(0)


def _same(wheels: Wheels, a: dict, b: dict) -> bool:
    """Return whether two candidates are on the same wheels (comparable row by row)."""
    return [s is None for s in a['per']] == [s is None for s in b['per']]


def preferred_joint(wheels: Wheels, winners: list[dict], level: float, record: dict) -> dict:
    """Return the significant effect to add (select._preferred on the pooled rows)."""
    best = max(winners, key=lambda s: s['evidence']['lr_validation'])
    critical = float(stats.norm.isf(level / 2))
    ties = [best]
    ca = _weighted_rows(wheels, best, 'contribution')
    ra = _weighted_rows(wheels, best, 'residual')
    for s in winners:
        if s is best or not _same(wheels, best, s):
            continue
        cb = _weighted_rows(wheels, s, 'contribution')
        norm = float(np.sqrt(np.dot(ca, ca) * np.dot(cb, cb)))
        if norm <= 0 or abs(float(np.dot(ca, cb))) / norm < SAME_STRUCTURE:
            continue
        d = _weighted_rows(wheels, s, 'residual') - ra
        sd = float(np.std(d))
        z = float(np.sqrt(len(d)) * np.mean(d) / sd) if sd > 0 else 0.0
        if abs(z) < critical:
            ties.append(s)
    rank = {k: i for i, k in enumerate(PRECEDENCE)}
    record['vuong_critical'] = critical
    record['indistinguishable'] = [s['candidate'].name for s in ties]
    return min(ties, key=lambda s: rank.get(s['candidate'].kind, len(rank)))


def joint_step(wheels: Wheels, residuals: list[np.ndarray], tried: set[str], alpha: float,
               alpha_held: float, present: frozenset[str] = frozenset()
               ) -> tuple[dict | None, dict]:
    """Score every untried joint candidate; return the named effect to add (or None).

    select.selection_step on the pooled evidence. The catch-all is scored and recorded;
    when it alone is significant it is left in ``record['catch_all']`` (joint.py decides).
    """
    cands, fallback = joint_candidates(wheels.datas, residuals)
    cands = [c for c in cands if fx.offered(c.name, tried, present)]
    m = sum(c.tests for c in cands if c.skipped is None) + fallback.tests
    level = alpha / m
    record: dict = {'level': level, 'tests': m, 'candidates': [], 'pooled': True}
    winners = []
    for cand in cands:
        if cand.skipped is not None:
            record['candidates'].append({'name': cand.name, 'skipped': cand.skipped})
            continue
        s = score_joint(wheels, cand)
        if s is None:
            record['candidates'].append({'name': cand.name,
                                         'skipped': NO_ADMISSIBLE_FIT})
            continue
        s['significant'] = significant(s['evidence'], level, alpha_held)
        record['candidates'].append({'name': cand.name, 'params': shared_params(s),
                                     'significant': s['significant'], **s['evidence']})
        if s['significant']:
            winners.append(s)
    generic = None
    if fallback.name not in tried:
        generic = score_joint(wheels, fallback)
        if generic is not None:
            generic['significant'] = significant(generic['evidence'], level, alpha_held)
            record['candidates'].append({'name': fallback.name,
                                         'significant': generic['significant'],
                                         **generic['evidence']})
            if not generic['significant']:
                generic = None
    if winners:
        chosen = preferred_joint(wheels, winners, level, record)
    else:
        chosen, record['catch_all'] = None, generic
    record['added'] = None if chosen is None else chosen['candidate'].name
    return chosen, record


def shared_params(scored: dict) -> dict:
    """Return the parameters of the first wheel that has the effect (shared ones)."""
    return next(s['params'] for s in scored['per'] if s is not None)
