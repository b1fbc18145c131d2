"""Forward selection of friction effects, validated on held-out data.

At each step every untried candidate (effects.py) is fitted on the training rows beside
the current model; its nonlinear parameters are profiled over their grid (best training
fit). Its evidence is the likelihood ratio with unknown noise variance,
LR = n_train log(RSS_0 / RSS_1), chi^2 with k degrees of freedom (k = rank added) under
"the effect is absent" (Wilks). A candidate is significant when

1. its p-value is below alpha / m, where m counts every grid point and searched frequency
   of every candidate of the step (Bonferroni: the chance of adding any effect to data
   that have none is at most alpha per step), and
2. it also improves the held-out rows: n_held log(RSS_0,held / RSS_1,held) above the
   chi^2(k) critical value at level ``alpha_held`` (an effect that only fits the noise of
   the training rows makes the held-out fit worse, not better), and
3. it pays for its parameters: the BIC gain LR - (k + q) ln(n_train) is positive, q the
   number of nonlinear parameters searched on its grid (Schwarz's criterion; the many
   weights of the fallback need a large gain).

Among the significant named candidates the one with the smallest held-out RSS is added.
Physics first: the smooth-speed catch-all is scored with the same tests at every step
(recorded), but it is added only when no named effect is significant, i.e. once the
named effects can bring the model no closer to the noise floor; it is then reported as
"unexplained speed dependence" with its size (report.py). The loop
stops when the residual passes the structure and whiteness tests (residuals.py), when
nothing significant is left, or after ``max_effects`` effects. Every step is recorded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.baseline import check_identifiable, find_jumps, Segments
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design, Fit, held_out_mask
from rwa_monitor.core.identify.residuals import diagnose
from rwa_monitor.core.params import check_int, check_real

SAME_STRUCTURE = 0.9
# When two named effects are alternative explanations of one structure (their fitted
# contributions have a cosine above SAME_STRUCTURE) and the data cannot tell them apart
# (Vuong's test), the one with the least structure is taken: the pre-sliding band only
# reshapes the Coulomb term at zero speed, Stribeck adds the lubricant film's speed
# scale, hysteresis a memory on top of it.
PRECEDENCE = ('presliding', 'stribeck', 'stribeck_hysteresis', 'asymmetric_coulomb', 'drag',
              'aux', 'drift', 'periodic')


@dataclass
class AddedEffect:
    """An effect the selection added: vocabulary name, kind, nonlinear params, columns."""

    name: str
    kind: str
    params: dict
    columns: slice
    evidence: dict


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

    def residual_before(self) -> np.ndarray:
        """Return the baseline model's residual on every row."""
        nb = len(self.baseline_names)
        return self.data.friction - self.design.X[:, :nb] @ self.baseline_fit.coef[:nb]

    def residual_after(self) -> np.ndarray:
        """Return the refined model's residual on every row."""
        return self.design.residual(self.final_fit)


def likelihood_ratio(n: int, rss0: float, rss1: float) -> float:
    """Return n log(RSS_0 / RSS_1): the likelihood ratio with unknown noise variance."""
    return float(n * np.log(max(rss0, 1e-300) / max(rss1, 1e-300)))


def _try(design: Design, cand: fx.Candidate, data: IdentData, params: dict):
    cols = fx.evaluate(cand.kind, params, data)
    if not np.all(np.isfinite(cols)):
        return None
    return params, design.fit(cols), cols


def _refine(design: Design, cand: fx.Candidate, data: IdentData, best: tuple) -> tuple:
    """Refine the candidate's continuous parameter between its grid neighbours.

    The training RSS is minimised over log(parameter) within one grid ratio of the best
    grid point (bounded scalar search); counted as three tests per grid point.
    """
    key, ratio = cand.extra['refine'], cand.extra['ratio']
    centre = float(best[0][key])

    def rss(log_value: float) -> float:
        got = _try(design, cand, data, {**best[0], key: float(np.exp(log_value))})
        return np.inf if got is None else got[1].rss_train
    res = optimize.minimize_scalar(rss, bounds=(np.log(centre / ratio), np.log(centre * ratio)),
                                   method='bounded', options={'xatol': 1e-3})
    got = _try(design, cand, data, {**best[0], key: float(np.exp(res.x))})
    return got if got is not None and got[1].rss_train < best[1].rss_train else best


