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
   on every wheel's residual counts every wheel's search), the summed validation LR above
   the chi^2(sum dof) critical value at ``alpha_held``, and the pooled BIC gain
   sum_k (LR_k - dof_k ln n_k) - q ln(sum_k n_k) > 0 (q shared nonlinear parameters,
   counted once). Among significant effects the largest summed validation LR wins, with
   select.py's precedence between alternative explanations of one structure (cosine
   and Vuong's test on the wheels' pooled, variance-weighted rows). After each addition
   the shared parameters of every common effect are profiled again and effects that no
   longer pass the pooled tests are removed (joint_backfit.py).
3. The loop runs on named effects and stops when every wheel's residual passes the
   structure and whiteness tests, when nothing named is significant on the pooled
   evidence, or after ``max_effects``. The catch-all (each wheel its own knots, scored
   the same way) is admitted only when no named set reaches the floor
   (:func:`_named_first`).
4. Each wheel is then refitted with the common set: the continuous parameter of each
   effect (Stribeck speed, band width) is re-profiled on the wheel's own data (one
   coordinate pass, within one grid ratio of the shared value); shapes, exponents and
   frequencies stay shared.
5. joint_flags.py tests whether a wheel's own data contradict its siblings.

Modules: joint_candidates.py (the shared grids), joint_scoring.py (pooled evidence, one
step), joint_backfit.py, joint_flags.py; this one runs the loop and refits the wheels.
Jumps are segmented per wheel (baseline.py) before, and searched again per wheel with
the common effects in the background, as in select.identify.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.baseline import check_identifiable, find_jumps, Segments
from rwa_monitor.core.identify.consistency import WHEEL
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design
from rwa_monitor.core.identify.joint_backfit import prune_joint, reprofile_joint
from rwa_monitor.core.identify.joint_candidates import joint_candidates, JointCandidate
from rwa_monitor.core.identify.joint_flags import wheel_flags
from rwa_monitor.core.identify.joint_scoring import joint_step, Wheels
from rwa_monitor.core.identify.residuals import diagnose
from rwa_monitor.core.identify.scoring import AddedEffect, drop_one
from rwa_monitor.core.identify.select import Selection
from rwa_monitor.core.params import check_int, check_real

__all__ = ['identify_joint', 'joint_candidates', 'JointCandidate', 'JointSelection',
           'wheel_name']


def wheel_name(name: str, wheel: str) -> str:
    """Return the wheel's own name of a canonical effect name."""
    return name.replace(WHEEL, wheel)


@dataclass
class JointSelection:
    """The outcome of the joint selection: one Selection per wheel and the comparison."""

    selections: dict[str, Selection]
    effects: list[str] = field(default_factory=list)
    steps: list[dict] = field(default_factory=list)
    stop_reason: str = ''
    consistency: dict = field(default_factory=dict)
    alternatives: list[dict] = field(default_factory=list)


