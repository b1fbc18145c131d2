"""Joint selection of friction effects on sibling wheels declared identical.

Wheels of one design on one bus share their physics; what differs between them is wear,
temperature and noise. So the forward selection of select.py is run on the wheels
together, the way one would argue from several specimens of one part:

1. A candidate effect is one hypothesis for every wheel. Its nonlinear parameters are
   shared (one Stribeck speed, band width, exponent or frequency for the design; the
   grids of speeds span quantiles of the pooled abs(w)); its weights are each wheel's
   own. Its pooled evidence is the sum of the wheels' likelihood ratios,
   LR = sum_k n_k log(RSS_0,k / RSS_1,k), chi^2 with sum_k dof_k degrees of freedom when
   the effect is absent from every wheel (independent noises, each wheel its own noise
   variance); grid points are profiled on this pooled LR, and the continuous parameter
   refined between grid neighbours on it.
2. The effect enters when the pooled evidence passes select.py's three tests: p-value
   below alpha / m (Bonferroni over the step's grid points; a periodic frequency searched
   on every wheel's residual counts every wheel's search), the summed held-out LR above
   the chi^2(sum dof) critical value at ``alpha_held``, and the pooled BIC gain
   sum_k (LR_k - dof_k ln n_k) - q ln(sum_k n_k) > 0 (q shared nonlinear parameters,
   counted once). Among significant effects the largest summed held-out LR wins, with
   select.py's precedence between alternative explanations of one structure (cosine
   and Vuong's test on the wheels' pooled, variance-weighted rows). The fallback is
   scored the same way (each wheel its own knots) and added only when no named effect
   is significant (physics first, select.py).
3. The loop stops when every wheel's residual passes the structure and whiteness tests,
   when nothing pooled is significant, or after ``max_effects``.
4. Each wheel is then refitted with the common set: the continuous parameter of each
   effect (Stribeck speed, band width) is re-profiled on the wheel's own data (one
   coordinate pass, within one grid ratio of the shared value); shapes, exponents and
   frequencies stay shared.
5. consistency.py tests whether a wheel's own data contradict its siblings.

Jumps are segmented per wheel (baseline.py) before, and searched again per wheel with
the common effects in the background, as in select.identify.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from rwa_monitor.core.identify import consistency
from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.baseline import check_identifiable, find_jumps, Segments
from rwa_monitor.core.identify.consistency import sibling_name as canonical_name, WHEEL
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design, Fit, held_out_mask
from rwa_monitor.core.identify.residuals import diagnose
from rwa_monitor.core.identify.select import AddedEffect, free_parameters
from rwa_monitor.core.identify.select import likelihood_ratio, PRECEDENCE, SAME_STRUCTURE
from rwa_monitor.core.identify.select import Selection, selection_step, significant
from rwa_monitor.core.params import check_int, check_real

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


@dataclass
class JointSelection:
    """The outcome of the joint selection: one Selection per wheel and the comparison."""

    selections: dict[str, Selection]
    effects: list[str] = field(default_factory=list)
    steps: list[dict] = field(default_factory=list)
    stop_reason: str = ''
    consistency: dict = field(default_factory=dict)
    alternatives: list[dict] = field(default_factory=list)


def wheel_name(name: str, wheel: str) -> str:
    """Return the wheel's own name of a canonical effect name."""
    return name.replace(WHEEL, wheel)


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
            grid = [[c.grid[g] if good else None for c, good in zip(cands, ok)]
                    for g in range(len(first.grid))]
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


class _Wheels:
    """The wheels' data, designs and current fits during the joint loop."""

    def __init__(self, datas: list[IdentData], segments: list[Segments]) -> None:
        self.datas = datas
        self.segments = segments
        self.designs = [Design(d.friction, s.columns(d.speed), held_out_mask(len(d)))
                        for d, s in zip(datas, segments)]
        self.base = [dz.fit() for dz in self.designs]
        self.current = list(self.base)

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
        return out

    def pooled_lr(self, per: list[dict | None]) -> float:
        """Return the summed training likelihood ratio of a candidate's fits."""
        return sum(likelihood_ratio(s['fit'].n_train, cur.rss_train, s['fit'].rss_train)
                   for s, cur in zip(per, self.current) if s is not None)


