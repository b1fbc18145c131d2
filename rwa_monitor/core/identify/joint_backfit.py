"""Backfitting the common set of sibling wheels (backfit.py on the pooled evidence)."""

from __future__ import annotations

import numpy as np
from scipy import stats

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.joint_scoring import score_joint, shared_params, Wheels
from rwa_monitor.core.identify.scoring import drop_one, likelihood_ratio, significant


def reprofile_joint(wheels: Wheels, added: list[dict], passes: int = 3) -> Wheels:
    """Re-profile each common effect's shared nonlinear parameters given the others.

    select.reprofile on the pooled evidence: each effect in turn is scored again over
    its grid (and refined) on every wheel with all the other common effects in the
    model; the point with the largest pooled training LR is kept when it beats the
    effect's current parameters. Periodic frequencies stay. Returns the new wheels.
    """
    for _ in range(passes):
        moved = False
        for a in added:
            cand = a['candidate']
            fixed = len(cand.grid) <= 1 and cand.refine is None
            if cand.kind in ('periodic', 'smooth_speed') or fixed:
                continue
            others = wheels.with_effects(added, skip=a)
            scored = score_joint(others, cand)
            if scored is None:
                continue
            now = sum(likelihood_ratio(o.n_train_eff, o.rss_train, c.rss_train)
                      for o, c, s in zip(others.current, wheels.current, a['per'])
                      if s is not None)
            if others.pooled_lr(scored['per']) <= now + 1e-9 * max(abs(now), 1.0):
                continue
            a.setdefault('params_at_entry', shared_params(a))
            a['per'] = scored['per']
            wheels = wheels.with_effects(added)
            moved = True
        if not moved:
            break
    return wheels


def prune_joint(wheels: Wheels, added: list[dict], alpha_held: float
                ) -> tuple[Wheels, list[dict]]:
    """Remove common effects that no longer pass the pooled entry tests (select.prune).

    Each effect's pooled evidence against the model without it (its parameters fixed):
    summed LR and validation LR over the wheels that have it, BIC gain with its shared
    parameters paid once, at its step's level; the wheels' mean weight of the physical
    sign (effects.POSITIVE_WEIGHT). The weakest failing one goes first.
    """
    removed: list[dict] = []
    while len(added) > 1:
        failing = []
        for a in added:
            lr = held = gain = 0.0
            dof = n_total = 0
            weights = []
            for k, s in enumerate(a['per']):
                if s is None:
                    continue
                full = wheels.current[k]
                columns = wheels.columns_of(added, a, k)
                weights.append(full.coef[columns])
                own = drop_one(wheels.designs[k], full, columns)
                lr, held, dof = lr + own['lr'], held + own['lr_validation'], dof + own['dof']
                gain += own['lr'] - own['dof'] * float(np.log(full.n_train_eff))
                n_total += full.n_train_eff
            entry = {'lr': lr, 'dof': dof, 'lr_validation': held,
                     'p_value': float(stats.chi2.sf(lr, dof)) if dof else 1.0,
                     'bic_gain': gain - a['candidate'].free * float(np.log(max(n_total, 1)))}
            kind = a['candidate'].kind
            physical = kind not in fx.POSITIVE_WEIGHT or fx.physical_weights(
                kind, np.mean(weights, axis=0))
            if dof == 0 or not physical:
                failing.append((-np.inf, a, entry))
            elif not significant(entry, a['evidence']['level'], alpha_held):
                failing.append((held, a, entry))
        if not failing:
            break
        _, a, entry = min(failing, key=lambda item: item[0])
        removed.append({'name': a['candidate'].name, 'params': shared_params(a), **entry})
        added.remove(a)
        wheels = wheels.with_effects(added)
    return wheels, removed
