"""Scoring one candidate effect on one wheel: profile, evidence, the entry tests.

A candidate is fitted on the training rows beside the current model; its nonlinear
parameters are profiled over their grid (best training fit) and the continuous one
refined between grid neighbours. Its evidence is the likelihood ratio with unknown noise
variance, LR = n_train log(RSS_0 / RSS_1), chi^2 with k degrees of freedom (k = rank
added) under "the effect is absent" (Wilks); the validation LR and the BIC gain are the
other two entry tests (:func:`significant`, select.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.fitting import Design, Fit


@dataclass
class AddedEffect:
    """An effect the selection added: vocabulary name, kind, nonlinear params, columns."""

    name: str
    kind: str
    params: dict
    columns: slice
    evidence: dict


NO_ADMISSIBLE_FIT = ('adds nothing the model lacks, or only with the unphysical sign of its '
                     'weight (effects.POSITIVE_WEIGHT)')


def likelihood_ratio(n: int, rss0: float, rss1: float) -> float:
    """Return n log(RSS_0 / RSS_1): the likelihood ratio with unknown noise variance."""
    return float(n * np.log(max(rss0, 1e-300) / max(rss1, 1e-300)))


def _try(design: Design, cand: fx.Candidate, data: IdentData, params: dict):
    """Return (params, fit, columns) at one point, or None: not finite, unphysical sign."""
    cols = fx.evaluate(cand.kind, params, data)
    if not np.all(np.isfinite(cols)):
        return None
    fit = design.fit(cols)
    if not fx.physical_weights(cand.kind, fit.coef[design.X.shape[1]:]):
        return None
    return params, fit, cols


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
    with np.errstate(invalid='ignore'):   # inf - inf at inadmissible points: golden step
        res = optimize.minimize_scalar(rss, bounds=(np.log(centre / ratio),
                                                    np.log(centre * ratio)),
                                       method='bounded', options={'xatol': 1e-3})
    got = _try(design, cand, data, {**best[0], key: float(np.exp(res.x))})
    return got if got is not None and got[1].rss_train < best[1].rss_train else best


def free_parameters(cand: fx.Candidate) -> int:
    """Return the number of nonlinear parameters searched (those that vary on the grid)."""
    if len(cand.grid) <= 1:
        return 0
    keys = set().union(*(g.keys() for g in cand.grid))
    return sum(len({repr(g.get(k)) for g in cand.grid}) > 1 for k in keys)


def score_candidate(design: Design, current: Fit, cand: fx.Candidate, data: IdentData
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
    lr = likelihood_ratio(fit.n_train_eff, current.rss_train, fit.rss_train)
    lr_held = likelihood_ratio(fit.n_validation_eff, current.rss_validation, fit.rss_validation)
    free = int(dof) + free_parameters(cand)
    return {'candidate': cand, 'params': params, 'fit': fit, 'columns': cols,
            'evidence': {'lr': lr, 'dof': int(dof), 'p_value': float(stats.chi2.sf(lr, dof)),
                         'lr_validation': lr_held,
                         'parameters': free,
                         'bic_gain': lr - free * float(np.log(fit.n_train_eff)),
                         'rmse_in_sample': fit.rmse_train,
                         'rmse_validation': fit.rmse_validation}}


def drop_one(design: Design, full: Fit, columns: slice) -> dict:
    """Return the evidence for columns in a fit: the LR of leaving them out."""
    keep = np.ones(design.X.shape[1], dtype=bool)
    keep[columns] = False
    without = Design(design.y, design.X[:, keep], design.split).fit()
    dof = max(int(full.rank - without.rank), 0)
    lr = likelihood_ratio(full.n_train_eff, without.rss_train, full.rss_train)
    return {'lr': lr, 'dof': dof,
            'p_value': float(stats.chi2.sf(lr, dof)) if dof else 1.0,
            'lr_validation': likelihood_ratio(full.n_validation_eff,
                                              without.rss_validation, full.rss_validation)}


def significant(evidence: dict, level: float, alpha_held: float) -> bool:
    """Return whether evidence passes the three tests (p, validation LR, BIC gain)."""
    evidence['level'] = level
    evidence['validation_threshold'] = float(stats.chi2.isf(alpha_held, evidence['dof']))
    return bool(evidence['p_value'] < level
                and evidence['lr_validation'] > evidence['validation_threshold']
                and evidence['bic_gain'] > 0)
