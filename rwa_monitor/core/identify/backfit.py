"""Backfitting a selected set: parameters profiled again, redundant effects removed.

Forward selection profiles an effect's nonlinear parameters when it enters, beside the
effects found before it. Effects found later change what it has to fit, and an effect
that entered early can become redundant once a later one sits at its own parameters.
Both left systematic leftovers that a spurious named effect (hysteresis) or the
catch-all then took (docs/identify.md, section 5). After each addition the selection
calls :func:`reprofile` and then :func:`prune`; joint_backfit.py does the same on the
pooled evidence of sibling wheels.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design
from rwa_monitor.core.identify.scoring import AddedEffect, drop_one, score_candidate
from rwa_monitor.core.identify.scoring import significant


def reprofile(design: Design, added: list[AddedEffect], data: IdentData,
              residual: np.ndarray, passes: int = 3) -> Design:
    """Re-profile every added effect's nonlinear parameters given all the others.

    An effect's speed scale, shape or exponent is profiled when it enters, beside the
    effects found before it; effects found later change what it has to fit (on the
    windage file a Stribeck speed of 4.39 rad/s and a drag exponent of 2.5 were fitted
    while drag and temperature were missing, and their leftover let a hysteresis term
    and the catch-all in). So after each addition each effect in turn is profiled again
    over its grid (and refined) with every other column in the model (coordinate
    descent on the training RSS, at most ``passes`` sweeps); a new point is kept only
    when it lowers the training RSS. Periodic frequencies stay (their grid comes from
    the residual's spectrum at the step). The effect's entry evidence is kept; its
    parameters at entry are in ``evidence['params_at_entry']``. Returns the new design.
    """
    for _ in range(passes):
        cands = {c.name: c for c in fx.named_candidates(data, residual)}
        moved = False
        for eff in added:
            cand = cands.get(eff.name)
            if cand is None or cand.skipped is not None or eff.kind == 'periodic' \
                    or (len(cand.grid) <= 1 and 'refine' not in cand.extra):
                continue
            keep = np.ones(design.X.shape[1], dtype=bool)
            keep[eff.columns] = False
            others = Design(design.y, design.X[:, keep], design.split)
            scored = score_candidate(others, others.fit(), cand, data)
            if scored is None or scored['columns'].shape[1] != eff.columns.stop - \
                    eff.columns.start or scored['fit'].rss_train >= \
                    design.fit().rss_train * (1.0 - 1e-9):
                continue
            X = design.X.copy()
            X[:, eff.columns] = scored['columns']
            design = Design(design.y, X, design.split)
            eff.evidence.setdefault('params_at_entry', dict(eff.params))
            eff.params = scored['params']
            moved = True
        if not moved:
            break
        residual = design.residual(design.fit())
    return design


def prune(design: Design, added: list[AddedEffect], alpha_held: float
          ) -> tuple[Design, list[dict]]:
    """Remove added effects that no longer pass the entry tests; return what went.

    After re-profiling, an effect that entered early can be redundant (on the windage
    file, before the sign rule of effects.POSITIVE_WEIGHT, a pre-sliding band took the
    Stribeck curve at step 0; once the Stribeck term sat at its own speed the band's
    validation gain was 0.4). Each effect is tested as it
    was at entry, against the model without it (its nonlinear parameters fixed): p below
    its step's level, validation LR above the chi^2 critical value at ``alpha_held``, BIC
    gain positive, its weight of the physical sign (effects.POSITIVE_WEIGHT). The weakest
    failing effect (smallest validation LR) is removed, the list changed in place, and the
    test repeated. A removed effect is not tried again.
    """
    removed: list[dict] = []
    while len(added) > 1:
        full = design.fit()
        failing = []
        for eff in added:
            own = drop_one(design, full, eff.columns)
            if own['dof'] == 0 or not fx.physical_weights(eff.kind, full.coef[eff.columns]):
                failing.append((-np.inf, eff, own))
                continue
            own['bic_gain'] = own['lr'] - (own['dof'] + eff.evidence['parameters']
                                           - eff.evidence['dof']) * np.log(full.n_train_eff)
            entry = {'p_value': own['p_value'], 'lr_validation': own['lr_validation'],
                     'bic_gain': own['bic_gain'], 'dof': own['dof']}
            if not significant(entry, eff.evidence.get('level', 1.0), alpha_held):
                failing.append((own['lr_validation'], eff, own))
        if not failing:
            break
        _, eff, own = min(failing, key=lambda item: item[0])
        keep = np.ones(design.X.shape[1], dtype=bool)
        keep[eff.columns] = False
        width = eff.columns.stop - eff.columns.start
        design = Design(design.y, design.X[:, keep], design.split)
        for other in added:
            if other.columns.start > eff.columns.start:
                other.columns = slice(other.columns.start - width, other.columns.stop - width)
        added.remove(eff)
        removed.append({'name': eff.name, 'params': eff.params, **own})
    return design, removed
