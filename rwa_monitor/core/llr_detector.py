"""The LLR friction-anomaly detector of one wheel (llr-realtime paper, Algorithm 1 and 2).

:class:`LLRDetector` owns the state: the compiled kernel's two arrays (core/llr_layout.py:
positions, prefix sums, rings of the last samples, counters), the noise model and
:class:`rwa_monitor.core.llr_changes.DeclaredChange`. Its per-sample logic is written
once: the kernel for the paper's model (eq. (1)), :mod:`rwa_monitor.core.llr_general`
for larger models, :mod:`rwa_monitor.core.llr_changes` for declarations and kinds.
``update`` runs it one sample at a time, ``process_arrays`` over whole arrays (the loop
compiled); both give the same events.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import llr_calibrated_step as calibrated, llr_cstep
from rwa_monitor.core import llr_kernel as kern, llr_layout as layout, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import RegressorSet
from rwa_monitor.core.llr_changes import ChangeRules, DeclaredChange
from rwa_monitor.core.llr_common import COUNTER_NAMES, validate_parameters, window_statistics
from rwa_monitor.core.llr_general import GeneralModel
from rwa_monitor.core.llr_noise import NoiseFitting, NoiseModel
from rwa_monitor.core.params import AUTO

_KERNEL_COUNTERS = (('non_finite', layout.I_NON_FINITE), ('out_of_range', layout.I_OUT_OF_RANGE),
                    ('non_increasing_time', layout.I_NON_INCREASING),
                    ('ill_conditioned', layout.I_ILL))
_step = kern.step
_step_calibrated = calibrated.step_calibrated
_C_CALL = llr_cstep.available()


class LLRDetector(ChangeRules, GeneralModel, NoiseFitting, llr_cstep.StepOwner):
    """Streaming LLR detector of friction changes for one wheel (Algorithm 1).

    Parameters
    ----------
    component : str
        Wheel id, copied into the events.
    window : int
        Look-ahead window w in samples (>= 10).
    k_verif : int or 'auto'
        Verification samples in ``[0, window - 1]``; ``'auto'``: ``window // 2``.
    false_alarm_rate : float
        r in (0, 1): a change is declared when p_min <= r.
    noise_std : float or 'auto'
        Noise standard deviation (N m); ``'auto'``: estimated on the reference.
    regressors : RegressorSet or None
        Friction model; None: the paper's eq. (1).
    min_excitation : float
        Smallest ``det(corr(Pi_P))`` in [0, 1); below it the test is skipped and counted
        as ``ill_conditioned``.
    category_level : float
        Level of each dry / viscous test (None: r).
    category_revisions : int
        Re-checks of the kind as data arrive.
    refine_change : bool
        Maximum-likelihood refinement of the change time.
    max_abs_speed, max_abs_friction : float
        Samples at or beyond are dropped and counted as ``out_of_range``; default 1e5
        rad/s and 1e3 N m (core/schema.py).
    noise_ar_max_order : int or 'auto'
        Largest order of the autoregressive noise model fitted on the first
        ``noise_fit_samples`` accepted samples and used to prewhiten the data; 'auto': 3
        with an estimated noise level, 0 (white noise, as in the paper) with ``noise_std``.
    noise_fit_samples : int or 'auto'
        Samples of that fit; 'auto': ``2 window + 1``.
    reference_max : int or None
        0 or None: the reference grows from its start as in the paper; else at most that
        many samples before the window (a sliding reference following slow drifts).
    noise_speed_model : bool
        Model the noise level against ``|w|`` on the fit segment and use it as weights.

    The algorithm, its departures from the paper and the categorisation are in docs/llr.md
    ("Noise beyond white", "Slow drifts", "Noise growing with speed"). Positions count
    accepted samples; events carry the row index (``update`` calls before that sample
    since construction or reset). Rejected samples are counted in :attr:`counters`
    (``non_finite``, ``out_of_range``, ``non_increasing_time``, ``missing_aux``,
    ``ill_conditioned``).

    Returns
    -------
    :meth:`update` returns the list of :class:`AnomalyEvent` a sample triggers (usually
    empty): a declaration (``revision`` 0) or a revision of the kind of the last one.

    Examples
    --------
    >>> import numpy as np
    >>> from rwa_monitor.core.llr import LLRDetector
    >>> rng = np.random.default_rng(0)
    >>> n = 4000
    >>> t = np.arange(n) * 0.1
    >>> w = 50.0 * np.sin(2 * np.pi * t / 100.0)
    >>> dry = np.where(np.arange(n) < 2000, 1.0, 1.5)
    >>> f = -dry * np.sign(w) - 0.05 * w + 0.1 * rng.standard_normal(n)
    >>> det = LLRDetector('rw1', window=200)
    >>> events = [e for row in zip(t, w, f) for e in det.update(*row)]
    >>> first = events[0]
    >>> first.revision, abs(first.index - 2000) < 200
    (0, True)
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
        self._p = cfg['regressors'].p
        self._default = cfg['regressors'].is_coulomb_viscous
        self._min_exc = cfg['min_excitation']
        self._z_thr = llr_stats.z_threshold(cfg['category_level'])
        self._R = cfg['reference_max']
        # Ring of the last accepted samples (a power of two: the kernel indexes it by mask).
        self._L = 1 << (2 * self._w + self._kverif + 1 + (self._R or 0)).bit_length()
        self._ar_max = cfg['noise_ar_max_order']
        self._fit_n = cfg['noise_fit_samples']
        self._speed_model = cfg['noise_speed_model']
        self.reset()

    # -- read-only state --------------------------------------------------------------
    @property
    def params(self) -> dict[str, Any]:
        """Validated keyword parameters, defaults filled in (core/protocol.py)."""
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
        return int(self._ints[layout.I_ROWS])

    @property
    def n_accepted(self) -> int:
        """Accepted samples: in the sums, or waiting for the noise fit."""
        return int(self._ints[layout.I_POS]) + len(self._buffer)

    @property
    def counters(self) -> dict[str, int]:
        """Rejected samples and skipped tests by reason."""
        counters = dict(self._counters)
        for name, slot in _KERNEL_COUNTERS:
            counters[name] += int(self._ints[slot])
        return counters

    @property
    def p_min(self) -> float:
        """Smallest p_k since the reference start (Algorithm 1 line 14), 1 before any."""
        return math.exp(self.log_p_min)

    @property
    def log_p_min(self) -> float:
        """Natural logarithm of :attr:`p_min` (never underflows)."""
        return float(self._fs[layout.F_LOGPMIN])

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
        pp = (self._rings().pref[k % self._L] - base)[:, None]
        pt = (self._prefix_now() - base)[:, None]
        ok, _, y, *_ = window_statistics(pp, pt, np.array([float(n_p)]), cfg)
        return float(y[0]) if ok[0] else math.nan

    @property
    def reference_start_index(self) -> int:
        """Row index where the current reference segment starts (-1 if no sample yet)."""
        return int(self._ints[layout.I_C_ROW])

    @property
    def noise_model(self) -> NoiseModel | None:
        """Autoregressive noise model in use (None while fitting or when white by setting)."""
        return self._noise

    @property
    def estimate(self) -> np.ndarray:
        """Least-squares ``x`` (``[f_c, f_v, ...]``) over the reference segment P_k.

        P_k of the latest test, or all samples since the reference start before the first
        test; nan while not identifiable.
        """
        row, n = self._reference_row()
        pi, q, _ = llr_stats.unpack(row, self._p)
        if n <= self._p or not bool(llr_stats.well_conditioned(pi, self._min_exc)):
            return np.full(self._p, np.nan)
        return np.linalg.solve(pi, q)

    @property
    def noise_std(self) -> float:
        """Noise standard deviation in use (given, or estimated on the reference)."""
        if self._noise_var is not None:
            return math.sqrt(self._noise_var)
        row, n = self._reference_row()
        pi, _, _ = llr_stats.unpack(row, self._p)
        if n <= self._p or not bool(llr_stats.well_conditioned(pi, self._min_exc)):
            return math.nan
        return math.sqrt(llr_stats.segment_fit(row, n, self._p, None)[2])

    def _latest_k(self) -> int:
        """Return the candidate k of the latest test of the current reference, or -1."""
        k = int(self._ints[layout.I_POS]) - self._w
        return k if k > int(self._ints[layout.I_C]) + self._w else -1

    def _reference_row(self) -> tuple[np.ndarray, int]:
        k = self._latest_k()
        if k > int(self._ints[layout.I_C]):
            base, n_p = self._base(k)
            return self._rings().pref[k % self._L] - base, n_p
        return self._prefix_now(), int(self._ints[layout.I_POS]) - int(self._ints[layout.I_C])

    # -- state changes ----------------------------------------------------------------
    def reset(self) -> None:
        """Forget all data, counters and the reference (back to the constructed state)."""
        p2 = self._p == 2
        # Per-sample state (core/llr_layout.py allocate): scalars, then rings of the last
        # L accepted samples: prefix rows, terms ((h1, h2, f) for p = 2), times, rows.
        self._fs, self._ints = layout.allocate(self._L, llr_stats.width(self._p),
                                               3 if p2 else llr_stats.width(self._p),
                                               self._ar_max if p2 else 0)
        fs, ints = self._fs, self._ints
        fs[layout.F_LAST_T] = -math.inf
        fs[layout.F_LOGR] = self._logr
        fs[layout.F_MIN_EXC] = self._min_exc
        fs[layout.F_NOISE_VAR] = math.nan if self._noise_var is None else self._noise_var
        fs[layout.F_MAX_W] = self._cfg['max_abs_speed']
        fs[layout.F_MAX_F] = self._cfg['max_abs_friction']
        fs[layout.F_FLOOR_REL] = llr_stats.NOISE_FLOOR_REL
        fs[layout.F_FLOOR_ABS] = llr_stats.NOISE_FLOOR_ABS
        ints[layout.I_W] = self._w
        ints[layout.I_KVERIF] = self._kverif
        ints[layout.I_R] = -1 if self._R is None else self._R
        ints[layout.I_ESTIMATED] = self._noise_var is None
        ints[layout.I_C_ROW] = -1
        ints[layout.I_CHECKPOINT] = -1
        self._pref_general = None if p2 else np.zeros(llr_stats.width(self._p))
        self._last_y = math.nan
        self._counters = {name: 0 for name in COUNTER_NAMES}
        self._cat: DeclaredChange | None = None
        self._noise: NoiseModel | None = None
        self._speed_std: tuple[float, float, float] | None = None
        self._wlow = math.inf
        self._whigh = 0.0
        self._next_fit: int | None = None
        self._lags: list[tuple[Any, ...]] = []
        self._ar: tuple[float, ...] = ()
        self._fitting = self._ar_max > 0 or self._speed_model
        self._buffer: list[tuple[int, float, float, Any, float]] = []
        self._fast = self._default and not self._fitting
        self._last_event: AnomalyEvent | None = None
        self._arm_step()

    def _arm_step(self) -> None:
        """Arm the C call of the step on the state arrays while the fast path holds.

        Called by :meth:`reset` (new arrays) and by the Python :meth:`update` when it finds
        the fast path unarmed (after the noise fit, a copy or a restored state).
        """
        address = llr_cstep.step_address() if self._fast else None
        if address is None:
            self._step_disarm()
        else:
            self._step_arm(address, self._fs, self._ints)

    def __getstate__(self) -> dict[str, Any]:
        """Return the instance attributes (copy, pickle): the C base holds no state."""
        return dict(self.__dict__)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Set the instance attributes, then arm the C call on the arrays set."""
        self.__dict__.update(state)
        self._arm_step()

    def update(self, t: float, speed: float, friction: float,
               aux: Mapping[str, float] | None = None) -> list[AnomalyEvent]:
        """Process one sample; return the events it triggers (usually none).

        Non-finite values (or a missing auxiliary channel of the model) and times not after
        the last accepted one are dropped and counted; they never enter the sums. On the
        fast path with three floats the call is handled in C (core/llr_cstep.py), the
        same compiled step; this Python method is the path of every other call.
        """
        if self._fast:
            # The paper's model: one compiled call per sample (core/llr_kernel.py step),
            # which takes Python and numpy numbers as floats; others are converted first.
            if _C_CALL and not self._step_armed():
                self._arm_step()
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
        self._fs[layout.F_LAST_T] = t
        return self.ingest_row(row, t, f, h, w)

    update = llr_cstep.compiled_update(update, '_after')

    def process_arrays(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray
                       ) -> list[AnomalyEvent]:
        """Process whole arrays as :meth:`update` would, row by row; return the events.

        Parameters
        ----------
        time, speed, friction : numpy.ndarray
            1-D float arrays of the same length.

        Returns
        -------
        list of AnomalyEvent
            The events of :meth:`update` on the same rows. For the paper's model the
            per-sample loop runs compiled (core/llr_kernel.py ``run``); Python runs only at
            the samples whose flags need it and while the noise model is fitted.
        """
        t, w, f = (np.ascontiguousarray(a, dtype=float) for a in (time, speed, friction))
        events: list[AnomalyEvent] = []
        i, n = 0, t.size
        while i < n:
            if self._fast:
                i = kern.run(self._fs, self._ints, t, w, f, i)
                if i < n:
                    events.extend(self._after(int(self._ints[layout.I_FLAGS])))
            elif self._default and self._fitting and not self._speed_model:
                i = self._buffer_arrays(t, w, f, i)
                if len(self._buffer) >= self._fit_n:
                    events.extend(self._fit_and_replay())
                continue
            else:
                events.extend(self.update(float(t[i]), float(w[i]), float(f[i])))
            i += 1
        return events

    def update_nominal(self, table: np.ndarray, t: float, speed: float, friction: float
                       ) -> list[AnomalyEvent]:
        """Process one calibrated sample: ``update(t, speed, friction - nominal(speed))``.

        ``table``: a wheel's nominal lookup (core/calibrate.py ``NominalWheel.table``, which
        counts the samples not tested; their residual is NaN, dropped and counted here as
        non-finite, as through ``NominalWheel.residual_one``). The lookup and the sample
        are one compiled call (core/llr_calibrated_step.py ``step_calibrated``); same events.
        """
        if self._fast:
            try:
                flags = _step_calibrated(self._fs, self._ints, table, t, speed, friction)
            except TypeError:
                pass
            else:
                return self._after(flags) if flags else []
        try:
            residual = calibrated.nominal_residual(table, float(t), float(speed), float(friction))
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
            self._ints[layout.I_ROWS] += 1
            self._counters['non_finite'] += 1
            return None

    def _row(self, t: float, w: float, aux: Mapping[str, float] | None) -> np.ndarray | None:
        """Return the regressor row of one sample, or None (missing channel, non-finite)."""
        if aux is not None:
            aux = {name: np.asarray([value], dtype=float) for name, value in aux.items()}
        try:
            h = self._cfg['regressors'].matrix(np.asarray([w]), np.asarray([t]), aux)[0]
        except (KeyError, TypeError):
            self._counters['missing_aux'] += 1
            return None
        if not np.all(np.isfinite(h)):
            self._counters['non_finite'] += 1
            return None
        return h
