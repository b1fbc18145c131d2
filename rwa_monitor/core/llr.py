"""Online LLR friction-anomaly detector (llr-realtime paper, Algorithm 1 and 2, eq. (1)-(7)).

:class:`LLRDetector` is the streaming object (one per wheel): ``update(t, speed, friction)``
per sample, O(1) per sample via prefix sums over the reference segment, memory bounded by
a ring of ``2 * window + k_verif + 2`` samples. :func:`detect_batch` (in
:mod:`rwa_monitor.core.llr_batch`, re-exported here) gives the same events from whole
arrays. The algorithm as implemented, its departures from the paper and the
categorisation design are in docs/llr.md.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from scipy import linalg

from rwa_monitor.core import keys, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import coulomb_viscous, RegressorSet
from rwa_monitor.core.gchi2 import (gchi2_logsf_general, log_lower_bound, log_sf2,
                                    log_sf2_t, skip_threshold)
from rwa_monitor.core.params import AUTO, check_int, check_real

COUNTER_NAMES = ('nonfinite', 'out_of_range', 'non_increasing_time', 'missing_aux',
                 'ill_conditioned')
_LN10 = math.log(10.0)


def validate_parameters(component: str = 'rw1', *, window: int = 500,
                        k_verif: int | str | None = AUTO, false_alarm_rate: float = 1e-5,
                        noise_std: float | str | None = AUTO,
                        regressors: RegressorSet | None = None,
                        min_excitation: float = 1e-6, category_level: float = 1e-3,
                        category_revisions: int = 3, refine_change: bool = True,
                        max_abs_speed: float = 1e6, max_abs_friction: float = 1e6
                        ) -> dict[str, Any]:
    """Check the detector's keyword parameters; return them normalised (ValueError if bad).

    ``k_verif`` and ``noise_std`` :data:`AUTO` (core/schema.py) become ``window // 2`` and
    None (estimated) in the returned mapping.
    """
    if not isinstance(component, str) or not component:
        raise ValueError(f'component must be a non-empty string, got {component!r}')
    if regressors is None:
        regressors = coulomb_viscous()
    if not isinstance(regressors, RegressorSet):
        raise ValueError(f'regressors must be a RegressorSet or None, got {regressors!r}')
    p = regressors.p
    window = check_int('window', window, max(10, p + 2))
    if k_verif is None or k_verif == AUTO:
        k_verif = window // 2
    k_verif = check_int('k_verif', k_verif, 0, window - 1)
    r = check_real('false_alarm_rate', false_alarm_rate, 0.0, 1.0, True, True)
    if noise_std == AUTO:
        noise_std = None
    if noise_std is not None:
        noise_std = check_real('noise_std', noise_std, 0.0, math.inf, True, True)
    min_excitation = check_real('min_excitation', min_excitation, 0.0, 1.0, False, True)
    if category_level is None:
        category_level = r
    category_level = check_real('category_level', category_level, 0.0, 1.0, True, True)
    category_revisions = check_int('category_revisions', category_revisions, 0, 60)
    if not isinstance(refine_change, bool):
        raise ValueError(f'refine_change must be True or False, got {refine_change!r}')
    max_abs_speed = check_real('max_abs_speed', max_abs_speed, 0.0, math.inf, True, True)
    max_abs_friction = check_real('max_abs_friction', max_abs_friction, 0.0, math.inf, True,
                                  True)
    return dict(component=component, window=window, k_verif=k_verif,
                false_alarm_rate=r, noise_std=noise_std, regressors=regressors,
                min_excitation=min_excitation, category_level=category_level,
                category_revisions=category_revisions, refine_change=refine_change,
                max_abs_speed=max_abs_speed, max_abs_friction=max_abs_friction)


def make_event(component: str, kind: str, rows: tuple[int, int, int],
               times: tuple[float, float], log_p: float, dx: np.ndarray,
               z: tuple[float, float], s2: float, revision: int, confirmed: bool
               ) -> AnomalyEvent:
    """Build the AnomalyEvent of a declaration or revision.

    ``rows = (change row, argmin row, declaration row)``, ``times = (change time,
    declaration time)``; ``confirmed``: the data tell the kind apart (docs/llr.md).
    """
    details = {keys.DELTA_DRY: float(dx[0]), keys.DELTA_VISCOUS: float(dx[1]),
               keys.NOISE_STD: math.sqrt(s2), keys.Z_DRY: z[0], keys.Z_VISCOUS: z[1],
               keys.KIND_CONFIRMED: bool(confirmed),
               keys.ARGMIN_INDEX: rows[1], keys.LOG10_P_VALUE: log_p / _LN10}
    return AnomalyEvent(detector='llr', component=component, kind=kind, time=times[0],
                        index=rows[0], declared_time=times[1], declared_index=rows[2],
                        p_value=math.exp(log_p), revision=revision, details=details)


def declaration(prefix: np.ndarray, first: int, c: int, k_min: int, n: int,
                cfg: Mapping[str, Any], z_thr: float) -> tuple[int, int, str, np.ndarray,
                                                               tuple[float, float], float,
                                                               bool]:
    """Return ``(change position, restart, kind, dx, z, sigma^2, confirmed)`` at a declaration.

    ``prefix[i]`` is the prefix-sum row (reference start ``c``) at position ``first + i``,
    covering ``[max(c, k_min - window), n + 1]``. Change position ``tau``: the ML refinement
    (:func:`llr_stats.refine_change`) over ``k_min +- window`` if enabled, else ``k_min``
    (the argmin of p_k, Algorithm 1 line 15). Categorisation: before = ``[c, tau)``, after
    = ``[tau, n]`` (:func:`llr_stats.categorise`). The new reference starts at
    ``max(tau, k_min)``, the later of the two change estimates, so that an estimate that
    falls before the true change does not put pre-change samples in it (they would be
    declared as the same change again).
    """
    p = cfg['regressors'].p
    noise_var = None if cfg['noise_std'] is None else cfg['noise_std'] ** 2
    tau = k_min
    if cfg['refine_change']:
        w = cfg['window']
        tau = llr_stats.refine_change(prefix, first, c, n, k_min - w, k_min + w, p,
                                      noise_var, z_thr, k_min)
    before = prefix[tau - first]
    after = prefix[n + 1 - first] - before
    kind, dx, z, s2, confirmed = llr_stats.categorise(before, tau - c, after, p, noise_var,
                                                      z_thr)
    return tau, max(tau, k_min), kind, dx, z, s2, confirmed


def checkpoints(start: int, n: int, count: int, window: int) -> list[int]:
    """Return the positions where the kind of a change declared at ``n`` is re-checked.

    The after-segment ``[start, n]`` holds ``n - start + 1`` samples at declaration; with
    ``L0 = max(n - start + 1, window)`` the kind is re-evaluated when it holds ``2 L0, 4 L0,
    ...`` samples (``count`` checks).
    """
    length = max(n - start + 1, window)
    return [start + length * 2 ** i - 1 for i in range(1, count + 1)]


class LLRDetector:
    """Streaming LLR detector of friction changes for one wheel (Algorithm 1).

    Keyword parameters (core/schema.py LLR, docs/parameters.md): ``window`` w (look-ahead
    samples, >= 10), ``k_verif`` (verification samples in ``[0, window - 1]``; ``'auto'``:
    ``window // 2``), ``false_alarm_rate`` r in (0, 1), ``noise_std`` (N m; ``'auto'``:
    estimated from the reference fit), ``regressors`` (a RegressorSet; None: the paper's eq. (1)),
    ``min_excitation`` (smallest ``det(corr(Pi_P))``, in [0, 1): below it the test is
    skipped and counted), ``category_level`` (level of each dry / viscous test, default
    1e-3; None: r),
    ``category_revisions`` (re-checks of the kind as data arrive), ``refine_change`` (ML
    refinement of the change time), ``max_abs_speed`` / ``max_abs_friction`` (samples at or
    beyond are dropped and counted as ``out_of_range``: absurd values never reach the sums;
    default 1e6 rad/s and 1e6 N m). Positions count accepted samples; events carry the row
    index (number of ``update`` calls before that sample since construction or reset).
    """

    def __init__(self, component: str = 'rw1', *, window: int = 500,
                 k_verif: int | str = AUTO, false_alarm_rate: float = 1e-5,
                 noise_std: float | str = AUTO, regressors: RegressorSet | None = None,
                 min_excitation: float = 1e-6, category_level: float = 1e-3,
                 category_revisions: int = 3, refine_change: bool = True,
                 max_abs_speed: float = 1e6, max_abs_friction: float = 1e6) -> None:
        self._cfg = validate_parameters(
            component, window=window, k_verif=k_verif, false_alarm_rate=false_alarm_rate,
            noise_std=noise_std, regressors=regressors, min_excitation=min_excitation,
            category_level=category_level, category_revisions=category_revisions,
            refine_change=refine_change, max_abs_speed=max_abs_speed,
            max_abs_friction=max_abs_friction)
        cfg = self._cfg
        self._component = cfg['component']
        self._w = cfg['window']
        self._kverif = cfg['k_verif']
        self._logr = math.log(cfg['false_alarm_rate'])
        self._noise_var = None if cfg['noise_std'] is None else cfg['noise_std'] ** 2
        self._regressors = cfg['regressors']
        self._p = self._regressors.p
        self._default = self._regressors.is_coulomb_viscous
        self._min_exc = cfg['min_excitation']
        self._z_thr = llr_stats.z_threshold(cfg['category_level'])
        self._L = 2 * self._w + self._kverif + 2
        self._max_w = cfg['max_abs_speed']
        self._max_f = cfg['max_abs_friction']
        self.reset()

    # -- read-only state --------------------------------------------------------------
    @property
    def parameters(self) -> dict[str, Any]:
        """Validated keyword parameters, defaults filled in."""
        return dict(self._cfg)

    @property
    def params(self) -> dict[str, Any]:
        """Validated keyword parameters (the detector protocol's name, core/protocol.py)."""
        return dict(self._cfg)

    @property
    def last_event(self) -> AnomalyEvent | None:
        """The latest event returned by :meth:`update` (declaration or revision), or None."""
        return self._last_event

    @property
    def component(self) -> str:
        """Wheel id."""
        return self._component

    @property
    def n_samples(self) -> int:
        """Number of ``update`` calls since construction or reset (accepted or not)."""
        return self._rows

    @property
    def counters(self) -> dict[str, int]:
        """Rejected samples and skipped tests by reason."""
        return dict(self._counters)

    @property
    def p_min(self) -> float:
        """Smallest p_k since the reference start (Algorithm 1 line 14), 1 before any."""
        return math.exp(self._logpmin)

    @property
    def log_p_min(self) -> float:
        """Natural logarithm of :attr:`p_min` (never underflows)."""
        return self._logpmin

    @property
    def last_statistic(self) -> float:
        """Latest ``LLR_k / sigma^2`` (nan before the first test or if it was skipped)."""
        k = self._latest_k()
        if k < 0:
            return math.nan
        if self._p != 2:
            return self._last_y
        from rwa_monitor.core.llr_batch import _stats
        cfg = {'min_excitation': self._min_exc,
               'noise_std': None if self._noise_var is None else math.sqrt(self._noise_var)}
        pp = np.asarray(self._rpref[k % self._L], dtype=float)[:, None]
        pt = np.asarray(self._pref, dtype=float)[:, None]
        ok, _, y, *_ = _stats(pp, pt, np.array([float(k - self._c)]), cfg)
        return float(y[0]) if ok[0] else math.nan

    def _latest_k(self) -> int:
        """Return the candidate k of the latest test of the current reference, or -1."""
        k = self._pos - self._w
        return k if k > self._c + self._w else -1

    @property
    def reference_start_index(self) -> int:
        """Row index where the current reference segment starts (-1 if no sample yet)."""
        return self._c_row

    def _reference_row(self) -> tuple[Any, int]:
        k = self._latest_k()
        if k > self._c:
            return self._rpref[k % self._L], k - self._c
        return self._pref, self._pos - self._c

    @property
    def estimate(self) -> np.ndarray:
        """Least-squares ``x`` (``[f_c, f_v, ...]``) over the reference segment P_k.

        P_k of the latest test, or all samples since the reference start before the first
        test; nan while not identifiable.
        """
        row, n = self._reference_row()
        pi, q, _ = llr_stats.unpack(np.asarray(row, dtype=float), self._p)
        if n <= self._p or not bool(llr_stats.well_conditioned(pi, self._min_exc)):
            return np.full(self._p, np.nan)
        return np.linalg.solve(pi, q)

    @property
    def noise_std(self) -> float:
        """Noise standard deviation in use (given, or estimated on the reference)."""
        if self._noise_var is not None:
            return math.sqrt(self._noise_var)
        row, n = self._reference_row()
        pi, _, _ = llr_stats.unpack(np.asarray(row, dtype=float), self._p)
        if n <= self._p or not bool(llr_stats.well_conditioned(pi, self._min_exc)):
            return math.nan
        return math.sqrt(llr_stats.segment_fit(np.asarray(row, dtype=float), n, self._p,
                                               None)[2])

    # -- state changes ----------------------------------------------------------------
    def reset(self) -> None:
        """Forget all data, counters and the reference (back to the constructed state)."""
        width = llr_stats.width(self._p)
        zero = (0.0,) * 6 if self._p == 2 else np.zeros(width)
        self._zero = zero
        self._rows = 0
        self._pos = 0
        self._last_t = -math.inf
        self._c = 0
        self._c_row = -1
        self._pref = zero
        self._rterm = [None] * self._L
        self._rpref = [None] * self._L
        self._rpref[0] = zero
        self._rrow = [0] * self._L
        self._rtime = [0.0] * self._L
        self._logpmin = 0.0
        self._kmin = 0
        self._ystar = 0.0
        self._last_y = math.nan
        self._counters = {name: 0 for name in COUNTER_NAMES}
        self._checks: list[int] = []
        self._cat: dict[str, Any] | None = None
        self._checkpoint = -1
        self._last_event: AnomalyEvent | None = None

    def update(self, t: float, speed: float, friction: float,
               aux: Mapping[str, float] | None = None) -> list[AnomalyEvent]:
        """Process one sample; return the events it triggers (usually none).

        Non-finite values (or a missing auxiliary channel of the model) and times not after
        the last accepted one are dropped and counted; they never enter the sums.
        """
        row = self._rows
        self._rows = row + 1
        try:
            t = float(t)
            w = float(speed)
            f = float(friction)
        except (TypeError, ValueError):
            self._counters['nonfinite'] += 1
            return []
        if (t - t) + (w - w) + (f - f) != 0.0:
            self._counters['nonfinite'] += 1
            return []
        if not (-self._max_w < w < self._max_w and -self._max_f < f < self._max_f):
            self._counters['out_of_range'] += 1
            return []
        if not t > self._last_t:
            self._counters['non_increasing_time'] += 1
            return []
        if self._default:
            # Inline copy of _add2 for the paper's model (one method call less per sample;
            # test_llr checks that both give the same events).
            self._last_t = t
            h1 = -1.0 if w > 0.0 else (1.0 if w < 0.0 else 0.0)
            h2 = -w
            ta = h1 * h1
            tb = h1 * h2
            tc = h2 * h2
            tu = h1 * f
            tv = h2 * f
            te = f * f
            P = self._pref
            P = (P[0] + ta, P[1] + tb, P[2] + tc, P[3] + tu, P[4] + tv, P[5] + te)
            self._pref = P
            j = self._pos
            self._pos = j + 1
            if j == 0:
                self._c_row = row
            L = self._L
            s = j % L
            self._rterm[s] = (ta, tb, tc, tu, tv, te)
            self._rrow[s] = row
            self._rtime[s] = t
            self._rpref[(j + 1) % L] = P
            events = self._revise(j) if j == self._checkpoint else []
            k = j - self._w + 1
            if k > self._c + self._w and self._test2(k, P):
                events.extend(self._declare(j))
            return events
        h = self._row(t, w, aux)
        if h is None:
            return []
        self._last_t = t
        return self.ingest_row(row, t, f, h)

    def ingest_row(self, row: int, t: float, f: float, h) -> list[AnomalyEvent]:
        """Process an accepted sample whose regressor row ``h`` is already computed.

        For :func:`detect_batch` with a model other than eq. (1): the rows are computed
        once for the whole file and validated there (finite, increasing time).
        """
        if self._p == 2:
            return self._add2(row, t, f, float(h[0]), float(h[1]))
        return self._update_general(row, t, f, np.asarray(h, dtype=float))

    def _add2(self, row: int, t: float, f: float, h1: float, h2: float
              ) -> list[AnomalyEvent]:
        """Add one accepted sample to the sums and ring, then test (p = 2)."""
        ta = h1 * h1
        tb = h1 * h2
        tc = h2 * h2
        tu = h1 * f
        tv = h2 * f
        te = f * f
        P = self._pref
        P = (P[0] + ta, P[1] + tb, P[2] + tc, P[3] + tu, P[4] + tv, P[5] + te)
        self._pref = P
        j = self._pos
        self._pos = j + 1
        if j == 0:
            self._c_row = row
        L = self._L
        s = j % L
        self._rterm[s] = (ta, tb, tc, tu, tv, te)
        self._rrow[s] = row
        self._rtime[s] = t
        self._rpref[(j + 1) % L] = P
        events = self._revise(j) if j == self._checkpoint else []
        k = j - self._w + 1
        if k > self._c + self._w and self._test2(k, P):
            events.extend(self._declare(j))
        return events

    def _test2(self, k: int, P: tuple) -> bool:
        """Algorithm 1 lines 9-18 at candidate ``k`` (p = 2); return True to declare.

        ``P`` is the prefix row at ``k + w`` (T_k), the one at ``k`` (P_k) is in the ring.
        Statistic: eq. (5) as ``d^T Pi_P d / sigma^2`` with ``d = x_T - x_P = Pi_T^-1 (q_W -
        Pi_W x_P)`` (the window's residual against the reference fit: no difference of
        two nearly equal estimates). Skips (counted) when ``Pi_P`` is ill-conditioned.
        """
        A, B, C, U, V, E = self._rpref[k % self._L]
        At, Bt, Ct, Ut, Vt, _ = P
        ac = A * C
        det = ac - B * B
        dett = At * Ct - Bt * Bt
        if det > self._min_exc * ac and dett > 0.0:
            x1 = (C * U - B * V) / det
            x2 = (A * V - B * U) / det
            if self._noise_var is None:
                n_p = k - self._c
                dof = float(n_p - 2)
                s2 = (E - (x1 * U + x2 * V)) / dof
                floor = llr_stats.NOISE_FLOOR_REL * E / n_p + llr_stats.NOISE_FLOOR_ABS
                if not s2 > floor:
                    s2 = floor
            else:
                s2 = self._noise_var
                dof = None
            Aw = At - A
            Bw = Bt - B
            Cw = Ct - C
            g1 = (Ut - U) - (Aw * x1 + Bw * x2)
            g2 = (Vt - V) - (Bw * x1 + Cw * x2)
            d1 = (Ct * g1 - Bt * g2) / dett
            d2 = (At * g2 - Bt * g1) / dett
            y = (A * d1 * d1 + 2.0 * B * d1 * d2 + C * d2 * d2) / s2
            tr = (Ct * Aw - 2.0 * Bt * Bw + At * Cw) / dett
            if tr > 0.0 and y > 0.0 and not y / tr < self._ystar:
                dm = (Aw * Cw - Bw * Bw) / dett
                logp = candidate_log_p2(y, tr, dm, self._logpmin, dof)
                if logp is not None and logp < self._logpmin:
                    self._record(k, logp)
        else:
            self._counters['ill_conditioned'] += 1
        return self._logpmin <= self._logr and k > self._kmin + self._kverif

    def _row(self, t: float, w: float, aux: Mapping[str, float] | None):
        if aux is not None:
            aux = {name: np.asarray([value], dtype=float) for name, value in aux.items()}
        try:
            h = self._regressors.matrix(np.asarray([w]), np.asarray([t]), aux)[0]
        except (KeyError, TypeError):
            self._counters['missing_aux'] += 1
            return None
        if not np.all(np.isfinite(h)):
            self._counters['nonfinite'] += 1
            return None
        return h

    def _record(self, k: int, logp: float) -> None:
        """Algorithm 1 lines 13-15: new smallest p_k."""
        self._logpmin = logp
        self._kmin = k
        self._ystar = skip_threshold(logp)

    def _prefix_block(self, first: int, last: int) -> np.ndarray:
        L = self._L
        return np.asarray([self._rpref[i % L] for i in range(first, last + 1)], dtype=float)

    def _declare(self, n: int) -> list[AnomalyEvent]:
        """Algorithm 1 lines 18-21: declare the change and restart the reference.

        The paper restarts at ``k_min``; here at ``max(tau, k_min)`` (``tau`` the refined
        change position), so that the new reference holds post-change samples only. The
        kind is re-checked on ``[tau, j]`` (the gap ``[tau, start)`` is kept as one
        prefix-sum row). Tests of the new reference whose window is already complete run
        at once (never, since the start is at or after ``k_min``; kept for safety).
        """
        L = self._L
        c, k_min = self._c, self._kmin
        first = max(c, k_min - self._w)
        prefix = self._prefix_block(first, n + 1)
        tau, start, kind, dx, z, s2, confirmed = declaration(prefix, first, c, k_min, n,
                                                             self._cfg, self._z_thr)
        rows = (self._rrow[tau % L], self._rrow[k_min % L], self._rrow[n % L])
        times = (self._rtime[tau % L], self._rtime[n % L])
        event = make_event(self._component, kind, rows, times, self._logpmin, dx, z, s2, 0,
                           confirmed)
        self._last_event = event
        self._cat = dict(before=prefix[tau - first].copy(), n_before=tau - c, kind=kind,
                         confirmed=confirmed, revision=0, rows=rows, time=times[0],
                         log_p=self._logpmin, start=tau,
                         gap=prefix[start - first] - prefix[tau - first])
        self._checks = checkpoints(tau, n, self._cfg['category_revisions'], self._w)
        self._checkpoint = self._checks.pop(0) if self._checks else -1
        self._restart(start, n)
        events = [event]
        test = self._test2 if self._p == 2 else self._test_general
        for k in range(start + self._w + 1, n - self._w + 2):
            if test(k, self._rpref[(k + self._w) % L]):
                events.extend(self._declare(n))
        return events

    def _restart(self, c: int, n: int) -> None:
        """Start the new reference at position ``c`` and rebuild its prefix sums."""
        L = self._L
        self._c = c
        self._c_row = self._rrow[c % L]
        P = self._zero
        self._rpref[c % L] = P
        for j in range(c, n + 1):
            t = self._rterm[j % L]
            if self._p == 2:
                P = (P[0] + t[0], P[1] + t[1], P[2] + t[2], P[3] + t[3], P[4] + t[4],
                     P[5] + t[5])
            else:
                P = P + t
            self._rpref[(j + 1) % L] = P
        self._pref = P
        self._logpmin = 0.0
        self._kmin = c
        self._ystar = 0.0

    def _revise(self, j: int) -> list[AnomalyEvent]:
        """Re-check the kind of the last declared change at a checkpoint."""
        cat = self._cat
        self._checkpoint = self._checks.pop(0) if self._checks else -1
        after = cat['gap'] + np.asarray(self._pref, dtype=float)
        kind, dx, z, s2, confirmed = llr_stats.categorise(
            cat['before'], cat['n_before'], after, self._p, self._noise_var, self._z_thr)
        if kind == cat['kind'] and (cat['confirmed'] or not confirmed):
            return []   # revision: new kind, or the same kind now confirmed
        cat['kind'] = kind
        cat['confirmed'] = confirmed
        cat['revision'] += 1
        rows = cat['rows'][:2] + (self._rrow[j % self._L],)
        times = (cat['time'], self._rtime[j % self._L])
        self._last_event = make_event(self._component, kind, rows, times, cat['log_p'], dx,
                                      z, s2, cat['revision'], confirmed)
        return [self._last_event]

    # -- general model (p > 2): numpy per sample -------------------------------------
    def _update_general(self, row: int, t: float, f: float, h: np.ndarray
                        ) -> list[AnomalyEvent]:
        term = np.concatenate([np.outer(h, h).ravel(), h * f, [f * f]])
        P = self._pref + term
        self._pref = P
        j = self._pos
        self._pos = j + 1
        if j == 0:
            self._c_row = row
        L = self._L
        s = j % L
        self._rterm[s] = term
        self._rrow[s] = row
        self._rtime[s] = t
        self._rpref[(j + 1) % L] = P
        events = self._revise(j) if j == self._checkpoint else []
        k = j - self._w + 1
        if k > self._c + self._w and self._test_general(k, P):
            events.extend(self._declare(j))
        return events

    def _test_general(self, k: int, P: np.ndarray) -> bool:
        """:meth:`_test2` for p > 2 (numpy; weights from the generalised eigenproblem)."""
        p = self._p
        self._last_y = math.nan
        pi_p, q_p, e = llr_stats.unpack(self._rpref[k % self._L], p)
        pi_t, q_t, _ = llr_stats.unpack(P, p)
        if bool(llr_stats.well_conditioned(pi_p, self._min_exc)):
            n_p = k - self._c
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
            # lambda_max >= tr / p, so b = y / (2 lambda_max) <= p y / (2 tr).
            if tr > 0.0 and y > 0.0 and not p * y / (2.0 * tr) < self._ystar:
                lam = np.sort(np.clip(linalg.eigh(pi_w, pi_t, eigvals_only=True), 0.0, 1.0))
                # Dropping all but the two largest terms gives a lower bound of the tail.
                two = (log_sf2(y, lam[-1], lam[-2]) if dof is None
                       else log_sf2_t(y, lam[-1], lam[-2], dof))
                if not two > self._logpmin + 1e-9 * (1.0 - self._logpmin):
                    logp = gchi2_logsf_general(y, lam, None, dof)[0]
                    if logp < self._logpmin:
                        self._record(k, logp)
        else:
            self._counters['ill_conditioned'] += 1
        return self._logpmin <= self._logr and k > self._kmin + self._kverif


def candidate_log_p2(y: float, tr: float, dm: float, log_p_min: float,
                     dof: float | None = None) -> float | None:
    """Return log p_k (eq. (7), Algorithm 2) if it may be below ``log_p_min``, else None.

    ``y = LLR_k / sigma^2``; ``tr`` and ``dm`` are the trace and determinant of ``Pi_T^-1
    Pi_W`` (``Pi_W = Pi_T - Pi_P``), whose eigenvalues are those of Lemma 1's ``I -
    Pi_P^1/2 Pi_T^-1 Pi_P^1/2`` (similar matrices). ``dof``: residual degrees of freedom
    of the estimated noise variance (studentised tail, :func:`log_sf2_t`), None when the
    noise level is given (Lemma 1's tail, :func:`log_sf2`). With ``b = y / (2 l1)``, ``rho =
    l2 / l1`` and ``a = b (1 - rho)``, ``p_k >= exp(-b rho) erfc(sqrt(a))`` (drop ``rho
    sin^2`` in the integral of :mod:`rwa_monitor.core.gchi2`), and the studentised
    analogue below; when the bound already exceeds ``p_min`` the sample cannot be a new
    minimum and the exact tail is not computed. Shared by the streaming and the batch path
    (same floats, same decision).
    """
    half = 0.5 * tr
    disc = half * half - dm
    lam1 = half + math.sqrt(disc) if disc > 0.0 else half
    lam2 = dm / lam1
    if lam2 < 0.0:
        lam2 = 0.0
    b = y / (2.0 * lam1)
    rho = lam2 / lam1
    a = b * (1.0 - rho)
    if dof is None:
        lower = -b * rho + log_lower_bound(a)
    else:
        # Studentised: h <= tan^2 and (1 + u)^-m >= exp(-m u) give p_k >= (1 + 2 b /
        # dof)^(-dof/2) exp(A) erfc(sqrt(A)), A = dof a / (dof + 2 b) (tighter than the
        # Gaussian bound, which also holds).
        big_a = dof * a / (dof + 2.0 * b)
        lower = -0.5 * dof * math.log1p(2.0 * b / dof) + big_a + log_lower_bound(big_a)
    if lower > log_p_min + 1e-9 * (1.0 - log_p_min):
        return None
    if dof is None:
        return log_sf2(y, lam1, lam2)
    return log_sf2_t(y, lam1, lam2, dof)


def detect_batch(time, speed, friction, *, component: str = 'rw1',
                 aux: Mapping[str, np.ndarray] | None = None, **params: Any
                 ) -> list[AnomalyEvent]:
    """Run Algorithm 1 over whole arrays; same events as streaming (see llr_batch)."""
    from rwa_monitor.core.llr_batch import detect_batch as run
    return run(time, speed, friction, component=component, aux=aux, **params)
