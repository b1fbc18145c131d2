"""The state of one LLR detector: typed records, and the working state its parts share.

:class:`LLRState` is the detector's saved state (``LLRDetector.state()`` /
``restore()``): a frozen record of the field types core/records.py understands, so that
``records.encode`` / ``records.decode`` write and read it as JSON plus named arrays and
nothing in it names code. It holds the compiled kernel's two state arrays as they are
(their layout: core/llr_layout.py; the positions, prefix sums and rings of Algorithm 1),
the Python-side parts as records (:class:`DeclaredChange`, :class:`FitSamples`,
:class:`GeneralPath`, the noise model, the counters the kernel does not keep, the last
event) and the parameters it was made with (``LLRConfig.fingerprint``).

:class:`Live` is the same state while the detector runs: the kernel arrays (written in
place by the kernel and by the parts), the counters, and the records, replaced when they
change (a declaration, a revision), except the samples waiting for the noise fit, which
accumulate in a :class:`SampleBuffer`. The parts (core/llr_changes.py, llr_general.py,
llr_samples.py) receive it and the configuration explicitly. What a restore refuses is
core/llr_restore.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from typing import ClassVar, NamedTuple

import numpy as np

from rwa_monitor.core import llr_layout as layout, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gchi2 import skip_threshold
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_noise import NoiseModel
from rwa_monitor.core.records import array_field, Scalar

COUNTER_NAMES = ('non_finite', 'out_of_range', 'non_increasing_time', 'missing_aux',
                 'ill_conditioned')


@dataclass(frozen=True)
class DeclaredChange:
    """The last declared change, whose kind is re-checked as data arrive (a record).

    Positions count accepted samples; the change was found at position ``tau`` (time
    ``time``, row ``rows[0]``), its p_min at row ``rows[1]``, declared at row
    ``rows[2]``. ``before``: prefix sums of the before segment (``n_before`` samples);
    ``gap``: sums of the after samples before the new reference starts (the after segment
    is ``gap`` + the new reference). ``checks``: positions where the kind is re-checked
    (:func:`llr_common.checkpoints`); ``points``: the remaining positions where the ramp
    sums take in samples (:func:`llr_common.ramp_points`); ``ramp``: one
    :func:`llr_growth.ramp_sums` block per row, of ``[tau, ramp_end]`` (times since
    ``time``). ``closed``: the re-checks are over; the ramp sums still take in samples every
    ``tail_stride`` samples (the rings' length), into one last block (``tail``), for the
    continuation test of a later declaration and the end of record. ``finished``: ``finish``
    has run. ``after_gap_s``: the change fell in a gap of the samples; the time from the last
    sample before it (NaN: not in a gap). ``shape``: the shape of the kind given (``step``, or
    ``ramp`` when it was named for a growing change; the continuation test of a later
    declaration lets only a kind named so fix the direction of the growth). ``speeds``: per
    ``ramp`` block the lowest and highest ``|w|`` of its samples (NaN for p > 2), for the kind
    rules' speed order (core/llr_kinds.py ``speed_ordered``).
    """

    n_before: int
    kind: str
    guess: str
    confirmed: bool
    revision: int
    rows: tuple[int, int, int]
    time: float
    log_p: float
    checks: tuple[int, ...]
    points: tuple[int, ...]
    ramp_end: int
    tau: int
    closed: bool
    tail: bool
    finished: bool
    after_gap_s: float
    shape: str
    before: np.ndarray = array_field('float64', 1)
    gap: np.ndarray = array_field('float64', 1)
    ramp: np.ndarray = array_field('float64', 2)
    speeds: np.ndarray = array_field('float64', 2)


@dataclass(frozen=True)
class FitSamples:
    """The accepted samples waiting for the noise fit (a record; llr_samples.py).

    One entry per sample: its row, time, friction, speed and regressor row (``(n, p)``,
    before any scaling). ``speed_low`` / ``speed_high``: the range of ``|speed|`` so far
    (inf / 0 when empty; the speed noise model waits for a spread); ``next_fit``: the
    count at which a speed model fit that was not final is tried again, or None.
    """

    speed_low: float
    speed_high: float
    next_fit: int | None
    rows: np.ndarray = array_field('int64', 1)
    time: np.ndarray = array_field('float64', 1)
    friction: np.ndarray = array_field('float64', 1)
    speed: np.ndarray = array_field('float64', 1)
    regressors: np.ndarray = array_field('float64', 2)


@dataclass(frozen=True)
class GeneralPath:
    """The state of the per-sample path of models with p > 2 (llr_general.py; a record).

    ``reference_sums``: the prefix sums of the reference up to the last sample (the ring
    of earlier rows is in the kernel arrays, as for p = 2); ``last_statistic``: the
    latest ``LLR_k / sigma^2`` (nan if skipped); ``lag_friction`` / ``lag_regressors``:
    the last samples before whitening, newest first (the AR filter's memory).
    """

    last_statistic: float
    reference_sums: np.ndarray = array_field('float64', 1)
    lag_friction: np.ndarray = array_field('float64', 1)
    lag_regressors: np.ndarray = array_field('float64', 2)


@dataclass(frozen=True)
class LLRState:
    """The saved state of one LLR detector (``LLRDetector.state()``), format :attr:`VERSION`.

    ``parameters``: ``LLRConfig.fingerprint()`` of the detector that made it (a restore
    refuses other parameters); ``floats`` / ``ints``: the kernel's state arrays
    (core/llr_layout.py); ``counters``: the rejections counted outside the kernel (the
    detector's ``counters`` add the kernel's); ``noise``: the fitted noise model (None
    while fitting or with white noise by setting); ``fit``: the samples waiting for the
    fit (None once fitted, or with no fit); ``general``: the p > 2 path (None for p = 2);
    ``change``: the last declared change; ``last_event``: the latest event returned.
    """

    VERSION: ClassVar[int] = 3   # 2: DeclaredChange.shape; 3: its speeds, the speed ring

    parameters: dict[str, Scalar]
    counters: dict[str, int]
    noise: NoiseModel | None
    fit: FitSamples | None
    general: GeneralPath | None
    change: DeclaredChange | None
    last_event: AnomalyEvent | None
    floats: np.ndarray = array_field('float64', 1)
    ints: np.ndarray = array_field('int64', 1)


class Rings(NamedTuple):
    """Views of the kernel's rings of the last ``L`` accepted samples (by position % L)."""

    pref: np.ndarray   # (L, width): prefix-sum row at each position
    term: np.ndarray   # (L, 3) (h1, h2, f) for p = 2, else (L, width) terms
    time: np.ndarray   # (L,) sample time
    speed: np.ndarray  # (L,) |w| for p = 2 (llr_kernel.ingest_sample), NaN for p > 2
    row: np.ndarray    # (L,) row index


def rings(floats: np.ndarray, ints: np.ndarray) -> Rings:
    """Return the ring views of the kernel arrays (core/llr_layout.py ``allocate``)."""
    length = int(ints[layout.I_L])
    o_pref, o_term = int(ints[layout.I_O_RPREF]), int(ints[layout.I_O_RTERM])
    o_time, o_speed = int(ints[layout.I_O_RTIME]), int(ints[layout.I_O_RSPEED])
    o_ar = int(ints[layout.I_O_AR])
    return Rings(floats[o_pref:o_term].reshape(length, -1),
                 floats[o_term:o_time].reshape(length, -1), floats[o_time:o_speed],
                 floats[o_speed:o_ar], ints[layout.I_SCALARS:layout.I_SCALARS + length])


class SampleBuffer:
    """Accepted samples waiting for the noise fit, as they arrive (the live :class:`FitSamples`).

    The streaming path appends one sample at a time, the batch path whole arrays
    (core/llr_kernel.py ``accept_run``); :meth:`columns` gives them in arrival order.
    """

    def __init__(self, p: int, record: FitSamples | None = None) -> None:
        self._p = p
        self._parts: list[tuple[np.ndarray, ...]] = []
        self._pending: list[tuple] = []
        self._size = 0
        self.speed_low = math.inf
        self.speed_high = 0.0
        self.next_fit: int | None = None
        if record is not None:
            self.extend(record.rows, record.time, record.friction, record.speed,
                        record.regressors)
            self.speed_low, self.speed_high = record.speed_low, record.speed_high
            self.next_fit = record.next_fit

    def __len__(self) -> int:
        return self._size

    def append(self, row: int, t: float, f: float, h, speed: float) -> None:
        """Add one sample (``h``: its regressor row)."""
        self._pending.append((row, t, f, speed, h))
        self._size += 1

    def extend(self, rows: np.ndarray, t: np.ndarray, f: np.ndarray, speed: np.ndarray,
               h: np.ndarray) -> None:
        """Add samples given as arrays (``h``: ``(n, p)``)."""
        self._flush()
        self._parts.append((rows, t, f, speed, h))
        self._size += rows.size

    def _flush(self) -> None:
        if self._pending:
            rows, t, f, speed, h = zip(*self._pending)
            self._parts.append((np.array(rows, dtype=np.int64), np.array(t, dtype=float),
                                np.array(f, dtype=float), np.array(speed, dtype=float),
                                np.array(h, dtype=float).reshape(len(rows), self._p)))
            self._pending = []

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(rows, time, friction, speed, regressors)`` of every sample, in order."""
        self._flush()
        if len(self._parts) != 1:
            if not self._parts:
                return (np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(0),
                        np.zeros((0, self._p)))
            self._parts = [tuple(np.concatenate(c) for c in zip(*self._parts))]
        return self._parts[0]

    def record(self) -> FitSamples:
        """Return the samples as a :class:`FitSamples` (arrays copied)."""
        rows, t, f, speed, h = (np.array(c) for c in self.columns())
        return FitSamples(self.speed_low, self.speed_high, self.next_fit, rows, t, f, speed, h)


@dataclass
class Live:
    """The working state of a running detector (the live form of :class:`LLRState`).

    ``floats`` / ``ints`` are written in place (the kernel holds them while the C call
    is armed); the records are replaced when they change. ``ring``: views of the rings
    in the arrays (derived, not state).
    """

    floats: np.ndarray
    ints: np.ndarray
    counters: dict[str, int]
    noise: NoiseModel | None = None
    fit: SampleBuffer | None = None
    general: GeneralPath | None = None
    change: DeclaredChange | None = None
    last_event: AnomalyEvent | None = None
    ring: Rings = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.ring = rings(self.floats, self.ints)

    def __getstate__(self) -> dict:
        """Return the fields without the ring views (copy, pickle: views would not alias)."""
        state = dict(self.__dict__)
        del state['ring']
        return state

    def __setstate__(self, state: dict) -> None:
        """Set the fields, then the ring views into the arrays set."""
        self.__dict__.update(state)
        self.ring = rings(self.floats, self.ints)

    @property
    def position(self) -> int:
        """Accepted samples in the sums: the next sample's position."""
        return int(self.ints[layout.I_POS])

    @property
    def reference_start(self) -> int:
        """Position ``c`` where the reference segment starts."""
        return int(self.ints[layout.I_C])

    def prefix_now(self) -> np.ndarray:
        """Return the prefix sums of the reference up to the last accepted sample (a copy)."""
        if self.general is not None:
            return self.general.reference_sums.copy()
        return self.floats[layout.F_PREF:layout.F_PREF + 6].copy()

    def record_minimum(self, k: int, log_p: float) -> None:
        """Algorithm 1 lines 13-15: ``p_k`` is the new smallest (its skip bound follows)."""
        self.floats[layout.F_LOGPMIN] = log_p
        self.ints[layout.I_KMIN] = k
        self.floats[layout.F_YSTAR] = skip_threshold(log_p)

    def declares(self, k: int, log_r: float, k_verif: int) -> bool:
        """Algorithm 1 line 18: p_min at or below r and ``k`` past the verification."""
        return (float(self.floats[layout.F_LOGPMIN]) <= log_r
                and k > int(self.ints[layout.I_KMIN]) + k_verif)

    def base(self, k: int, reference_max: int | None) -> tuple[np.ndarray, int]:
        """Return the prefix row where P_k starts and the length of P_k (Algorithm 1 line 7).

        With a sliding reference (``reference_max``, docs/llr.md "Slow drifts") P_k is
        at most ``reference_max`` samples long.
        """
        c = self.reference_start
        if reference_max is not None and k - reference_max > c:
            return self.ring.pref[(k - reference_max) % len(self.ring.row)].copy(), \
                reference_max
        return np.zeros(self.ring.pref.shape[1]), k - c


def fresh(config: LLRConfig) -> Live:
    """Return the state of a detector that has seen no sample (``reset``)."""
    p2 = config.p == 2
    floats, ints = layout.allocate(config.ring_length, config.width, config.term_width,
                                   config.kernel_ar_order)
    floats[layout.F_LAST_T] = -math.inf
    floats[layout.F_LOGR] = config.log_r
    floats[layout.F_MIN_EXC] = config.min_excitation
    floats[layout.F_NOISE_VAR] = math.nan if config.noise_var is None else config.noise_var
    floats[layout.F_MAX_W] = config.max_abs_speed
    floats[layout.F_MAX_F] = config.max_abs_friction
    floats[layout.F_FLOOR_REL] = llr_stats.NOISE_FLOOR_REL
    floats[layout.F_FLOOR_ABS] = llr_stats.NOISE_FLOOR_ABS
    ints[layout.I_W] = config.window
    ints[layout.I_KVERIF] = config.k_verif
    ints[layout.I_R] = -1 if config.reference_max is None else config.reference_max
    ints[layout.I_ESTIMATED] = config.noise_var is None
    ints[layout.I_C_ROW] = -1
    ints[layout.I_CHECKPOINT] = -1
    general = None if p2 else GeneralPath(math.nan, np.zeros(config.width), np.zeros(0),
                                          np.zeros((0, config.p)))
    return Live(floats, ints, dict.fromkeys(COUNTER_NAMES, 0),
                fit=SampleBuffer(config.p) if config.fits_noise else None, general=general)


def snapshot(live: Live, config: LLRConfig) -> LLRState:
    """Return the :class:`LLRState` of a working state (arrays copied: it stays as it is)."""
    change = live.change
    if change is not None:
        change = replace(change, before=change.before.copy(), gap=change.gap.copy(),
                         ramp=change.ramp.copy(), speeds=change.speeds.copy())
    general = live.general
    if general is not None:
        general = replace(general, reference_sums=general.reference_sums.copy(),
                          lag_friction=general.lag_friction.copy(),
                          lag_regressors=general.lag_regressors.copy())
    return LLRState(parameters=config.fingerprint(), counters=dict(live.counters),
                    noise=live.noise, fit=None if live.fit is None else live.fit.record(),
                    general=general, change=change, last_event=live.last_event,
                    floats=live.floats.copy(), ints=live.ints.copy())


def working(state: LLRState, config: LLRConfig) -> Live:
    """Return the working state of a checked :class:`LLRState` (arrays copied)."""
    copy = snapshot(Live(state.floats, state.ints, state.counters, state.noise, None,
                         state.general, state.change, state.last_event), config)
    fit = None
    if state.fit is not None:
        fit = SampleBuffer(config.p, replace(state.fit, **{
            name: getattr(state.fit, name).copy()
            for name in ('rows', 'time', 'friction', 'speed', 'regressors')}))
    return Live(copy.floats, copy.ints, copy.counters, copy.noise, fit, copy.general,
                copy.change, copy.last_event)
