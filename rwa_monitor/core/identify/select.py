"""Forward selection of friction effects, validated on rows it was not fitted on.

At each step every untried candidate (effects.py) is fitted on the training rows beside
the current model; its nonlinear parameters are profiled over their grid (best training
fit). Its evidence is the likelihood ratio with unknown noise variance,
LR = n_train log(RSS_0 / RSS_1), chi^2 with k degrees of freedom (k = rank added) under
"the effect is absent" (Wilks). A candidate is significant when

1. its p-value is below alpha / m, where m counts every grid point and searched frequency
   of every candidate of the step (Bonferroni: the chance of adding any effect to data
   that have none is at most alpha per step), and
2. it also improves the validation rows: n_val log(RSS_0,val / RSS_1,val) above the
   chi^2(k) critical value at level ``alpha_held`` (an effect that only fits the noise of
   the training rows makes the validation fit worse, not better), and
3. it pays for its parameters: the BIC gain LR - (k + q) ln(n_train) is positive, q the
   number of nonlinear parameters searched on its grid (Schwarz's criterion; the many
   weights of the fallback need a large gain).

Among the significant named candidates the one with the smallest validation RSS is added
(ties between alternative explanations: ties.py). After each addition every effect's
nonlinear parameters are profiled again beside all the others and effects that no
longer pass the three tests are removed (backfit.py). Physics first: the loop runs on
the named effects only; the smooth-speed catch-all is scored with the same tests at
every step (recorded) and admitted only when no named set reaches the noise floor
(:func:`_named_first`); it is then reported as "unexplained speed dependence" with its
size (report.py). The loop stops when the residual passes the structure and whiteness
tests (residuals.py), when no named effect is significant, or after ``max_effects``
effects. Every step is recorded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.backfit import prune, reprofile
from rwa_monitor.core.identify.baseline import check_identifiable, find_jumps, Segments
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design, Fit, split_rows
from rwa_monitor.core.identify.residuals import diagnose
from rwa_monitor.core.identify.scoring import AddedEffect, NO_ADMISSIBLE_FIT
from rwa_monitor.core.identify.scoring import score_candidate, significant
from rwa_monitor.core.identify.ties import preferred
from rwa_monitor.core.params import check_int, check_real

__all__ = ['AddedEffect', 'identify', 'Selection', 'selection_step']


@dataclass
class Selection:
    """The outcome of the identification loop on one wheel."""

    data: IdentData
    segments: Segments
    design: Design
    baseline_fit: Fit
    final_fit: Fit
    baseline_names: list[str]
    effects: list[AddedEffect] = field(default_factory=list)
    steps: list[dict] = field(default_factory=list)
    stop_reason: str = ''
    diagnostics_before: dict = field(default_factory=dict)
    diagnostics_after: dict = field(default_factory=dict)
    first_pass_jumps: list[int] | None = None
    banned: list[str] = field(default_factory=list)
    alternatives: list[dict] = field(default_factory=list)
    catch_all: dict | None = None

    def residual_before(self) -> np.ndarray:
        """Return the baseline model's residual on every row."""
        nb = len(self.baseline_names)
        return self.data.friction - self.design.X[:, :nb] @ self.baseline_fit.coef[:nb]

    def residual_after(self) -> np.ndarray:
        """Return the refined model's residual on every row."""
        return self.design.residual(self.final_fit)


