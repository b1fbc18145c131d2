"""The gyro detectors' state as typed records (docs/vsadc.md "State").

:class:`VsadcState` (``VsadcDetector``, ``feature: paper``) and :class:`GyroDiagnosisState`
(``GyroDiagnosis``, ``feature: residual``) are what ``state()`` returns and ``restore``
takes; :func:`rwa_monitor.core.records.encode` / ``decode`` turn them into a JSON tree and
named arrays and back. The records are declared here, apart from the detectors' private
attributes: renaming an attribute cannot change the format, only a new record can, and
then ``VERSION`` changes. Windows are stored oldest value first, whatever the ring layout.
A stamp is a ``(time, row)`` pair: times in s, rows the telemetry row index.

The checks shared by the detectors' ``restore`` are here too (:func:`require`,
:func:`check_parameters`, ...): each raises :class:`~rwa_monitor.core.records.RecordError`
naming the field.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.records import array_field, RecordError, Scalar

Stamp = tuple[float, int]
_MISSING = object()


@dataclass(frozen=True)
class Stamps:
    """Stamps ``(time, row)`` of consecutive samples, oldest first."""

    times: np.ndarray = array_field('float64', 1)
    rows: np.ndarray = array_field('int64', 1)


@dataclass(frozen=True)
class WindowState:
    """A sliding window of floats: its last ``min(updates, size)`` values, oldest first.

    ``total`` and ``squares`` are the running sums as they stand (their rounding included:
    the resumed detector must add to the same numbers).
    """

    values: np.ndarray = array_field('float64', 1)
    total: float
    squares: float
    updates: int


@dataclass(frozen=True)
class SlidingMaxState:
    """A sliding maximum: the candidates ``(position, value)`` and the number pushed."""

    positions: np.ndarray = array_field('int64', 1)
    values: np.ndarray = array_field('float64', 1)
    pushed: int


@dataclass(frozen=True)
class StarTrackerState:
    """The star-tracker differencer: the last accepted quaternion (normalised) and counters."""

    previous: tuple[float, float, float, float] | None
    previous_time: float
    invalid: int
    non_increasing_time: int
    gaps: int


@dataclass(frozen=True)
class GyroRowsState:
    """The row filter: the last accepted stamp and the counters (core/gyro_rows.py)."""

    rows: int
    accepted: int
    held: int
    bad_gyro: int
    non_finite: int
    non_increasing_time: int
    bad_axis: dict[str, int]
    last_time: float
    star_tracker: StarTrackerState


@dataclass(frozen=True)
class VsadcAxisState:
    """One VSADC axis (core/vsadc_axis.py ``VsadcAxis``).

    ``features`` (k, 2) are the last ``min(samples, window)`` ``(res_sst, res_gyr)`` with
    their ``stamps``; ``distances`` the last ``sigma_window`` distances (fewer at
    start-up); ``reference`` / ``reference_max`` the healthy sigmas behind the limits,
    ``regime`` / ``regime_max`` the sigmas of the current fault (self-adaptation);
    ``candidate`` and ``run`` the label waiting for ``hold`` agreeing samples;
    ``quiet_since`` the first stamp above the quiet level (None while quiet).
    """

    samples: int
    features: np.ndarray = array_field('float64', 2)
    stamps: Stamps
    feature_sums: tuple[float, float]
    distances: np.ndarray = array_field('float64', 1)
    distance_sums: tuple[float, float]
    ready: bool
    reference: WindowState
    reference_max: SlidingMaxState
    regime: WindowState
    regime_max: SlidingMaxState
    nominal_centre: tuple[float, float]
    healthy_distance_mean: float
    healthy_distance_variance: float
    label: int
    candidate: int
    run: int
    quiet_since: Stamp | None
    distance: float
    sigma: float
    sigma_limits: tuple[float, float]


@dataclass(frozen=True)
class ResidualThresholds:
    """One residual axis's thresholds (rad/s, rad/s per s): its calibration's or defaults."""

    block_std: float
    level: float
    quiet: float
    slope: float


@dataclass(frozen=True)
class ResidualAxisState:
    """One axis of the residual diagnosis (core/gyro_residual.py ``ResidualAxis``).

    ``partial_*`` is the block being filled (its sum, the sum of its first half, the
    times and stamps of its samples); ``block_*`` the last completed blocks kept for the
    decision and the slope (means, half-block means, sample times (k, block), stamps);
    ``pending`` / ``pending_run`` the label being confirmed, ``over`` the blocks above
    the level, ``waited`` the blocks the kind decision waited, ``level_sum`` /
    ``level_blocks`` the held bias level. ``calibrated``, ``lag1_correlation`` and
    ``thresholds`` say which calibration the state was made with;
    ``threshold_sample_s`` the sample period the default thresholds were scaled to
    (None: calibrated, or not yet measured).
    """

    samples: int
    blocks_seen: int
    partial_sum: float
    first_half_sum: float
    partial_times: np.ndarray = array_field('float64', 1)
    partial_stamps: Stamps
    block_means: np.ndarray = array_field('float64', 1)
    block_halves: np.ndarray = array_field('float64', 2)
    block_times: np.ndarray = array_field('float64', 2)
    block_stamps: Stamps
    nominal_sum: float
    nominal: float
    label: int
    pending: int
    pending_run: int
    over: int
    waited: int
    fault_blocks: int
    level_sum: float
    level_blocks: int
    distance: float
    slope: float
    cusum: tuple[float, float]
    calibrated: bool
    lag1_correlation: float
    thresholds: ResidualThresholds
    threshold_sample_s: float | None


@dataclass(frozen=True)
class VsadcState:
    """The state of a ``VsadcDetector``: its parameters, its axes, its row filter."""

    VERSION: ClassVar[int] = 1
    parameters: dict[str, Scalar]
    axes: dict[str, VsadcAxisState]
    rows: GyroRowsState
    last_event: AnomalyEvent | None


@dataclass(frozen=True)
class GyroDiagnosisState:
    """The state of a ``GyroDiagnosis``: its parameters, axes, row filter and more.

    Beside :class:`VsadcState`'s fields: the saturation counts and flags per axis and the
    previous gyro sample with its stamp (the trapezoid's other end).
    """

    VERSION: ClassVar[int] = 1
    parameters: dict[str, Scalar]
    axes: dict[str, ResidualAxisState]
    rows: GyroRowsState
    last_event: AnomalyEvent | None
    saturated: dict[str, int]
    saturated_now: dict[str, bool]
    previous_gyro: tuple[float, float, float] | None
    previous_time: float


def require(ok: bool, path: str, message: str) -> None:
    """Raise RecordError ``path: message`` unless ``ok``."""
    if not ok:
        raise RecordError(f'{path}: {message}')


def check_type(record: Any, cls: type, path: str) -> None:
    """Refuse a record that is not a ``cls``."""
    require(type(record) is cls, path, f'expected a {cls.__name__}, got '
            f'{type(record).__name__}')


def check_counts(record: Any, names: Sequence[str], path: str) -> None:
    """Refuse a record whose integer fields ``names`` are negative."""
    for name in names:
        value = getattr(record, name)
        require(type(value) is int and value >= 0, f'{path}.{name}',
                f'expected a count >= 0, got {value!r}')


def check_finite(path: str, *values: Any) -> None:
    """Refuse non-finite numbers (running sums and windows of finite samples)."""
    for value in values:
        require(bool(np.all(np.isfinite(value))), path, 'holds a non-finite value')


def check_label(value: Any, path: str) -> None:
    """Refuse a label other than 0 (healthy), 1 (drift) or 2 (bias)."""
    require(value in (0, 1, 2) and type(value) is int, path,
            f'expected a label 0, 1 or 2, got {value!r}')


def check_parameters(saved: Mapping[str, Scalar], own: Mapping[str, Scalar],
                     path: str) -> None:
    """Refuse a state made with other parameters (names every one that differs)."""
    differ = []
    for name in sorted(set(saved) | set(own)):
        a, b = saved.get(name, _MISSING), own.get(name, _MISSING)
        if type(a) is not type(b) or a != b:
            shown = ['none' if v is _MISSING else repr(v) for v in (a, b)]
            differ.append(f'{path}.parameters.{name}: {shown[0]} in the state, {shown[1]} '
                          'in this detector')
    if differ:
        raise RecordError('; '.join(differ))


def check_keys(saved: Mapping[str, Any], axes: Sequence[str], path: str) -> None:
    """Refuse a per-axis mapping whose keys are not exactly ``axes``."""
    require(set(saved) == set(axes), path,
            f'axes {sorted(saved)} in the state, {sorted(axes)} in this detector')


def check_stamps(stamps: Any, size: int, path: str) -> None:
    """Refuse stamps that are not :class:`Stamps` of ``size`` finite times."""
    check_type(stamps, Stamps, path)
    require(len(stamps.times) == size and len(stamps.rows) == size, path,
            f'expected {size} stamps, got {len(stamps.times)} times, {len(stamps.rows)} rows')
    check_finite(f'{path}.times', stamps.times)


def stamps_record(stamps: Sequence[Any], path: str) -> Stamps:
    """Return the :class:`Stamps` of ``(time, row)`` pairs (RecordError for other stamps)."""
    try:
        times = np.array([float(s[0]) for s in stamps], dtype=np.float64)
        rows = np.array([int(s[1]) for s in stamps], dtype=np.int64)
    except (TypeError, ValueError, IndexError, OverflowError):
        raise RecordError(f'{path}: only (time, row) stamps can be saved') from None
    return Stamps(times, rows)


def stamp_list(stamps: Stamps) -> list[Stamp]:
    """Return the ``(time, row)`` pairs of a :class:`Stamps`."""
    return list(zip(stamps.times.tolist(), stamps.rows.tolist()))


def stamp_record(stamp: Any, path: str) -> Stamp | None:
    """Return one stamp as ``(time, row)`` (None stays None)."""
    if stamp is None:
        return None
    return stamp_list(stamps_record([stamp], path))[0]


def ring(values: Sequence[Any], pushed: int, size: int, empty: Any) -> list[Any]:
    """Return the ring buffer of ``size`` slots after ``pushed`` pushes of ``values``.

    ``values`` are the last ``min(pushed, size)`` pushed, oldest first; the ring writes
    push ``j`` (from 0) into slot ``j % size``; unwritten slots hold ``empty``.
    """
    out = [empty] * size
    first = pushed - len(values)
    for i, v in enumerate(values):
        out[(first + i) % size] = v
    return out


def chronological(slots: Sequence[Any], pushed: int, size: int) -> list[Any]:
    """Return the last ``min(pushed, size)`` values of a ring, oldest first (see ring)."""
    count = min(pushed, size)
    first = pushed - count
    return [slots[(first + i) % size] for i in range(count)]
