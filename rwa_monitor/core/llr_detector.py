"""The LLR friction-anomaly detector of one wheel (llr-realtime paper, Algorithm 1 and 2).

:class:`LLRDetector` holds two things: its configuration (core/llr_config.py, the
parameters of core/schema.py checked and frozen) and its working state (core/llr_state.py
``Live``: the compiled kernel's two arrays, the records of the noise model, of the samples
waiting for its fit, of the p > 2 path and of the last declared change). Its parts are
functions that receive both: the kernel (core/llr_kernel.py) for the paper's model (eq.
(1)), core/llr_general.py for larger models, core/llr_samples.py for the noise fit and
prewhitening, core/llr_changes.py for declarations and kinds. ``update`` runs them one
sample at a time, ``process_arrays`` over whole arrays (for the paper's model the loop
compiled); both give the same events. ``state`` / ``restore`` save and resume it exactly.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import llr_calibrated_step as calibrated, llr_changes, llr_cstep
from rwa_monitor.core import llr_kernel as kern, llr_layout as layout, llr_readout
from rwa_monitor.core import llr_restore, llr_samples as samples, llr_state
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import RegressorSet
from rwa_monitor.core.llr_config import DEFAULTS, LLRConfig, numpydoc_parameters
from rwa_monitor.core.llr_noise import NoiseModel
from rwa_monitor.core.llr_state import LLRState

_KERNEL_COUNTERS = (('non_finite', layout.I_NON_FINITE), ('out_of_range', layout.I_OUT_OF_RANGE),
                    ('non_increasing_time', layout.I_NON_INCREASING),
                    ('ill_conditioned', layout.I_ILL))
_step = kern.step
_step_calibrated = calibrated.step_calibrated
_C_CALL = llr_cstep.available()


class LLRDetector(llr_cstep.StepOwner):
    """Streaming LLR detector of friction changes for one wheel (Algorithm 1).

    Parameters
    ----------
    component : str
        Wheel id, copied into the events.
    <the llr_detector parameters of core/schema.py>
    regressors : RegressorSet or None
        Friction model; None: the paper's eq. (1).

    The keyword parameters above are written from core/schema.py (docs/parameters.md);
    None stands for ``'auto'`` where a parameter has it. A bad value raises ValueError
    naming the parameter, an unknown name TypeError.

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

    __doc__ = __doc__.replace('    <the llr_detector parameters of core/schema.py>',
                              numpydoc_parameters())

    # The keywords are the schema's names with the schema's defaults; __init__ only
    # hands them to LLRConfig, which checks them against the schema (a keyword the schema
    # does not know is refused there, one the signature lacks takes the schema default).
    def __init__(self, component: str = 'rw1', *, window: int = DEFAULTS['window'],
                 k_verif: int | str = DEFAULTS['k_verif'],
                 false_alarm_rate: float = DEFAULTS['false_alarm_rate'],
                 noise_std: float | str = DEFAULTS['noise_std'],
                 category_level: float = DEFAULTS['category_level'],
                 category_revisions: int = DEFAULTS['category_revisions'],
                 refine_change: bool = DEFAULTS['refine_change'],
                 min_excitation: float = DEFAULTS['min_excitation'],
                 max_abs_speed: float = DEFAULTS['max_abs_speed'],
                 max_abs_friction: float = DEFAULTS['max_abs_friction'],
                 noise_ar_max_order: int | str = DEFAULTS['noise_ar_max_order'],
                 noise_fit_samples: int | str = DEFAULTS['noise_fit_samples'],
                 reference_max: int | None = DEFAULTS['reference_max'],
                 noise_speed_model: bool = DEFAULTS['noise_speed_model'],
                 regressors: RegressorSet | None = None) -> None:
        given = {name: value for name, value in locals().items()
                 if name not in ('self', 'component', 'regressors')}
        self._config = LLRConfig.from_parameters(component, regressors, **given)
        self.reset()

    # -- read-only state --------------------------------------------------------------
    @property
    def config(self) -> LLRConfig:
        """The checked parameters (frozen)."""
        return self._config

    @property
    def params(self) -> dict[str, Any]:
        """Validated keyword parameters, defaults filled in (core/protocol.py)."""
        return self._config.as_dict()

    @property
    def last_event(self) -> AnomalyEvent | None:
        """The latest event returned by :meth:`update` (declaration or revision), or None."""
        return self._live.last_event

    @property
    def component(self) -> str:
        """Wheel id."""
        return self._config.component

    @property
    def n_samples(self) -> int:
        """Number of ``update`` calls since construction or reset (accepted or not)."""
        return int(self._live.ints[layout.I_ROWS])

    @property
    def n_accepted(self) -> int:
        """Accepted samples: in the sums, or waiting for the noise fit."""
        live = self._live
        return live.position + (0 if live.fit is None else len(live.fit))

    @property
    def counters(self) -> dict[str, int]:
        """Rejected samples and skipped tests by reason."""
        counters = dict(self._live.counters)
        for name, slot in _KERNEL_COUNTERS:
            counters[name] += int(self._live.ints[slot])
        return counters

    @property
    def p_min(self) -> float:
        """Smallest p_k since the reference start (Algorithm 1 line 14), 1 before any."""
        return math.exp(self.log_p_min)

    @property
    def log_p_min(self) -> float:
        """Natural logarithm of :attr:`p_min` (never underflows)."""
        return float(self._live.floats[layout.F_LOGPMIN])

    @property
    def last_statistic(self) -> float:
        """Latest ``LLR_k / sigma^2`` (nan before the first test or if it was skipped)."""
        return llr_readout.last_statistic(self._live, self._config)

    @property
    def reference_start_index(self) -> int:
        """Row index where the current reference segment starts (-1 if no sample yet)."""
        return int(self._live.ints[layout.I_C_ROW])

    @property
    def noise_model(self) -> NoiseModel | None:
        """Autoregressive noise model in use (None while fitting or when white by setting)."""
        return self._live.noise

    @property
    def estimate(self) -> np.ndarray:
        """Least-squares ``x`` (``[f_c, f_v, ...]``) over the reference segment P_k.

        P_k of the latest test, or all samples since the reference start before the first
        test; nan while not identifiable.
        """
        return llr_readout.estimate(self._live, self._config)

    @property
    def noise_std(self) -> float:
        """Noise standard deviation in use (given, or estimated on the reference)."""
        return llr_readout.noise_std(self._live, self._config)

    # -- state ------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget all data, counters and the reference (back to the constructed state)."""
        self._install(llr_state.fresh(self._config))

    def state(self) -> LLRState:
        """Return the detector's state as a record (core/llr_state.py; a copy).

        ``records.encode`` writes it as JSON plus arrays; :meth:`restore` into a detector
        of the same parameters resumes exactly where this one stands.
        """
        return llr_state.snapshot(self._live, self._config)

    def restore(self, state: LLRState) -> None:
        """Resume from a record of :meth:`state`; RecordError (a ValueError) if it does not fit.

        The record must have been made with this detector's parameters and be consistent
        (core/llr_restore.py lists the checks); otherwise the error names the field and
        this detector is left as it was.
        """
        self._install(llr_restore.checked(state, self._config))

    def _install(self, live: llr_state.Live) -> None:
        self._live = live
        self._fast = self._config.paper_model and live.fit is None
        self._arm_step()

    def _arm_step(self) -> None:
        """Arm the C call of the step on the state arrays while the fast path holds.

        Called on a new state (reset, restore) and by the Python :meth:`update` when it
        finds the fast path unarmed (after the noise fit, in a copy).
        """
        address = llr_cstep.step_address() if self._fast else None
        if address is None:
            self._step_disarm()
        else:
            self._step_arm(address, self._live.floats, self._live.ints)

    def __getstate__(self) -> dict[str, Any]:
        """Return the instance attributes (copy, pickle): the C base holds no state."""
        return dict(self.__dict__)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Set the instance attributes, then arm the C call on the arrays set."""
        self.__dict__.update(state)
        self._arm_step()

    # -- samples ----------------------------------------------------------------------
    def _after(self, flags: int) -> list[AnomalyEvent]:
        """Act on a kernel step's non-zero flags (the C call's callback)."""
        return llr_changes.after(self._live, self._config, flags)

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
                flags = _step(self._live.floats, self._live.ints, t, speed, friction)
            except TypeError:
                return self._update_converted(t, speed, friction)
            return self._after(flags) if flags else []
        values = self._floats(t, speed, friction)
        if values is None:
            return []
        t, w, f = values
        live, config = self._live, self._config
        row = kern.accept(live.floats, live.ints, t, w, f)
        if row < 0:
            return []
        if config.paper_model:
            h = (-1.0 if w > 0.0 else (1.0 if w < 0.0 else 0.0), -w)
        else:
            h = samples.regressor_row(live, config, t, w, aux)
            if h is None:
                return []
        live.floats[layout.F_LAST_T] = t
        events = samples.ingest(live, config, row, t, f, h, w)
        self._fast = config.paper_model and live.fit is None
        return events

    update = llr_cstep.compiled_update(update, '_after')

    def process_arrays(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray,
                       aux: Mapping[str, np.ndarray] | None = None) -> list[AnomalyEvent]:
        """Process whole arrays as :meth:`update` would, row by row; return the events.

        Parameters
        ----------
        time, speed, friction : array_like
            1-D arrays of the same length (ValueError otherwise).
        aux : mapping of str to array_like, optional
            Auxiliary channels of a friction model that needs them (same length).

        Returns
        -------
        list of AnomalyEvent
            The events of :meth:`update` on the same rows, and the detector's state after
            them is the one :meth:`update` leaves. For the paper's model the per-sample
            loop runs compiled (core/llr_kernel.py ``run``; Python only at the samples
            whose flags need it and while the noise model is fitted); for other models
            the regressor rows are computed once for the arrays.
        """
        t, w, f = samples.as_arrays(time, speed, friction)
        if not self._config.paper_model:
            return self._process_rows(t, w, f, aux)
        live, config = self._live, self._config
        events: list[AnomalyEvent] = []
        i, n = 0, t.size
        while i < n:
            if self._fast:
                i = kern.run(live.floats, live.ints, t, w, f, i)
                if i < n:
                    events.extend(self._after(layout.take_flags(live.ints)))
            elif live.fit is not None and not config.noise_speed_model:
                i = samples.buffer_arrays(live, config, t, w, f, i)
                if len(live.fit) >= config.noise_fit_samples:
                    events.extend(samples.fit_and_replay(live, config))
                    self._fast = live.fit is None
                continue
            else:
                events.extend(self.update(float(t[i]), float(w[i]), float(f[i])))
            i += 1
        return events

    def _process_rows(self, t: np.ndarray, w: np.ndarray, f: np.ndarray,
                      aux: Mapping[str, np.ndarray] | None) -> list[AnomalyEvent]:
        """:meth:`process_arrays` of a model other than the paper's."""
        columns = None
        if aux:
            columns = {name: np.asarray(values, dtype=float) for name, values in aux.items()}
            for name, values in columns.items():
                if values.shape != t.shape:
                    raise ValueError(f'aux[{name!r}] must have the length of time ({t.size}), '
                                     f'got {values.size}')
        events = samples.process_rows(self._live, self._config, t, w, f, columns)
        if events is not None:
            return events
        events = []
        for i in range(t.size):
            row_aux = {name: float(v[i]) for name, v in columns.items()} if columns else None
            events.extend(self.update(float(t[i]), float(w[i]), float(f[i]), row_aux))
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
                flags = _step_calibrated(self._live.floats, self._live.ints, table, t, speed,
                                         friction)
            except TypeError:
                pass
            else:
                return self._after(flags) if flags else []
        try:
            residual = calibrated.nominal_residual(table, float(t), float(speed), float(friction))
        except (TypeError, ValueError):
            return self.update(t, speed, friction)
        return self.update(t, speed, residual)

    def finish(self) -> list[AnomalyEvent]:
        """End of record: the final kind of the last declared change (docs/llr.md).

        :func:`rwa_monitor.core.llr_changes.finish`; a second call gives nothing.
        """
        return llr_changes.finish(self._live, self._config)

    def _update_converted(self, t: Any, speed: Any, friction: Any) -> list[AnomalyEvent]:
        """:meth:`update` of the fast path for values the kernel does not take as floats."""
        values = self._floats(t, speed, friction)
        if values is None:
            return []
        flags = _step(self._live.floats, self._live.ints, *values)
        return self._after(flags) if flags else []

    def _floats(self, t: Any, speed: Any, friction: Any) -> tuple[float, float, float] | None:
        """Return the sample as floats, or None (counted as a non-finite row)."""
        try:
            return float(t), float(speed), float(friction)
        except (TypeError, ValueError):
            self._live.ints[layout.I_ROWS] += 1
            self._live.counters['non_finite'] += 1
            return None
