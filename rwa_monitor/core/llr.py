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

from rwa_monitor.core import llr_batch, llr_kernel as kern, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import RegressorSet
from rwa_monitor.core.gchi2 import (gchi2_logsf_general, log_sf2, log_sf2_t,
                                    skip_threshold)
from rwa_monitor.core.llr_common import (candidate_log_p2, checkpoints, COUNTER_NAMES,
                                         declaration, fit_noise_model, make_event,
                                         NoiseModel, ramp_points, reference_base,
                                         revision_due, speed_fit_done, speed_fit_ready,
                                         speed_scale, validate_parameters,
                                         window_statistics)
from rwa_monitor.core.params import AUTO

_INF = math.inf
_PREF = slice(kern.F_PREF, kern.F_PREF + 6)
_step = kern.step
_step_calibrated = kern.step_calibrated
_KERNEL_COUNTERS = (('nonfinite', kern.I_NONFINITE), ('out_of_range', kern.I_OUT_OF_RANGE),
                    ('non_increasing_time', kern.I_NON_INCREASING),
                    ('ill_conditioned', kern.I_ILL))

__all__ = ['candidate_log_p2', 'COUNTER_NAMES', 'detect_batch', 'detect_batch_with_counters',
           'LLRDetector', 'NoiseModel', 'validate_parameters']


class _Column:
    """A 1-D ring of the kernel's state read as Python scalars (row indices, times)."""

    __slots__ = ('_values',)

    def __init__(self, values: np.ndarray) -> None:
        self._values = values

    def __len__(self) -> int:
        return len(self._values)

    def __getitem__(self, i: int) -> Any:
        return self._values[i].item()

    def __setitem__(self, i: int, value: Any) -> None:
        self._values[i] = value


def _int_slot(slot: int) -> property:
    """Return an attribute that reads and writes ``self._ints[slot]`` (kernel state)."""
    return property(lambda self: int(self._ints[slot]),
                    lambda self, v: self._ints.__setitem__(slot, v))


