"""The per-sample path of the LLR detector for models with more than two regressors.

llr-realtime paper, Algorithm 1 lines 9-18 with eq. (5)-(7), for a friction model of ``p >
2`` columns (a :class:`rwa_monitor.core.friction.RegressorSet` from model identification):
numpy per sample (outer products, a generalised eigenproblem for the weights of the tail).
The paper's two-column model runs compiled (core/llr_kernel.py). :class:`GeneralModel` is
a base of :class:`rwa_monitor.core.llr_detector.LLRDetector`; declarations and kinds are
those of :class:`rwa_monitor.core.llr_changes.ChangeRules`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg

from rwa_monitor.core import llr_layout as layout, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gchi2 import gchi2_logsf_general, log_sf2, log_sf2_t


class GeneralModel:
    """Algorithm 1 per sample for ``p > 2`` regressors (numpy)."""

    def _update_general(self, row: int, t: float, f: float, h: np.ndarray
                        ) -> list[AnomalyEvent]:
        term = np.concatenate([np.outer(h, h).ravel(), h * f, [f * f]])
        P = self._pref_general + term
        self._pref_general = P
        ints, ring = self._ints, self._rings()
        j = int(ints[layout.I_POS])
        ints[layout.I_POS] = j + 1
        if j == 0:
            ints[layout.I_C_ROW] = row
        s = j % self._L
        ring.term[s] = term
        ring.row[s] = row
        ring.time[s] = t
        ring.pref[(j + 1) % self._L] = P
        events = self._revise(j) if j == ints[layout.I_CHECKPOINT] else []
        k = j - self._w + 1
        if k > int(ints[layout.I_C]) + self._w and self._test_general(k, P):
            events.extend(self._declare(j))
        return events

    def _test_general(self, k: int, P: np.ndarray) -> bool:
        """Algorithm 1 lines 9-18 at ``k`` (weights from the generalised eigenproblem)."""
        p = self._p
        self._last_y = math.nan
        base, n_p = self._base(k)
        pi_p, q_p, e = llr_stats.unpack(self._rings().pref[k % self._L] - base, p)
        pi_t, q_t, _ = llr_stats.unpack(P - base, p)
        if bool(llr_stats.well_conditioned(pi_p, self._min_exc)):
            x = np.linalg.solve(pi_p, q_p)
            if self._noise_var is None:
                dof = float(n_p - p)
                s2 = (float(e) - float(x @ q_p)) / dof
                floor = llr_stats.NOISE_FLOOR_REL * float(e) / n_p + llr_stats.NOISE_FLOOR_ABS
                s2 = s2 if s2 > floor else floor
            else:
                s2 = self._noise_var
                dof = None
            pi_w = pi_t - pi_p
            m = np.linalg.solve(pi_t, np.column_stack([(q_t - q_p) - pi_w @ x, pi_w]))
            d = m[:, 0]
            y = float(d @ pi_p @ d) / s2
            tr = float(np.trace(m[:, 1:]))
            self._last_y = y
            logpmin = float(self._fs[layout.F_LOGPMIN])
            # lambda_max >= tr / p, so b = y / (2 lambda_max) <= p y / (2 tr).
            if tr > 0.0 and y > 0.0 and not p * y / (2.0 * tr) < self._fs[layout.F_YSTAR]:
                lam = np.sort(np.clip(linalg.eigh(pi_w, pi_t, eigvals_only=True), 0.0, 1.0))
                # Dropping all but the two largest terms gives a lower bound of the tail.
                two = (log_sf2(y, lam[-1], lam[-2]) if dof is None
                       else log_sf2_t(y, lam[-1], lam[-2], dof))
                if not two > logpmin + 1e-9 * (1.0 - logpmin):
                    logp = gchi2_logsf_general(y, lam, None, dof)[0]
                    if logp < logpmin:
                        self._record(k, logp)
        else:
            self._counters['ill_conditioned'] += 1
        return self._declares(k)

    def _whiten(self, f: float, h: np.ndarray) -> tuple[float, np.ndarray]:
        """Apply the AR filter ``v_l - sum_i a_i v_(l-1-i)`` to one sample (missing lags omitted).

        Same operations in the same order as :func:`llr_common.whiten`; the paper's model
        is whitened in the kernel (core/llr_kernel.py ``ingest``).
        """
        lags = self._lags
        fw = f
        h = np.asarray(h, dtype=float)
        hw = h
        for a, (lf, lh) in zip(self._ar, lags):
            fw = fw - a * lf
            hw = hw - a * lh
        lags.insert(0, (f, h))
        del lags[len(self._ar):]
        return fw, hw