def identify(data: IdentData, alpha: float = 1e-3, alpha_held: float = 1e-2,
             max_effects: int = 10, jumps: bool = True, jump_window: int | None = None
             ) -> Selection:
    """Run the loop: baseline fit with jumps, diagnostics, forward selection.

    Jumps are found with the flexible background of baseline.py; once effects are
    selected, jumps are searched again with those effects in the background, and if the
    segments change the selection is run again on the new baseline (so that neither a
    jump passes for an effect nor an effect for a string of jumps).

    Parameters
    ----------
    data : IdentData
        One wheel's valid samples and their noise standard deviation (N m).
    alpha : float
        Family-wise level of the effect and jump tests, in (0, 0.5].
    alpha_held : float
        Level of the validation confirmation of an added effect, in (0, 0.5].
    max_effects : int
        Most effects added to model (1).
    jumps : bool
        Segment friction jumps before fitting.
    jump_window : int or None
        Samples of the jump search's window; None: chosen from the data.

    Returns
    -------
    Selection
        The added ``effects`` (each with its test), the baseline and final fits, the
        segments and the reason the selection stopped.

    Examples
    --------
    >>> import numpy as np
    >>> from rwa_monitor.core.identify.data import IdentData
    >>> speed = 300.0 * np.sin(np.arange(2000) * 0.005)
    >>> noise = np.random.default_rng(0).normal(0.0, 1e-5, 2000)
    >>> friction = -2e-4 * np.sign(speed) - 5e-7 * speed + noise
    >>> data = IdentData(wheel='rw1', time=np.arange(2000) * 0.1, speed=speed,
    ...                  friction=friction, noise_std=np.full(2000, 1e-5))
    >>> selection = identify(data, jumps=False)
    >>> selection.effects, selection.stop_reason
    ([], 'the residual passes the structure and whiteness tests')
    """
    alpha = check_real('alpha', alpha, 0.0, 0.5, low_open=True)
    alpha_held = check_real('alpha_held', alpha_held, 0.0, 0.5, low_open=True)
    max_effects = check_int('max_effects', max_effects, 0, 20)
    check_identifiable(data.speed)
    if not jumps:
        return _named_first(data, Segments(), alpha, alpha_held, max_effects)
    segments = find_jumps(data, jump_window, alpha)
    sel = _named_first(data, segments, alpha, alpha_held, max_effects)
    if not sel.effects or len(segments.starts) == 1:
        return sel   # effects in the background only weaken the evidence for a jump
    extra = np.hstack([sel.design.X[:, e.columns] for e in sel.effects])
    again = find_jumps(data, jump_window, alpha, extra=extra)
    if again.starts == segments.starts:
        return sel
    sel2 = _named_first(data, again, alpha, alpha_held, max_effects)
    sel2.first_pass_jumps = [int(k) for k in segments.starts[1:]]
    return sel2


def _named_first(data: IdentData, segments: Segments, alpha: float, alpha_held: float,
                 max_effects: int) -> Selection:
    """Select named effects; admit the catch-all only when no named set reaches the floor.

    The forward selection runs on the named effects only (:func:`_select`). A named set
    *reaches the noise floor* when its residual passes the structure and whiteness tests
    (residuals.py), or when the catch-all, scored on top of it, fails the entry tests of
    :func:`significant` at the last step's level (p below alpha / m, validation LR above
    the chi^2 critical value at ``alpha_held`` for its columns, BIC gain positive): then
    it cannot show structure beyond noise that the named effects leave. Forward selection
    is greedy (an early step can give a structure to the wrong named effect: a pre-sliding
    band took the Stribeck curve while drag and temperature still dominated the
    residual), so when the first named set does not reach the floor the selection runs
    again with each of its effects left out in turn. Among the named sets that reach the
    floor the smallest validation RSS wins; when none does, the catch-all is added to the
    set with the smallest validation RSS and reported as unexplained speed dependence.
    ``Selection.alternatives`` records every run.
    """
    sel = _select(data, segments, alpha, alpha_held, max_effects, frozenset())
    if sel.catch_all is None:
        return sel
    runs = [sel] + [_select(data, segments, alpha, alpha_held, max_effects,
                            fx.left_out(eff.name)) for eff in sel.effects]
    floor = [r for r in runs if r.catch_all is None]
    best = min(floor or runs, key=lambda r: r.final_fit.rss_validation)
    best.alternatives = [{'left_out': r.banned, 'effects': [e.name for e in r.effects],
                          'rmse_validation': r.final_fit.rmse_validation,
                          'rmse_held_out': r.final_fit.rmse_test,
                          'reaches_floor': r.catch_all is None} for r in runs]
    if best.catch_all is not None:
        _admit_catch_all(best, alpha)
    return best


def _admit_catch_all(sel: Selection, alpha: float) -> None:
    """Add the catch-all scored at the selection's last step (it passed the entry tests)."""
    scored, design = sel.catch_all, sel.design
    start = design.X.shape[1]
    design.add(scored['columns'])
    sel.final_fit = design.fit()
    sel.diagnostics_after = diagnose(sel.data, design.residual(sel.final_fit), alpha)
    evidence = dict(scored['evidence'])
    evidence['residual_failing_after'] = list(sel.diagnostics_after['failing'])
    sel.effects.append(AddedEffect(fx.FALLBACK, scored['candidate'].kind, scored['params'],
                                   slice(start, design.X.shape[1]), evidence))
    sel.steps[-1]['added'] = fx.FALLBACK
    sel.stop_reason = ('no named effect is significant and no named set reaches the noise '
                       'floor: the catch-all was added')


