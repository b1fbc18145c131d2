"""The per-sample path of the LLR detector for models with more than two regressors.

llr-realtime paper, Algorithm 1 lines 9-18 with eq. (5)-(7), for a friction model of ``p >
2`` columns (a :class:`rwa_monitor.core.friction.RegressorSet` from model identification):
numpy per sample (outer products, a generalised eigenproblem for the weights of the tail).
The paper's two-column model runs compiled (core/llr_kernel.py). Like the kernel, these
functions act on the detector's state (core/llr_state.py ``Live``: the kernel arrays, whose
rings they share, and the ``GeneralPath`` record) with its configuration given, and return
the kernel's flags; declarations and kinds are core/llr_changes.py.
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
from scipy import linalg

from rwa_monitor.core import llr_layout as layout, llr_stats
from rwa_monitor.core.gchi2 import gchi2_logsf_general, log_sf2, log_sf2_t
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_state import Live


def ingest(live: Live, config: LLRConfig, row: int, t: float, f: float, h: np.ndarray
           ) -> int:
    """Add one accepted sample (scaled and whitened) to the sums and rings, test; return flags.

    ``REVISE`` when its position is the last change's revision point, ``DECLARE`` when the
    test of candidate ``k = j - window + 1`` (Algorithm 1 line 6) declares.
    """
    term = np.concatenate([np.outer(h, h).ravel(), h * f, [f * f]])
    total = live.general.reference_sums + term
    live.general = replace(live.general, reference_sums=total)
    ints, ring = live.ints, live.ring
    length = len(ring.row)
    j = int(ints[layout.I_POS])
    ints[layout.I_POS] = j + 1
    if j == 0:
        ints[layout.I_C_ROW] = row
    s = j % length
    ring.term[s] = term
    ring.row[s] = row
    ring.time[s] = t
    ring.speed[s] = math.nan   # a model's columns need not hold the speed
    ring.pref[(j + 1) % length] = total
    flags = layout.REVISE if j == ints[layout.I_CHECKPOINT] else 0
    k = j - config.window + 1
    if k > int(ints[layout.I_C]) + config.window and test(live, config, k, total):
        flags |= layout.DECLARE
    return flags


def test(live: Live, config: LLRConfig, k: int, total: np.ndarray) -> bool:
    """Algorithm 1 lines 9-18 at ``k`` (weights from the generalised eigenproblem).

    ``total``: the prefix row at ``k + window`` (T_k). Records a new smallest p_k
    (lines 13-15); returns True if line 18 declares.
    """
    p = config.p
    statistic = math.nan
    base, n_p = live.base(k, config.reference_max)
    pi_p, q_p, e = llr_stats.unpack(live.ring.pref[k % len(live.ring.row)] - base, p)
    pi_t, q_t, _ = llr_stats.unpack(total - base, p)
    if bool(llr_stats.well_conditioned(pi_p, config.min_excitation)):
        x = np.linalg.solve(pi_p, q_p)
        if config.noise_var is None:
            dof = float(n_p - p)
            s2 = (float(e) - float(x @ q_p)) / dof
            floor = llr_stats.NOISE_FLOOR_REL * float(e) / n_p + llr_stats.NOISE_FLOOR_ABS
            s2 = s2 if s2 > floor else floor
        else:
            s2 = config.noise_var
            dof = None
        pi_w = pi_t - pi_p
        m = np.linalg.solve(pi_t, np.column_stack([(q_t - q_p) - pi_w @ x, pi_w]))
        d = m[:, 0]
        y = float(d @ pi_p @ d) / s2
        tr = float(np.trace(m[:, 1:]))
        statistic = y
        logpmin = float(live.floats[layout.F_LOGPMIN])
        # lambda_max >= tr / p, so b = y / (2 lambda_max) <= p y / (2 tr).
        if tr > 0.0 and y > 0.0 and not p * y / (2.0 * tr) < live.floats[layout.F_YSTAR]:
            lam = np.sort(np.clip(linalg.eigh(pi_w, pi_t, eigvals_only=True), 0.0, 1.0))
            # Dropping all but the two largest terms gives a lower bound of the tail.
            two = (log_sf2(y, lam[-1], lam[-2]) if dof is None
                   else log_sf2_t(y, lam[-1], lam[-2], dof))
            if not two > logpmin + 1e-9 * (1.0 - logpmin):
                logp = gchi2_logsf_general(y, lam, None, dof)[0]
                if logp < logpmin:
                    live.record_minimum(k, logp)
    else:
        live.counters['ill_conditioned'] += 1
    live.general = replace(live.general, last_statistic=statistic)
    return live.declares(k, config.log_r, config.k_verif)


def forget_lags(live: Live) -> None:
    """Clear the AR filter's memory at a break of the sequence (llr_kernel.breaks)."""
    general = live.general
    live.general = replace(general, lag_friction=general.lag_friction[:0],
                           lag_regressors=general.lag_regressors[:0])


def whiten(live: Live, ar: tuple[float, ...], f: float, h: np.ndarray
           ) -> tuple[float, np.ndarray]:
    """Apply the AR filter ``v_l - sum_i a_i v_(l-1-i)`` to one sample (missing lags omitted).

    Same operations in the same order as :func:`llr_noise.whiten`; the paper's model is
    whitened in the kernel (core/llr_kernel.py ``ingest_sample``). The sample joins the
    filter's memory (``GeneralPath.lag_*``, newest first, ``len(ar)`` kept).
    """
    general = live.general
    fw = f
    h = np.asarray(h, dtype=float)
    hw = h
    for a, lf, lh in zip(ar, general.lag_friction, general.lag_regressors):
        fw = fw - a * lf
        hw = hw - a * lh
    keep = len(ar)
    live.general = replace(
        general, lag_friction=np.concatenate([[f], general.lag_friction])[:keep],
        lag_regressors=np.concatenate([h[None, :], general.lag_regressors])[:keep])
    return fw, hw