def _score(wheels: _Wheels, cand: JointCandidate) -> dict | None:
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
        lr_k = likelihood_ratio(fit.n_train, cur.rss_train, fit.rss_train)
        held_k = likelihood_ratio(fit.n_held_out, cur.rss_held_out, fit.rss_held_out)
        lr, lr_held, dof, n_total = lr + lr_k, lr_held + held_k, dof + k, n_total + fit.n_train
        gain += lr_k - k * float(np.log(fit.n_train))
        own[data.wheel] = {'lr': lr_k, 'dof': k, 'lr_held_out': held_k,
                           'rmse_held_out': fit.rmse_held_out}
    if dof <= 0:
        return None
    evidence = {'lr': lr, 'dof': dof, 'p_value': float(stats.chi2.sf(lr, dof)),
                'lr_held_out': lr_held, 'parameters': dof + cand.free,
                'bic_gain': gain - cand.free * float(np.log(n_total)),
                'rmse_held_out': float(np.sqrt(np.mean(
                    [v['rmse_held_out'] ** 2 for v in own.values()]))),
                'wheels': own}
    return {'candidate': cand, 'per': best, 'evidence': evidence}


def _refine(wheels: _Wheels, cand: JointCandidate, best: list[dict | None]) -> list:
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
    res = optimize.minimize_scalar(loss, bounds=(np.log(centre / ratio),
                                                 np.log(centre * ratio)),
                                   method='bounded', options={'xatol': 1e-3})
    per = at(res.x)
    return per if per is not None and wheels.pooled_lr(per) > wheels.pooled_lr(best) \
        else best


def _weighted_rows(wheels: _Wheels, scored: dict, what: str) -> np.ndarray:
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


def _same(wheels: _Wheels, a: dict, b: dict) -> bool:
    """Return whether two candidates are on the same wheels (comparable row by row)."""
    return [s is None for s in a['per']] == [s is None for s in b['per']]


def _preferred(wheels: _Wheels, winners: list[dict], level: float, record: dict) -> dict:
    """Return the significant effect to add (select._preferred on the pooled rows)."""
    best = max(winners, key=lambda s: s['evidence']['lr_held_out'])
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


def _step(wheels: _Wheels, residuals: list[np.ndarray], tried: set[str], alpha: float,
          alpha_held: float) -> tuple[dict | None, dict]:
    cands, fallback = joint_candidates(wheels.datas, residuals)
    cands = [c for c in cands if c.name not in tried]
    m = sum(c.tests for c in cands if c.skipped is None) + fallback.tests
    level = alpha / m
    record: dict = {'level': level, 'tests': m, 'candidates': [], 'pooled': True}
    winners = []
    for cand in cands:
        if cand.skipped is not None:
            record['candidates'].append({'name': cand.name, 'skipped': cand.skipped})
            continue
        s = _score(wheels, cand)
        if s is None:
            record['candidates'].append({'name': cand.name,
                                         'skipped': 'adds nothing the model lacks'})
            continue
        s['significant'] = significant(s['evidence'], level, alpha_held)
        record['candidates'].append({'name': cand.name, 'params': _shared(s),
                                     'significant': s['significant'], **s['evidence']})
        if s['significant']:
            winners.append(s)
    generic = None
    if fallback.name not in tried:
        generic = _score(wheels, fallback)
        if generic is not None:
            generic['significant'] = significant(generic['evidence'], level, alpha_held)
            record['candidates'].append({'name': fallback.name,
                                         'significant': generic['significant'],
                                         **generic['evidence']})
            if not generic['significant']:
                generic = None
    chosen = _preferred(wheels, winners, level, record) if winners else generic
    record['added'] = None if chosen is None else chosen['candidate'].name
    return chosen, record


def _shared(scored: dict) -> dict:
    """Return the parameters of the first wheel that has the effect (shared ones)."""
    return next(s['params'] for s in scored['per'] if s is not None)