def free_parameters(cand: fx.Candidate) -> int:
    """Return the number of nonlinear parameters searched (those that vary on the grid)."""
    if len(cand.grid) <= 1:
        return 0
    keys = set().union(*(g.keys() for g in cand.grid))
    return sum(len({repr(g.get(k)) for g in cand.grid}) > 1 for k in keys)


def _score(design: Design, current: Fit, cand: fx.Candidate, data: IdentData
           ) -> dict | None:
    """Return the best grid point of a candidate with its evidence, or None."""
    best = None
    for params in cand.grid:
        got = _try(design, cand, data, params)
        if got is not None and (best is None or got[1].rss_train < best[1].rss_train):
            best = got
    if best is None:
        return None
    if 'refine' in cand.extra:
        best = _refine(design, cand, data, best)
    params, fit, cols = best
    dof = fit.rank - current.rank
    if dof <= 0:
        return None
    lr = likelihood_ratio(fit.n_train, current.rss_train, fit.rss_train)
    lr_held = likelihood_ratio(fit.n_held_out, current.rss_held_out, fit.rss_held_out)
    free = int(dof) + free_parameters(cand)
    return {'candidate': cand, 'params': params, 'fit': fit, 'columns': cols,
            'evidence': {'lr': lr, 'dof': int(dof), 'p_value': float(stats.chi2.sf(lr, dof)),
                         'lr_held_out': lr_held,
                         'parameters': free,
                         'bic_gain': lr - free * float(np.log(fit.n_train)),
                         'rmse_in_sample': fit.rmse_train,
                         'rmse_held_out': fit.rmse_held_out}}


def identify(data: IdentData, alpha: float = 1e-3, alpha_held: float = 1e-2,
             max_effects: int = 6, jumps: bool = True, jump_window: int | None = None
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
        Level of the held-out confirmation of an added effect, in (0, 0.5].
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
        return _select(data, Segments(), alpha, alpha_held, max_effects)
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
    """Run the selection; when it ends on the catch-all, look for named physics first.

    Forward selection is greedy: an early step can give a structure to the wrong named
    effect (a pre-sliding band taking a Stribeck curve while drag and temperature still
    dominate the residual; the Stribeck term then spent on the drag at a speed scale of
    the whole range), and the catch-all then holds what is left. When the catch-all
    entered, the selection is run again with each named effect of that set left out in
    turn; the run with the smallest held-out RSS among those that need no catch-all is
    kept if its named effects reach the noise floor: its residual passes the structure
    and whiteness tests (residuals.py), or the catch-all's held-out gain over it, n_held
    log(RSS_named / RSS_catch-all), is below the chi^2 critical value at ``alpha_held``
    for the catch-all's columns (the test an effect must pass to enter).
    ``Selection.alternatives`` records every run; none kept: the first stands.
    """
    sel = _select(data, segments, alpha, alpha_held, max_effects)
    if not any(e.name == fx.FALLBACK for e in sel.effects):
        return sel
    runs = [sel]
    for eff in [e for e in sel.effects if e.name != fx.FALLBACK]:
        runs.append(_select(data, segments, alpha, alpha_held, max_effects,
                            banned=frozenset({eff.name})))
    catch = next(e for e in sel.effects if e.name == fx.FALLBACK)
    bound = float(stats.chi2.isf(alpha_held, catch.evidence['dof']))
    fit = sel.final_fit
    named = [r for r in runs if not any(e.name == fx.FALLBACK for e in r.effects)
             and (r.diagnostics_after['passes']
                  or likelihood_ratio(fit.n_held_out, r.final_fit.rss_held_out,
                                      fit.rss_held_out) < bound)]
    best = min(named, key=lambda r: r.final_fit.rss_held_out) if named else sel
    best.alternatives = [{'left_out': r.banned, 'effects': [e.name for e in r.effects],
                          'rmse_held_out': r.final_fit.rmse_held_out} for r in runs]
    return best


def _select(data: IdentData, segments: Segments, alpha: float, alpha_held: float,
            max_effects: int, banned: frozenset[str] = frozenset()) -> Selection:
    """Run the forward selection on top of a baseline with the given segments.

    ``banned``: named effects not tried at all (see :func:`_named_first`).
    """
    held = held_out_mask(len(data))
    design = Design(data.friction, segments.columns(data.speed), held)
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
                                        alpha_held)
        sel.steps.append(record)
        if chosen is None:
            sel.stop_reason = 'no candidate effect is significant'
            break
        start = design.X.shape[1]
        design.add(chosen['columns'])
        current = design.fit()
        residual = design.residual(current)
        diag = diagnose(data, residual, alpha)
        evidence = dict(chosen['evidence'])
        evidence['residual_failing_after'] = list(diag['failing'])
        sel.effects.append(AddedEffect(chosen['candidate'].name, chosen['candidate'].kind,
                                       chosen['params'], slice(start, design.X.shape[1]),
                                       evidence))
        tried.add(chosen['candidate'].name)
    sel.final_fit = current
    sel.diagnostics_after = diag
    return sel