def identify_joint(datas: list[IdentData], alpha: float = 1e-3, alpha_held: float = 1e-2,
                   max_effects: int = 10, jumps: bool = True, jump_window: int | None = None
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


@dataclass
class _Run:
    """One joint forward selection of named effects, before the wheels are refitted."""

    wheels: Wheels
    added: list[dict]
    steps: list[dict]
    stop: str
    before: list[dict]
    banned: list[str]
    catch_all: dict | None = None

    def validation_rss(self) -> float:
        """Return the validation RSS summed over the wheels, each over its floor squared."""
        return sum(fit.rss_validation / data.noise_floor ** 2
                   for fit, data in zip(self.wheels.current, self.wheels.datas))


def _named_first(datas: list[IdentData], segments: list[Segments], alpha: float,
                 alpha_held: float, max_effects: int) -> JointSelection:
    """Select a common named set; admit the catch-all only when no named set reaches the floor.

    select._named_first on the pooled evidence. A named set reaches the noise floor when
    every wheel's residual passes the structure and whiteness tests, or when the pooled
    catch-all (each wheel its own knots), scored on top of it, fails the entry tests at
    the last step's level (p below alpha / m, summed validation LR above the chi^2
    critical value at ``alpha_held`` for its summed columns, pooled BIC gain positive).
    When the first named set does not, the selection runs again with each of its
    effects left out in turn; among the named sets that reach the floor the smallest
    validation RSS (summed over wheels, each over its floor squared) wins; when none does,
    the catch-all is added to the set with the smallest and reported as unexplained
    speed dependence. ``JointSelection.alternatives`` records every run.
    """
    run = _run(datas, segments, alpha, alpha_held, max_effects, frozenset())
    runs = [run]
    if run.catch_all is not None:
        runs += [_run(datas, segments, alpha, alpha_held, max_effects,
                      fx.left_out(a['candidate'].name)) for a in run.added]
    floor = [r for r in runs if r.catch_all is None]
    best = min(floor or runs, key=_Run.validation_rss)
    if best.catch_all is not None:
        best.added.append(best.catch_all)
        best.wheels = best.wheels.with_effects(best.added)
        best.steps[-1]['added'] = fx.FALLBACK
        best.stop = ('no named effect is significant on the pooled evidence and no named '
                     'set reaches the noise floor: the catch-all was added')
    joint = _finish(best, alpha, alpha_held)
    if len(runs) > 1:
        joint.alternatives = [{'left_out': r.banned,
                               'effects': [a['candidate'].name for a in r.added],
                               'validation_over_floor2': r.validation_rss(),
                               'reaches_floor': r.catch_all is None} for r in runs]
        for sel in joint.selections.values():   # selection.json of every wheel
            sel.alternatives = joint.alternatives
    return joint


def _run(datas: list[IdentData], segments: list[Segments], alpha: float,
         alpha_held: float, max_effects: int, banned: frozenset[str]) -> _Run:
    """Run the joint forward selection of named effects (backfitted after each addition).

    ``banned``: named effects not tried (canonical names; :func:`_named_first`).
    """
    wheels = Wheels(datas, segments)
    residuals = [dz.residual(c) for dz, c in zip(wheels.designs, wheels.current)]
    before = [diagnose(d, r, alpha) for d, r in zip(datas, residuals)]
    diags = list(before)
    run = _Run(wheels, [], [], '', before, sorted(banned))
    tried: set[str] = set(banned)
    while True:
        if all(dg['passes'] for dg in diags):
            run.stop = "every wheel's residual passes the structure and whiteness tests"
            break
        if len(run.added) >= max_effects:
            run.stop = f'max_effects = {max_effects} reached'
            break
        chosen, record = joint_step(run.wheels, residuals, tried, alpha, alpha_held,
                                    frozenset(a['candidate'].name for a in run.added))
        record['banned'] = run.banned
        run.steps.append(record)
        if chosen is None:
            run.stop = 'no candidate effect is significant on the pooled evidence'
            run.catch_all = record.pop('catch_all', None)
            break
        run.added.append(chosen)
        tried.add(chosen['candidate'].name)
        run.wheels = run.wheels.with_effects(run.added)
        if len(run.added) > 1:
            run.wheels = reprofile_joint(run.wheels, run.added)
            run.wheels, record['removed'] = prune_joint(run.wheels, run.added, alpha_held)
        for k, data in enumerate(datas):
            residuals[k] = run.wheels.designs[k].residual(run.wheels.current[k])
            diags[k] = diagnose(data, residuals[k], alpha)
    return run


def _finish(run: _Run, alpha: float, alpha_held: float) -> JointSelection:
    """Refit every wheel with the common set and test the wheels' agreement."""
    joint = JointSelection(selections={}, effects=[a['candidate'].name for a in run.added],
                           steps=run.steps, stop_reason=run.stop)
    for k, data in enumerate(run.wheels.datas):
        joint.selections[data.wheel] = _refit_wheel(run.wheels, k, run.added, run.before[k],
                                                    alpha, run.steps, run.stop)
    joint.consistency = wheel_flags(joint.selections, joint.effects, run.wheels, run.added,
                                    alpha, alpha_held)
    return joint


def _refit_wheel(wheels: Wheels, k: int, added: list[dict], before: dict, alpha: float,
                 steps: list[dict], stop: str) -> Selection:
    """Return wheel k's Selection: the common effects, continuous parameters its own."""
    data, segments = wheels.datas[k], wheels.segments[k]
    held = wheels.designs[k].split
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
        evidence['rmse_validation'] = design.fit().rmse_validation
        evidence['rmse_held_out'] = design.fit().rmse_test
        sel.effects.append(AddedEffect(wheel_name(cand.name, data.wheel), cand.kind, params,
                                       slice(start, design.X.shape[1]), evidence))
    sel.final_fit = design.fit()
    sel.diagnostics_after = diagnose(data, design.residual(sel.final_fit), alpha)
    for eff in sel.effects:
        eff.evidence['own'] = drop_one(design, sel.final_fit, eff.columns)
        eff.evidence['residual_failing_after'] = list(sel.diagnostics_after['failing'])
    return sel