def identify_joint(datas: list[IdentData], alpha: float = 1e-3, alpha_held: float = 1e-2,
                   max_effects: int = 6, jumps: bool = True, jump_window: int | None = None
                   ) -> JointSelection:
    """Identify sibling wheels declared identical together (module docstring).

    Returns one Selection per wheel (its own fit of the common effects, ready for the
    reports) and the consistency of the wheels (consistency.contradictions).
    """
    alpha = check_real('alpha', alpha, 0.0, 0.5, low_open=True)
    alpha_held = check_real('alpha_held', alpha_held, 0.0, 0.5, low_open=True)
    max_effects = check_int('max_effects', max_effects, 0, 20)
    if len({d.wheel for d in datas}) != len(datas) or not datas:
        raise ValueError('identify_joint needs one IdentData per wheel, distinct wheel ids')
    for data in datas:
        check_identifiable(data.speed)
    if not jumps:
        return _named_first(datas, [Segments() for _ in datas], alpha, alpha_held,
                            max_effects)
    segments = [find_jumps(d, jump_window, alpha) for d in datas]
    joint = _named_first(datas, segments, alpha, alpha_held, max_effects)
    if not joint.effects or all(len(s.starts) == 1 for s in segments):
        return joint   # effects in the background only weaken the evidence for a jump
    again = []
    for data, seg in zip(datas, segments):
        sel = joint.selections[data.wheel]
        if len(seg.starts) == 1 or not sel.effects:
            again.append(seg)
            continue
        extra = np.hstack([sel.design.X[:, e.columns] for e in sel.effects])
        again.append(find_jumps(data, jump_window, alpha, extra=extra))
    if all(a.starts == s.starts for a, s in zip(again, segments)):
        return joint
    joint2 = _named_first(datas, again, alpha, alpha_held, max_effects)
    for data, seg, new in zip(datas, segments, again):
        if seg.starts != new.starts:
            joint2.selections[data.wheel].first_pass_jumps = [int(k) for k in seg.starts[1:]]
    return joint2


def _named_first(datas: list[IdentData], segments: list[Segments], alpha: float,
                 alpha_held: float, max_effects: int) -> JointSelection:
    """Run the joint selection; when it ends on the catch-all, look for named physics.

    As select.py ``_named_first`` for one wheel: the selection is run again with each
    named effect of the set left out in turn, and the run with the smallest held-out
    RSS (summed over the wheels, each relative to its noise floor squared) among those
    without the catch-all is kept when its named effects reach the floor on every
    wheel: each wheel's residual passes, or on each wheel the catch-all's held-out gain
    over it is below the chi^2 critical value at ``alpha_held`` for its columns there.
    """
    joint = _joint(datas, segments, alpha, alpha_held, max_effects)
    if fx.FALLBACK not in joint.effects:
        return joint
    runs = [joint] + [_joint(datas, segments, alpha, alpha_held, max_effects,
                             banned=frozenset({name}))
                      for name in joint.effects if name != fx.FALLBACK]

    def score(run: JointSelection) -> float:
        return sum(sel.final_fit.rss_held_out / sel.data.noise_floor ** 2
                   for sel in run.selections.values())
    named = [r for r in runs[1:] if fx.FALLBACK not in r.effects
             and _reaches_floor(r, joint, alpha_held)]
    best = min(named, key=score) if named else joint
    best.alternatives = [{'left_out': r.steps[0].get('banned', []) if r.steps else [],
                          'effects': list(r.effects), 'held_out_over_floor2': score(r)}
                         for r in runs]
    return best


def _reaches_floor(run: JointSelection, catch: JointSelection, alpha_held: float) -> bool:
    """Return whether a named-only run reaches the floor as well as the catch-all did."""
    if all(sel.diagnostics_after['passes'] for sel in run.selections.values()):
        return True
    for wheel, sel in run.selections.items():
        other = catch.selections[wheel]
        width = sum(e.columns.stop - e.columns.start for e in other.effects
                    if e.name == fx.FALLBACK)
        fit = other.final_fit
        gain = likelihood_ratio(fit.n_held_out, sel.final_fit.rss_held_out, fit.rss_held_out)
        if width and gain >= float(stats.chi2.isf(alpha_held, width)):
            return False
    return True


