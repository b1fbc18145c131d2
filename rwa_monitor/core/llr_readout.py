"""What the LLR detector reports between samples: estimate, noise level, last statistic.

llr-realtime paper, eq. (2) (the least-squares fit of the reference P_k) and eq. (5) (the
statistic of the latest test), read from the detector's working state (core/llr_state.py
``Live``) and configuration; nothing here changes the state.
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core import llr_stats
from rwa_monitor.core.llr_common import window_statistics
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_state import Live


def latest_candidate(live: Live, config: LLRConfig) -> int:
    """Return the candidate k of the latest test of the current reference, or -1."""
    k = live.position - config.window
    return k if k > live.reference_start + config.window else -1


def reference_row(live: Live, config: LLRConfig) -> tuple[np.ndarray, int]:
    """Return the prefix sums of P_k and its number of samples.

    P_k of the latest test, or every sample since the reference start before the first.
    """
    k = latest_candidate(live, config)
    if k > live.reference_start:
        base, n_p = live.base(k, config.reference_max)
        return live.ring.pref[k % len(live.ring.row)] - base, n_p
    return live.prefix_now(), live.position - live.reference_start


def estimate(live: Live, config: LLRConfig) -> np.ndarray:
    """Return the least-squares ``x`` of :func:`reference_row` (eq. (2)); nan if unidentifiable."""
    p = config.p
    row, n = reference_row(live, config)
    pi, q, _ = llr_stats.unpack(row, p)
    if n <= p or not bool(llr_stats.well_conditioned(pi, config.min_excitation)):
        return np.full(p, np.nan)
    return np.linalg.solve(pi, q)


def noise_std(live: Live, config: LLRConfig) -> float:
    """Return the noise level in use: given, or of the fit of :func:`reference_row`."""
    if config.noise_std is not None:
        return config.noise_std
    row, n = reference_row(live, config)
    pi, _, _ = llr_stats.unpack(row, config.p)
    if n <= config.p or not bool(llr_stats.well_conditioned(pi, config.min_excitation)):
        return math.nan
    return math.sqrt(llr_stats.segment_fit(row, n, config.p, None)[2])


def last_statistic(live: Live, config: LLRConfig) -> float:
    """Return the latest ``LLR_k / sigma^2`` (eq. (5)); nan before the first test or if skipped."""
    k = latest_candidate(live, config)
    if k < 0:
        return math.nan
    if live.general is not None:
        return live.general.last_statistic
    base, n_p = live.base(k, config.reference_max)
    pp = (live.ring.pref[k % len(live.ring.row)] - base)[:, None]
    pt = (live.prefix_now() - base)[:, None]
    ok, _, y, *_ = window_statistics(pp, pt, np.array([float(n_p)]), config.min_excitation,
                                     config.noise_std)
    return float(y[0]) if ok[0] else math.nan
