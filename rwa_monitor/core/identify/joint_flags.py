"""Wheels that contradict their siblings: both tests of consistency.py on a joint fit.

*extra*: the wheel's refitted residual fails and one step of the single-wheel selection
on it, at the family level alpha / K, adds an effect. *missing*: the Wald test of the
wheel's weights against its siblings' (consistency.weaker_than_siblings) with the
wheel's own evidence for the effect; the covariances come from :func:`shared_weights`.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.identify import consistency
from rwa_monitor.core.identify.consistency import sibling_name as canonical_name
from rwa_monitor.core.identify.joint_scoring import Wheels
from rwa_monitor.core.identify.select import Selection, selection_step


def shared_weights(wheels: Wheels, added: list[dict]) -> dict[str, list]:
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


def wheel_flags(selections: dict[str, Selection], effects: list[str], wheels: Wheels,
                added: list[dict], alpha: float, alpha_held: float) -> dict:
    """Run both contradiction tests of consistency.py on every wheel."""
    shared = shared_weights(wheels, added)
    ids = [d.wheel for d in wheels.datas]
    count = len(ids)
    extra: dict[str, dict] = {}
    for data in wheels.datas:
        sel = selections[data.wheel]
        if sel.diagnostics_after['passes']:
            continue   # alone, the wheel would stop here too (select.py)
        tried = {e.name for e in sel.effects}
        resid = sel.design.residual(sel.final_fit)
        chosen, record = selection_step(sel.design, sel.final_fit, data, resid, tried,
                                        alpha / count, alpha_held, present=frozenset(tried))
        if chosen is not None:
            extra[data.wheel] = {'effect': canonical_name(chosen['candidate'].name,
                                                          data.wheel),
                                 **{k: v for k, v in chosen['evidence'].items()},
                                 'params': chosen['params']}
    missing: dict[str, dict] = {}
    for a in added:
        name = a['candidate'].name
        own = [next((e.evidence['own'] for e in selections[w].effects
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
    return consistency.joint_summary(ids, effects, extra, missing, untestable)