def _joint(datas: list[IdentData], segments: list[Segments], alpha: float,
           alpha_held: float, max_effects: int, banned: frozenset[str] = frozenset()
           ) -> JointSelection:
    """Run the joint forward selection, refit every wheel, test the wheels' agreement.

    ``banned``: named effects not tried (canonical names; :func:`_named_first`).
    """
    wheels = _Wheels(datas, segments)
    residuals = [dz.residual(c) for dz, c in zip(wheels.designs, wheels.current)]
    before = [diagnose(d, r, alpha) for d, r in zip(datas, residuals)]
    diags = list(before)
    added: list[dict] = []
    steps: list[dict] = []
    tried: set[str] = set(banned)
    while True:
        if all(dg['passes'] for dg in diags):
            stop = "every wheel's residual passes the structure and whiteness tests"
            break
        if len(added) >= max_effects:
            stop = f'max_effects = {max_effects} reached'
            break
        chosen, record = _step(wheels, residuals, tried, alpha, alpha_held)
        record['banned'] = sorted(banned)
        steps.append(record)
        if chosen is None:
            stop = 'no candidate effect is significant on the pooled evidence'
            break
        for k, s in enumerate(chosen['per']):
            if s is None:
                continue
            wheels.designs[k].add(s['columns'])
            wheels.current[k] = wheels.designs[k].fit()
            residuals[k] = wheels.designs[k].residual(wheels.current[k])
            diags[k] = diagnose(datas[k], residuals[k], alpha)
        added.append(chosen)
        tried.add(chosen['candidate'].name)
    joint = JointSelection(selections={}, effects=[a['candidate'].name for a in added],
                           steps=steps, stop_reason=stop)
    shared = _shared_weights(wheels, added)
    for k, data in enumerate(datas):
        joint.selections[data.wheel] = _refit_wheel(wheels, k, added, before[k], alpha,
                                                    steps, stop)
    joint.consistency = _consistency(joint, wheels, added, shared, alpha, alpha_held)
    return joint


def _shared_weights(wheels: _Wheels, added: list[dict]) -> dict[str, list]:
    """Return per effect each wheel's weights and covariance with the shared parameters.

    Covariance sigma^2 (X'X)^-1 on the training rows, sigma^2 = RSS / (n - p), scaled by
    the stride of the friction's correlated noise (a derivative over 2h + 1 samples).
    """
    out: dict[str, list] = {}
    for k, (data, design, fit) in enumerate(zip(wheels.datas, wheels.designs,
                                                wheels.current)):
        xt = design.X[design.train]
        sigma2 = fit.rss_train / max(fit.n_train - fit.rank, 1) * max(1, data.stride)
        cov = sigma2 * np.linalg.pinv(xt.T @ xt)
        start = len(wheels.segments[k].names())
        for a in added:
            s = a['per'][k]
            width = 0 if s is None else s['columns'].shape[1]
            item = None
            if s is not None:
                cols = slice(start, start + width)
                item = (fit.coef[cols], cov[cols, cols])
                start += width
            out.setdefault(a['candidate'].name, []).append(item)
    return out


