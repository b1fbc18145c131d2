"""A non-learned baseline beside the SVMs: thresholds on least-squares estimates.

Each statistic compares a window with its wheel's nominal reference (commissioning), as
a ratio minus one; an anomaly is flagged when its statistic exceeds a threshold set on
nominal windows only (no anomalous example is used, unlike the SVMs of eq. 24-27):

The estimates are those of stage 2 (eq. 14, one dry coefficient per interval between
the accepted changepoints and one viscous coefficient); each interval's dry coefficient
counts for its number of samples (a time-weighted distribution of the dry level):

- ``dry``: the low quantile ``LOW`` of the dry level (the base dry friction plus what
  the FSSs hold at their lowest in the window);
- ``viscous``: the viscous coefficient;
- ``fss1``: the median size of the dry jumps at the changepoints (most are the fast
  system's);
- ``fss2``: the spread of the dry level, quantile 1 - ``LOW`` minus quantile ``LOW``.

A single dry coefficient over the whole window (no changepoints) is not used: the slow
FSS's levels correlate with the slow speed profile and bias its viscous estimate by tens
of percent (measured on the development seeds).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from rwa_monitor.core.fss.segments import fit_intervals

KINDS = ('dry', 'viscous', 'fss1', 'fss2')
LOW = 0.05


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order][min(np.searchsorted(cum, q * cum[-1]), values.size - 1)])


def ls_summary(speed: np.ndarray, friction: np.ndarray, changepoints: np.ndarray, *,
               dk_error: int = 10, viscous_prior: float = 1.0) -> dict[str, float]:
    """Return the least-squares estimates the baseline compares (normalised units).

    ``changepoints``: the accepted changepoints (Extraction.accepted).
    """
    fit = fit_intervals(friction, speed, changepoints, dk_error=dk_error,
                        viscous_prior=viscous_prior)
    ok = np.isfinite(fit.dry) & (fit.hth > 0)
    dry, weight = fit.dry[ok], fit.hth[ok]
    deltas = np.diff(fit.dry)
    deltas = deltas[np.isfinite(deltas)]
    if dry.size == 0:
        nan = float('nan')
        return {'dry': nan, 'viscous': float(fit.viscous), 'jump_median': nan,
                'dry_range': nan}
    low = _weighted_quantile(dry, weight, LOW)
    return {'dry': low, 'viscous': float(fit.viscous),
            'jump_median': float(np.median(np.abs(deltas))) if deltas.size else 0.0,
            'dry_range': _weighted_quantile(dry, weight, 1.0 - LOW) - low}


def _ratio(value: float, reference: float) -> float:
    if not (np.isfinite(value) and np.isfinite(reference)) or reference <= 0:
        return float('nan')
    return value / reference - 1.0


def baseline_scores(window: Mapping[str, float], reference: Mapping[str, float]
                    ) -> dict[str, float]:
    """Return each anomaly's statistic: the window's estimate / the reference's - 1."""
    return {'dry': _ratio(window['dry'], reference['dry']),
            'viscous': _ratio(window['viscous'], reference['viscous']),
            'fss1': _ratio(window['jump_median'], reference['jump_median']),
            'fss2': _ratio(window['dry_range'], reference['dry_range'])}


def nominal_thresholds(nominal_scores: list[Mapping[str, float]], false_rate: float
                       ) -> dict[str, float]:
    """Return per anomaly the (1 - false_rate) quantile of its statistic on nominal windows."""
    if not nominal_scores:
        raise ValueError('nominal_thresholds needs nominal windows')
    if not 0.0 < false_rate < 1.0:
        raise ValueError(f'false_rate must be in (0, 1), got {false_rate}')
    out = {}
    for kind in KINDS:
        values = np.array([s[kind] for s in nominal_scores], dtype=float)
        values = values[np.isfinite(values)]
        out[kind] = float(np.quantile(values, 1.0 - false_rate)) if values.size else np.inf
    return out


def baseline_flags(scores: Mapping[str, float], thresholds: Mapping[str, float]
                   ) -> dict[str, bool]:
    """Return one boolean per anomaly: its statistic above its threshold."""
    return {k: bool(np.isfinite(scores[k]) and scores[k] > thresholds[k]) for k in KINDS}