def selection_step(design: Design, current: Fit, data: IdentData, residual: np.ndarray,
                   tried: set[str], alpha: float, alpha_held: float
                   ) -> tuple[dict | None, dict]:
    """Score every untried candidate on one wheel; return the one to add (or None)."""
    cands = [c for c in fx.named_candidates(data, residual) if c.name not in tried]
    fallback = fx.fallback_candidate(data)
    m = sum(c.tests for c in cands if c.skipped is None) + fallback.tests
    level = alpha / m
    record: dict = {'level': level, 'tests': m, 'candidates': [],
                    'rmse_in_sample_before': current.rmse_train,
                    'rmse_held_out_before': current.rmse_held_out}
    scored = []
    for cand in cands:
        if cand.skipped is not None:
            record['candidates'].append({'name': cand.name, 'skipped': cand.skipped})
            continue
        s = _score(design, current, cand, data)
        if s is None:
            record['candidates'].append({'name': cand.name,
                                         'skipped': 'adds nothing the model lacks'})
            continue
        s['significant'] = significant(s['evidence'], level, alpha_held)
        record['candidates'].append({'name': cand.name, 'params': s['params'],
                                     'significant': s['significant'], **s['evidence']})
        scored.append(s)
    winners = [s for s in scored if s['significant']]
    generic = None
    if fallback.name not in tried:
        generic = _score(design, current, fallback, data)
        if generic is not None:
            generic['significant'] = significant(generic['evidence'], level, alpha_held)
            record['candidates'].append({'name': fallback.name, 'params': generic['params'],
                                         'significant': generic['significant'],
                                         **generic['evidence']})
            if not generic['significant']:
                generic = None
    chosen = _preferred(design, data, winners, level, record) if winners else generic
    if chosen is None:
        record['added'] = None
        return None, record
    record['added'] = chosen['candidate'].name
    return chosen, record


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


def _preferred(design: Design, data: IdentData, winners: list[dict], level: float,
               record: dict) -> dict:
    """Return the significant named effect to add.

    The smallest held-out RSS wins unless another candidate explains the same structure
    (:func:`same_structure` above SAME_STRUCTURE), is indistinguishable from it and
    comes earlier in PRECEDENCE: then that one (identical wheels must not tell different
    stories because of noise). Indistinguishable: Vuong's two-sided test at the step's
    Bonferroni level ``level`` (a preference is claimed only with the evidence a finding
    needs).
    """
    best = min(winners, key=lambda s: s['fit'].rss_held_out)
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


def significant(evidence: dict, level: float, alpha_held: float) -> bool:
    """Return whether evidence passes the three tests (p, held-out LR, BIC gain)."""
    evidence['level'] = level
    evidence['held_out_threshold'] = float(stats.chi2.isf(alpha_held, evidence['dof']))
    return bool(evidence['p_value'] < level
                and evidence['lr_held_out'] > evidence['held_out_threshold']
                and evidence['bic_gain'] > 0)