def _refit_wheel(wheels: _Wheels, k: int, added: list[dict], before: dict, alpha: float,
                 steps: list[dict], stop: str) -> Selection:
    """Return wheel k's Selection: the common effects, continuous parameters its own."""
    data, segments = wheels.datas[k], wheels.segments[k]
    held = wheels.designs[k].held_out
    mine = [(a['candidate'], dict(a['per'][k]['params'])) for a in added
            if a['per'][k] is not None]
    cols = [fx.evaluate(c.kind, p, data) for c, p in mine]
    base = segments.columns(data.speed)
    for i, (cand, params) in enumerate(mine):
        if cand.refine is None:
            continue
        key, ratio = cand.refine
        design = Design(data.friction, np.hstack([base] + cols[:i] + cols[i + 1:]), held)

        def rss(log_value: float) -> float:
            c = fx.evaluate(cand.kind, {**params, key: float(np.exp(log_value))}, data)
            return design.fit(c).rss_train if np.all(np.isfinite(c)) else np.inf
        centre = float(params[key])
        res = optimize.minimize_scalar(rss, bounds=(np.log(centre / ratio),
                                                    np.log(centre * ratio)),
                                       method='bounded', options={'xatol': 1e-3})
        if rss(res.x) < rss(np.log(centre)):
            params[key] = float(np.exp(res.x))
            cols[i] = fx.evaluate(cand.kind, params, data)
    design = Design(data.friction, base, held)
    sel = Selection(data=data, segments=segments, design=design, baseline_fit=design.fit(),
                    final_fit=design.fit(), baseline_names=segments.names(),
                    steps=steps, stop_reason=stop, diagnostics_before=before)
    for (cand, params), c in zip(mine, cols):
        start = design.X.shape[1]
        design.add(c)
        pooled = next(a['evidence'] for a in added if a['candidate'] is cand)
        evidence = {key: v for key, v in pooled.items() if key != 'wheels'}
        evidence['pooled'] = True
        evidence['rmse_in_sample'] = design.fit().rmse_train
        evidence['rmse_held_out'] = design.fit().rmse_held_out
        sel.effects.append(AddedEffect(wheel_name(cand.name, data.wheel), cand.kind, params,
                                       slice(start, design.X.shape[1]), evidence))
    sel.final_fit = design.fit()
    sel.diagnostics_after = diagnose(data, design.residual(sel.final_fit), alpha)
    for eff in sel.effects:
        eff.evidence['own'] = drop_one(design, sel.final_fit, eff.columns)
        eff.evidence['residual_failing_after'] = list(sel.diagnostics_after['failing'])
    return sel


def drop_one(design: Design, full: Fit, columns: slice) -> dict:
    """Return one wheel's own evidence for an effect: the LR of leaving its columns out."""
    keep = np.ones(design.X.shape[1], dtype=bool)
    keep[columns] = False
    without = Design(design.y, design.X[:, keep], design.held_out).fit()
    dof = max(int(full.rank - without.rank), 0)
    lr = likelihood_ratio(full.n_train, without.rss_train, full.rss_train)
    return {'lr': lr, 'dof': dof,
            'p_value': float(stats.chi2.sf(lr, dof)) if dof else 1.0,
            'lr_held_out': likelihood_ratio(full.n_held_out, without.rss_held_out,
                                            full.rss_held_out)}


def _consistency(joint: JointSelection, wheels: _Wheels, added: list[dict],
                 shared: dict[str, list], alpha: float, alpha_held: float) -> dict:
    """Run both contradiction tests of consistency.py on every wheel."""
    ids = [d.wheel for d in wheels.datas]
    count = len(ids)
    extra: dict[str, dict] = {}
    for data in wheels.datas:
        sel = joint.selections[data.wheel]
        if sel.diagnostics_after['passes']:
            continue   # alone, the wheel would stop here too (select.py)
        tried = {e.name for e in sel.effects}
        resid = sel.design.residual(sel.final_fit)
        chosen, record = selection_step(sel.design, sel.final_fit, data, resid, tried,
                                        alpha / count, alpha_held)
        if chosen is not None:
            extra[data.wheel] = {'effect': canonical_name(chosen['candidate'].name,
                                                          data.wheel),
                                 **{k: v for k, v in chosen['evidence'].items()},
                                 'params': chosen['params']}
    missing: dict[str, dict] = {}
    for a in added:
        name = a['candidate'].name
        own = [next((e.evidence['own'] for e in joint.selections[w].effects
                     if canonical_name(e.name, w) == name), None) for w in ids]
        level = alpha / (count * len(added))
        found = consistency.weaker_than_siblings(shared[name], own, level, alpha)
        lacking = [k for k, r in enumerate(found) if r is not None and r['contradicts']]
        showing = [k for k, o in enumerate(own) if o is not None and o['p_value'] <= alpha]
        if len(lacking) > len(showing):
            for k in showing:   # the effect is the minority's: flag the wheels that have it
                extra.setdefault(ids[k], {'effect': name, 'common': True, **own[k]})
            continue
        for k in lacking:
            missing.setdefault(ids[k], {})[name] = found[k]
    untestable = {w: [a['candidate'].name for a in added if a['per'][k] is None]
                  for k, w in enumerate(ids)}
    return consistency.joint_summary(ids, joint.effects, extra, missing, untestable)