def _float_slot(slot: int) -> property:
    """Return an attribute that reads and writes ``self._fs[slot]`` (kernel state)."""
    return property(lambda self: float(self._fs[slot]),
                    lambda self, v: self._fs.__setitem__(slot, v))


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
    default 1e6 rad/s and 1e6 N m), ``noise_ar_max_order`` (largest order of the
    autoregressive noise model fitted on the first ``noise_fit_samples`` accepted samples
    and used to prewhiten the data; default 3 with an estimated noise level, 0 = white
    noise as in the paper), ``reference_max`` (None: the reference grows from its start as
    in the paper; else at most that many samples before the window: a sliding reference
    that follows slow drifts of the nominal friction), ``noise_speed_model`` (True: the
    noise level is modelled against ``|w|`` on the fit segment, extended until the speed
    varies, and used as weights; docs/llr.md "Noise growing with speed"). Positions count
    accepted samples;
    events carry the row index (number of ``update`` calls before that sample since
    construction or reset). docs/llr.md "Noise beyond white" and "Slow drifts".
    """

    def __init__(self, component: str = 'rw1', *, window: int = 500,
                 k_verif: int | str = AUTO, false_alarm_rate: float = 1e-5,
                 noise_std: float | str = AUTO, regressors: RegressorSet | None = None,
                 min_excitation: float = 1e-6, category_level: float = 1e-3,
                 category_revisions: int = 3, refine_change: bool = True,
                 max_abs_speed: float = 1e5, max_abs_friction: float = 1e3,
                 noise_ar_max_order: int | str = AUTO, noise_fit_samples: int | str = AUTO,
                 reference_max: int | None = 0, noise_speed_model: bool = False) -> None:
        self._cfg = validate_parameters(
            component, window=window, k_verif=k_verif, false_alarm_rate=false_alarm_rate,
            noise_std=noise_std, regressors=regressors, min_excitation=min_excitation,
            category_level=category_level, category_revisions=category_revisions,
            refine_change=refine_change, max_abs_speed=max_abs_speed,
            max_abs_friction=max_abs_friction, noise_ar_max_order=noise_ar_max_order,
            noise_fit_samples=noise_fit_samples, reference_max=reference_max,
            noise_speed_model=noise_speed_model)
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
        self._R = cfg['reference_max']
        self._L = 2 * self._w + self._kverif + 2 + (self._R or 0)
        self._ar_max = cfg['noise_ar_max_order']
        self._fit_n = cfg['noise_fit_samples']
        self._speed_model = cfg['noise_speed_model']
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
        counters = dict(self._counters)
        ints = self._ints
        for name, slot in _KERNEL_COUNTERS:
            counters[name] += int(ints[slot])
        return counters

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
        cfg = {'min_excitation': self._min_exc,
               'noise_std': None if self._noise_var is None else math.sqrt(self._noise_var)}
        base, n_p = self._base(k)
        pp = (np.asarray(self._rpref[k % self._L], dtype=float) - base)[:, None]
        pt = (np.asarray(self._pref, dtype=float) - base)[:, None]
        ok, _, y, *_ = window_statistics(pp, pt, np.array([float(n_p)]), cfg)
        return float(y[0]) if ok[0] else math.nan

    def _base(self, k: int) -> tuple[np.ndarray, int]:
        """Return the prefix row where P_k starts and the length of P_k."""
        if self._R is not None and k - self._R > self._c:
            return np.asarray(self._rpref[(k - self._R) % self._L], dtype=float), self._R
        return np.zeros(llr_stats.width(self._p)), k - self._c

    def _latest_k(self) -> int:
        """Return the candidate k of the latest test of the current reference, or -1."""
        k = self._pos - self._w
        return k if k > self._c + self._w else -1

    @property
    def reference_start_index(self) -> int:
        """Row index where the current reference segment starts (-1 if no sample yet)."""
        return self._c_row

    @property
    def noise_model(self) -> NoiseModel | None:
        """Autoregressive noise model in use (None while fitting or when white by setting)."""
        return self._noise

    def _reference_row(self) -> tuple[Any, int]:
        k = self._latest_k()
        if k > self._c:
            base, n_p = self._base(k)
            return np.asarray(self._rpref[k % self._L], dtype=float) - base, n_p
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
        # The state of the per-sample path lives in two arrays (core/llr_kernel.py); the
        # attributes below that name it (_pos, _c, _pref, the rings...) are views of them.
        fs, ints = kern.allocate(self._L, width, 3 if self._p == 2 else width,
                                 self._ar_max if self._p == 2 else 0)
        self._fs, self._ints = fs, ints
        fs[kern.F_LAST_T] = -math.inf
        fs[kern.F_LOGR] = self._logr
        fs[kern.F_MIN_EXC] = self._min_exc
        fs[kern.F_NOISE_VAR] = math.nan if self._noise_var is None else self._noise_var
        fs[kern.F_MAX_W] = self._max_w
        fs[kern.F_MAX_F] = self._max_f
        fs[kern.F_FLOOR_REL] = llr_stats.NOISE_FLOOR_REL
        fs[kern.F_FLOOR_ABS] = llr_stats.NOISE_FLOOR_ABS
        ints[kern.I_W] = self._w
        ints[kern.I_KVERIF] = self._kverif
        ints[kern.I_R] = -1 if self._R is None else self._R
        ints[kern.I_ESTIMATED] = self._noise_var is None
        ints[kern.I_C_ROW] = -1
        ints[kern.I_CHECKPOINT] = -1
        self._pref_general = zero
        # Rings of the last L accepted samples: (h1, h2, f) for p = 2 (a restart recomputes
        # the same products from them) or the terms for p > 2; prefix rows; row index; time.
        L = self._L
        self._rpref = fs[ints[kern.I_O_RPREF]:ints[kern.I_O_RTERM]].reshape(L, width)
        self._rterm = fs[ints[kern.I_O_RTERM]:ints[kern.I_O_RTIME]].reshape(L, -1)
        self._rtime = _Column(fs[ints[kern.I_O_RTIME]:ints[kern.I_O_AR]])
        self._rrow = _Column(ints[kern.I_SCALARS:])
        self._last_y = math.nan
        self._counters = {name: 0 for name in COUNTER_NAMES}
        self._checks: list[int] = []
        self._cat: dict[str, Any] | None = None
        self._noise: NoiseModel | None = None
        self._speed_std: tuple[float, float, float] | None = None
        self._wlow = math.inf
        self._whigh = 0.0
        self._next_fit: int | None = None
        self._lags: list[tuple[Any, ...]] = []
        self._ar: tuple[float, ...] = ()
        self._fitting = self._ar_max > 0 or self._speed_model
        self._buffer: list[tuple[int, float, float, Any]] = []
        self._fast = self._default and not self._fitting
        self._last_event: AnomalyEvent | None = None

    # Scalars of the per-sample state (views of the kernel's arrays).
    _rows = _int_slot(kern.I_ROWS)
    _pos = _int_slot(kern.I_POS)
    _c = _int_slot(kern.I_C)
    _c_row = _int_slot(kern.I_C_ROW)
    _kmin = _int_slot(kern.I_KMIN)
    _checkpoint = _int_slot(kern.I_CHECKPOINT)
    _last_t = _float_slot(kern.F_LAST_T)
    _logpmin = _float_slot(kern.F_LOGPMIN)
    _ystar = _float_slot(kern.F_YSTAR)

    @property
    def _pref(self) -> Any:
        """Prefix sums of the reference up to the last sample (a tuple for p = 2)."""
        if self._p == 2:
            return tuple(self._fs[_PREF].tolist())
        return self._pref_general

    @_pref.setter
    def _pref(self, value: Any) -> None:
        if self._p == 2:
            self._fs[_PREF] = value
        else:
            self._pref_general = value

    def update(self, t: float, speed: float, friction: float,
               aux: Mapping[str, float] | None = None) -> list[AnomalyEvent]:
        """Process one sample; return the events it triggers (usually none).

        Non-finite values (or a missing auxiliary channel of the model) and times not after
        the last accepted one are dropped and counted; they never enter the sums.
        """
        if self._fast:
            # The paper's model (whitened when an AR noise model is fitted): one compiled
            # call per sample (core/llr_kernel.py step), which takes Python and numpy
            # numbers as floats; anything else is converted here first.
            try:
                flags = _step(self._fs, self._ints, t, speed, friction)
            except TypeError:
                return self._update_converted(t, speed, friction)
            return self._after(flags) if flags else []
        values = self._floats(t, speed, friction)
        if values is None:
            return []
        t, w, f = values
        row = kern.accept(self._fs, self._ints, t, w, f)
        if row < 0:
            return []
        if self._default:
            h = (-1.0 if w > 0.0 else (1.0 if w < 0.0 else 0.0), -w)
        else:
            h = self._row(t, w, aux)
            if h is None:
                return []
        self._last_t = t
        return self.ingest_row(row, t, f, h, w)

    def update_nominal(self, table: np.ndarray, t: float, speed: float, friction: float
                       ) -> list[AnomalyEvent]:
        """Process one calibrated sample: ``update(t, speed, friction - nominal(speed))``.

        ``table``: a wheel's nominal lookup (core/calibrate.py ``NominalWheel.table``, which
        counts the samples not tested; their residual is NaN, dropped and counted here as
        non-finite, as through ``NominalWheel.residual_one``). The lookup and the sample
        are one compiled call (core/llr_kernel.py ``step_calibrated``); same events.
        """
        if self._fast:
            try:
                flags = _step_calibrated(self._fs, self._ints, table, t, speed, friction)
            except TypeError:
                pass
            else:
                return self._after(flags) if flags else []
        try:
            residual = kern.nominal_residual(table, float(t), float(speed), float(friction))
        except (TypeError, ValueError):
            return self.update(t, speed, friction)
        return self.update(t, speed, residual)

    def _update_converted(self, t: Any, speed: Any, friction: Any) -> list[AnomalyEvent]:
        """:meth:`update` of the fast path for values the kernel does not take as floats."""
        values = self._floats(t, speed, friction)
        if values is None:
            return []
        flags = _step(self._fs, self._ints, *values)
        return self._after(flags) if flags else []

    def _floats(self, t: Any, speed: Any, friction: Any) -> tuple[float, float, float] | None:
        """Return the sample as floats, or None (counted as a non-finite row)."""
        try:
            return float(t), float(speed), float(friction)
        except (TypeError, ValueError):
            self._ints[kern.I_ROWS] += 1
            self._counters['nonfinite'] += 1
            return None

    def _after(self, flags: int) -> list[AnomalyEvent]:
        """Act on the flags of a kernel call: revise, finish the test, declare."""
        j = self._pos - 1
        events = self._revise(j) if flags & kern.REVISE else []
        if flags & kern.DECLARE or flags & kern.EXACT and self._exact():
            events.extend(self._declare(j))
        return events

    def _exact(self) -> bool:
        """Finish the test the kernel left at EXACT: eq. (7) tail, new minimum, decision."""
        fs, ints = self._fs, self._ints
        k = int(ints[kern.I_K])
        dof = int(ints[kern.I_DOF])
        logpmin = float(fs[kern.F_LOGPMIN])
        logp = candidate_log_p2(float(fs[kern.F_Y]), float(fs[kern.F_TR]),
                                float(fs[kern.F_DM]), logpmin,
                                None if dof < 0 else float(dof))
        if logp is not None and logp < logpmin:
            self._record(k, logp)
        return self._logpmin <= self._logr and k > self._kmin + self._kverif

    def ingest_row(self, row: int, t: float, f: float, h, speed: float) -> list[AnomalyEvent]:
        """Process an accepted sample whose regressor row ``h`` is already computed.

        For :func:`detect_batch` with a model other than eq. (1): the rows are computed
        once for the whole file and validated there (finite, increasing time). While the
        noise model is being fitted the sample is buffered; once fitted the buffer is
        replayed, and every sample is prewhitened (divided by the modelled noise level at
        ``|speed|``, then AR-filtered) before it enters the sums.
        """
        if self._fitting:
            self._buffer.append((row, t, f, h, speed))
            if self._speed_model:
                aw = abs(speed)
                self._wlow = min(self._wlow, aw)
                self._whigh = max(self._whigh, aw)
                if self._next_fit is None:
                    if not speed_fit_ready(len(self._buffer), self._fit_n, self._wlow,
                                           self._whigh):
                        return []
                elif len(self._buffer) < self._next_fit:
                    return []
            elif len(self._buffer) < self._fit_n:
                return []
            return self._fit_and_replay()
        return self._ingest_fitted(row, t, f, h, speed)

    def _fit_and_replay(self) -> list[AnomalyEvent]:
        """Fit the noise model on the buffered samples, then process them."""
        buffer = self._buffer
        rows = np.array([np.asarray(item[3], dtype=float) for item in buffer])
        speeds = (np.abs(np.array([item[4] for item in buffer], dtype=float))
                  if self._speed_model else None)
        model = fit_noise_model(rows, np.array([item[2] for item in buffer]), self._ar_max,
                                speeds)
        if self._speed_model and not speed_fit_done(len(buffer), self._fit_n, model):
            self._next_fit = len(buffer) + self._fit_n
            return []
        self._buffer = []
        self._fitting = False
        self._noise = model
        self._ar = model.ar
        if self._p == 2:
            ints = self._ints
            ints[kern.I_AR_ORDER] = len(model.ar)
            self._fs[ints[kern.I_O_AR]:ints[kern.I_O_AR] + len(model.ar)] = model.ar
        self._speed_std = model.speed_std
        self._fast = self._default and self._speed_std is None
        events: list[AnomalyEvent] = []
        for row, t, f, h, w in buffer:
            events.extend(self._ingest_fitted(row, t, f, h, w))
        return events

    def _ingest_fitted(self, row: int, t: float, f: float, h, speed: float
                       ) -> list[AnomalyEvent]:
        if self._speed_std is not None:
            level = speed_scale(abs(speed), self._speed_std)
            f = f / level
            if self._p == 2:
                h = (float(h[0]) / level, float(h[1]) / level)
            else:
                h = np.asarray(h, dtype=float) / level
        if self._p == 2:
            flags = kern.ingest(self._fs, self._ints, row, t, f, float(h[0]), float(h[1]))
            return self._after(flags) if flags else []
        if self._ar:
            f, h = self._whiten(f, h)
        return self._update_general(row, t, f, np.asarray(h, dtype=float))

    def _whiten(self, f: float, h: np.ndarray) -> tuple[float, np.ndarray]:
        """Apply the AR filter ``v_l - sum_i a_i v_(l-1-i)`` to one sample (missing lags omitted).

        Same operations in the same order as :func:`llr_common.whiten` (batch path); p > 2
        (the paper's model is whitened in the kernel, core/llr_kernel.py ``ingest``).
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

    def _test2(self, k: int, P) -> bool:
        """Algorithm 1 lines 9-18 at candidate ``k`` (p = 2); return True to declare.

        ``P`` is the prefix row at ``k + w`` (T_k), the one at ``k`` (P_k) is in the ring:
        core/llr_kernel.py ``test`` (eq. (5)), then :meth:`_exact` when the skip bound does
        not rule ``k`` out. For a restart's catch-up; the per-sample path tests in the
        kernel call.
        """
        flags = kern.test_row(self._fs, self._ints, k, np.asarray(P, dtype=float))
        return bool(flags & kern.DECLARE) or bool(flags & kern.EXACT) and self._exact()

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
        at once (never, since the start is at or after ``k_min``; kept for safety). Not in
        the paper: a declaration that the previous change's growth explains
        (:meth:`_continues`, docs/llr.md "Kinds on ramps") is no new change: its kind is
        re-checked instead and the reference restarts as after any declaration.
        """
        L = self._L
        c, k_min = self._c, self._kmin
        first = max(c, k_min - self._w)
        base = reference_base(c, first, self._R)
        prefix = self._prefix_block(first, n + 1)
        if base != c:
            prefix = prefix - np.asarray(self._rpref[base % L], dtype=float)
        ramps: dict[int, np.ndarray] = {}

        def ramp_of(tau: int) -> np.ndarray:
            ramps[tau] = self._ramp_block(tau, n, self._rtime[tau % L])
            return ramps[tau]

        tau, start, cat = declaration(prefix, first, base, k_min, n, self._cfg, self._z_thr,
                                      ramp_of)
        if self._continues(tau, n):
            prev = self._cat
            events = self._recheck(n, prev['gap'] + np.asarray(self._pref, dtype=float))
            prev['gap'] = prev['gap'] + np.asarray(self._rpref[start % L], dtype=float)
            return events + self._restart_and_test(start, n)
        rows = (self._rrow[tau % L], self._rrow[k_min % L], self._rrow[n % L])
        times = (self._rtime[tau % L], self._rtime[n % L])
        event = make_event(self._component, cat, rows, times, self._logpmin, 0)
        self._last_event = event
        checks = checkpoints(tau, n, self._cfg['category_revisions'], self._w)
        self._cat = dict(before=prefix[tau - first].copy(), n_before=tau - base,
                         kind=cat.kind, guess=cat.guess, confirmed=cat.confirmed,
                         revision=0, rows=rows, time=times[0], log_p=self._logpmin, start=tau,
                         gap=prefix[start - first] - prefix[tau - first], checks=set(checks),
                         ramp=[ramps[tau]], ramp_end=n, ramp_t0=times[0])
        self._checks = ramp_points(n, checks, self._w)
        self._checkpoint = self._checks.pop(0) if self._checks else -1
        return [event] + self._restart_and_test(start, n)

    def _restart_and_test(self, start: int, n: int) -> list[AnomalyEvent]:
        """Restart the reference at ``start``; run the tests whose window is complete."""
        self._restart(start, n)
        events: list[AnomalyEvent] = []
        test = self._test2 if self._p == 2 else self._test_general
        for k in range(start + self._w + 1, n - self._w + 2):
            if test(k, self._rpref[(k + self._w) % self._L]):
                events.extend(self._declare(n))
        return events

    def _continues(self, tau: int, n: int) -> bool:
        """Return True if the change declared at ``n`` is the previous one still growing.

        Possible while the previous change's kind is still re-checked (its ramp sums are
        kept up to date): :func:`llr_stats.continues` on its segments up to ``n`` and on
        the samples ``[tau, n]``. If so, its ramp sums take in the samples up to ``n``.
        """
        prev = self._cat
        if prev is None or self._checkpoint < 0:
            return False
        L = self._L
        blocks = list(prev['ramp'])
        if prev['ramp_end'] < n:
            blocks.append(self._ramp_block(prev['ramp_end'] + 1, n, prev['ramp_t0']))
        after = prev['gap'] + np.asarray(self._pref, dtype=float)
        tail = self._terms(tau, n)
        times = np.asarray([self._rtime[j % L] for j in range(tau, n + 1)], dtype=float)
        if not llr_stats.continues(prev['before'], prev['n_before'], after,
                                   np.asarray(blocks), tail, times - prev['ramp_t0'],
                                   prev['kind'], self._p, self._noise_var, self._z_thr):
            return False
        prev['ramp'] = blocks
        prev['ramp_end'] = n
        return True

    def _ramp_block(self, first: int, last: int, t0: float) -> np.ndarray:
        """Return :func:`llr_stats.ramp_sums` of positions ``first..last`` (in the ring)."""
        L = self._L
        times = np.asarray([self._rtime[j % L] for j in range(first, last + 1)], dtype=float)
        return llr_stats.ramp_sums(self._terms(first, last), times - t0)

    def _terms(self, first: int, last: int) -> np.ndarray:
        """Return the per-sample terms of positions ``first..last`` (in the ring), ``(n, w)``.

        For p = 2 the ring holds ``(h1, h2, f)``: the six products are formed with numpy as
        the batch path forms them (``llr_batch._Terms``), so both get the same floats.
        """
        L = self._L
        rows = np.asarray([self._rterm[j % L] for j in range(first, last + 1)], dtype=float)
        if self._p != 2:
            return rows
        h1, h2, f = rows[:, 0], rows[:, 1], rows[:, 2]
        return np.column_stack((h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f))

    def _restart(self, c: int, n: int) -> None:
        """Start the new reference at position ``c`` and rebuild its prefix sums."""
        L = self._L
        self._c = c
        self._c_row = self._rrow[c % L]
        P = self._zero
        self._rpref[c % L] = P
        for j in range(c, n + 1):
            if self._p == 2:
                h1, h2, f = self._rterm[j % L]
                P = (P[0] + h1 * h1, P[1] + h1 * h2, P[2] + h2 * h2, P[3] + h1 * f,
                     P[4] + h2 * f, P[5] + f * f)
            else:
                P = P + self._rterm[j % L]
            self._rpref[(j + 1) % L] = P
        self._pref = P
        self._logpmin = 0.0
        self._kmin = c
        self._ystar = 0.0

    def _revise(self, j: int) -> list[AnomalyEvent]:
        """Take the new samples into the ramp sums; re-check the kind at a checkpoint.

        ``j`` is a point of :func:`llr_common.ramp_points`; the kind is re-checked only at
        the points of :func:`llr_common.checkpoints`.
        """
        cat = self._cat
        self._checkpoint = self._checks.pop(0) if self._checks else -1
        cat['ramp'].append(self._ramp_block(cat['ramp_end'] + 1, j, cat['ramp_t0']))
        cat['ramp_end'] = j
        if j not in cat['checks']:
            return []
        return self._recheck(j, cat['gap'] + np.asarray(self._pref, dtype=float))

    def _recheck(self, j: int, after: np.ndarray) -> list[AnomalyEvent]:
        """Re-check the kind of the last declared change on its after segment up to ``j``."""
        cat = self._cat
        new = llr_stats.categorise(cat['before'], cat['n_before'], after, self._p,
                                   self._noise_var, self._z_thr, np.asarray(cat['ramp']))
        if not revision_due(cat['kind'], cat['guess'], cat['confirmed'], new):
            return []
        cat['kind'] = new.kind
        cat['guess'] = new.guess
        cat['confirmed'] = new.confirmed
        cat['revision'] += 1
        rows = cat['rows'][:2] + (self._rrow[j % self._L],)
        times = (cat['time'], self._rtime[j % self._L])
        self._last_event = make_event(self._component, new, rows, times, cat['log_p'],
                                      cat['revision'])
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
        base, n_p = self._base(k)
        pi_p, q_p, e = llr_stats.unpack(self._rpref[k % self._L] - base, p)
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


def detect_batch(time, speed, friction, *, component: str = 'rw1',
                 aux: Mapping[str, np.ndarray] | None = None, **params: Any
                 ) -> list[AnomalyEvent]:
    """Run Algorithm 1 over whole arrays and return the events of the streaming detector.

    ``time``, ``speed``, ``friction``: 1-D arrays of the same length (one row per sample;
    event indices are row indices). Keyword parameters as :class:`LLRDetector`.
    """
    events, _ = detect_batch_with_counters(time, speed, friction, component=component,
                                           aux=aux, **params)
    return events


def detect_batch_with_counters(time, speed, friction, *, component: str = 'rw1',
                               aux: Mapping[str, np.ndarray] | None = None, **params: Any
                               ) -> tuple[list[AnomalyEvent], dict[str, int]]:
    """Return ``(events, counters)`` of :func:`detect_batch` (counters as the detector's).

    The paper's model runs vectorised (:mod:`rwa_monitor.core.llr_batch`); other regressor
    sets run the streaming engine on rows computed once.
    """
    cfg = validate_parameters(component, **params)
    t, w, f = llr_batch.as_arrays(time, speed, friction)
    if cfg['regressors'].is_coulomb_viscous:
        return llr_batch.detect_paper_model(t, w, f, cfg)
    return _streamed(t, w, f, aux, component, params)


def _streamed(t: np.ndarray, w: np.ndarray, f: np.ndarray,
              aux: Mapping[str, np.ndarray] | None, component: str,
              params: Mapping[str, Any]) -> tuple[list[AnomalyEvent], dict[str, int]]:
    """Run the streaming detector on precomputed rows (models other than eq. (1)).

    The regressor matrix is computed once for the whole file; acceptance follows the
    streaming order of checks (finite time, speed and friction; increasing time; finite
    row). If the model cannot be evaluated on the file (missing auxiliary channel), the
    rows are fed one by one through ``update`` instead.
    """
    det = LLRDetector(component, **params)
    aux_arrays = None
    if aux:
        aux_arrays = {}
        for name, values in aux.items():
            col = np.asarray(values, dtype=float)
            if col.shape != t.shape:
                raise ValueError(f'aux[{name!r}] must have the length of time ({t.size}), '
                                 f'got {col.size}')
            aux_arrays[name] = col
    try:
        with np.errstate(all='ignore'):
            h = det.parameters['regressors'].matrix(w, t, aux_arrays)
    except (KeyError, TypeError):
        return _row_by_row(det, t, w, f, aux_arrays)
    cfg = det.parameters
    accepted, counts = llr_batch.accepted_mask(t, w, f, cfg['max_abs_speed'],
                                               cfg['max_abs_friction'],
                                               np.all(np.isfinite(h), axis=1))
    events: list[AnomalyEvent] = []
    for i in np.flatnonzero(accepted):
        events.extend(det.ingest_row(int(i), float(t[i]), float(f[i]), h[i], float(w[i])))
    counters = det.counters
    for name, value in counts.items():
        counters[name] += value
    return events, counters


def _row_by_row(det: LLRDetector, t: np.ndarray, w: np.ndarray, f: np.ndarray,
                aux: Mapping[str, np.ndarray] | None
                ) -> tuple[list[AnomalyEvent], dict[str, int]]:
    names = list(aux) if aux else []
    events: list[AnomalyEvent] = []
    for i in range(t.size):
        row_aux = {name: float(aux[name][i]) for name in names} if aux else None
        events.extend(det.update(float(t[i]), float(w[i]), float(f[i]), row_aux))
    return events, det.counters