def _select(data: IdentData, segments: Segments, alpha: float, alpha_held: float,
            max_effects: int, banned: frozenset[str] = frozenset()) -> Selection:
    """Run the forward selection of named effects on top of a baseline with the segments.

    ``banned``: named effects not tried at all (see :func:`_named_first`). After each
    addition the effects' nonlinear parameters are profiled again (:func:`reprofile`)
    and effects that no longer pass the entry tests are removed (:func:`prune`). When
    the loop stops because no named effect is significant while the catch-all is,
    ``Selection.catch_all`` holds the catch-all's scored fit (not added).
    """
    design = Design(data.friction, segments.columns(data.speed),
                    split_rows(len(data), data.stride))
    base_fit = design.fit()
    sel = Selection(data=data, segments=segments, design=design, baseline_fit=base_fit,
                    final_fit=base_fit, baseline_names=segments.names())
    current = base_fit
    residual = design.residual(current)
    sel.diagnostics_before = diagnose(data, residual, alpha)
    diag = sel.diagnostics_before
    sel.banned = sorted(banned)
    tried: set[str] = set(banned)
    while True:
        if diag['passes']:
            sel.stop_reason = 'the residual passes the structure and whiteness tests'
            break
        if len(sel.effects) >= max_effects:
            sel.stop_reason = f'max_effects = {max_effects} reached'
            break
        chosen, record = selection_step(design, current, data, residual, tried, alpha,
                                        alpha_held, catch_all=False,
                                        present=frozenset(e.name for e in sel.effects))
        sel.steps.append(record)
        if chosen is None:
            sel.stop_reason = 'no candidate effect is significant'
            sel.catch_all = record.pop('catch_all', None)
            break
        start = design.X.shape[1]
        design.add(chosen['columns'])
        evidence = dict(chosen['evidence'])
        sel.effects.append(AddedEffect(chosen['candidate'].name, chosen['candidate'].kind,
                                       chosen['params'], slice(start, design.X.shape[1]),
                                       evidence))
        tried.add(chosen['candidate'].name)
        if len(sel.effects) > 1:
            design = reprofile(design, sel.effects, data, design.residual(design.fit()))
            design, record['removed'] = prune(design, sel.effects, alpha_held)
            sel.design = design
        current = design.fit()
        residual = design.residual(current)
        diag = diagnose(data, residual, alpha)
        evidence['residual_failing_after'] = list(diag['failing'])
    sel.final_fit = current
    sel.diagnostics_after = diag
    for eff, name in zip(sel.effects, fx.renumbered([e.name for e in sel.effects])):
        eff.name = name
    return sel


def selection_step(design: Design, current: Fit, data: IdentData, residual: np.ndarray,
                   tried: set[str], alpha: float, alpha_held: float,
                   catch_all: bool = True, present: frozenset[str] = frozenset()
                   ) -> tuple[dict | None, dict]:
    """Score every untried candidate on one wheel; return the one to add (or None).

    The catch-all is scored and recorded at every step and chosen only when no named
    effect is significant; with ``catch_all`` False it is not chosen: when it alone is
    significant it is left in ``record['catch_all']`` (the caller decides, _named_first).
    """
    cands = [c for c in fx.named_candidates(data, residual)
             if fx.offered(c.name, tried, present)]
    fallback = fx.fallback_candidate(data)
    m = sum(c.tests for c in cands if c.skipped is None) + fallback.tests
    level = alpha / m
    record: dict = {'level': level, 'tests': m, 'candidates': [],
                    'rmse_in_sample_before': current.rmse_train,
                    'rmse_validation_before': current.rmse_validation,
                    'rmse_held_out_before': current.rmse_test}
    scored = []
    for cand in cands:
        if cand.skipped is not None:
            record['candidates'].append({'name': cand.name, 'skipped': cand.skipped})
            continue
        s = score_candidate(design, current, cand, data)
        if s is None:
            record['candidates'].append({'name': cand.name,
                                         'skipped': NO_ADMISSIBLE_FIT})
            continue
        s['significant'] = significant(s['evidence'], level, alpha_held)
        record['candidates'].append({'name': cand.name, 'params': s['params'],
                                     'significant': s['significant'], **s['evidence']})
        scored.append(s)
    winners = [s for s in scored if s['significant']]
    generic = None
    if fallback.name not in tried:
        generic = score_candidate(design, current, fallback, data)
        if generic is not None:
            generic['significant'] = significant(generic['evidence'], level, alpha_held)
            record['candidates'].append({'name': fallback.name, 'params': generic['params'],
                                         'significant': generic['significant'],
                                         **generic['evidence']})
            if not generic['significant']:
                generic = None
    if winners:
        chosen = preferred(design, data, winners, level, record)
    elif catch_all:
        chosen = generic
    else:
        chosen, record['catch_all'] = None, generic
    record['added'] = None if chosen is None else chosen['candidate'].name
    return chosen, record
