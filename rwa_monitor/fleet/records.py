"""The fleet's typed data: what a spacecraft's chain carries and what its state keeps.

Everything here is a frozen dataclass. :class:`SpacecraftRecord` is what the state folder
keeps of one spacecraft between runs (core/records.py types only: read back by its
declared types, never by names in the file); :class:`Chain` is what one ``step`` task
hands to the next through Dask (in memory); :class:`TrendRow`, :class:`PassFacts` are the
rows of trend.parquet and of the summary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, ClassVar, Iterator, Mapping, Sequence

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_runner import GyroRunnerState
from rwa_monitor.core.records import array_field, RecordError
from rwa_monitor.core.runner_facts import ComponentFacts
from rwa_monitor.core.wheel_runner import WheelRunnerState

GYRO = 'gyro'


@dataclass(frozen=True)
class PassRecord:
    """A pass processed: its file name and size (what makes it the same pass), stamps."""

    name: str
    size: int
    first: float
    last: float


@dataclass(frozen=True, eq=False)
class PassLog:
    """Every pass processed, in time order, one column per field of :class:`PassRecord`.

    The longest part of a state: a daily run reads and writes it whole, and after a year
    of 6 passes a day it holds 219,000 passes for 100 spacecraft. As columns (names in the
    tree, the numbers as arrays) they cost one call per column to read and write, instead
    of one record per pass.
    """

    VERSION: ClassVar[int] = 1
    names: tuple[str, ...] = ()
    sizes: np.ndarray = array_field('int64', 1, default_factory=lambda: np.zeros(0, np.int64))
    first: np.ndarray = array_field('float64', 1, default_factory=lambda: np.zeros(0))
    last: np.ndarray = array_field('float64', 1, default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        """Refuse columns of different lengths (a log read back is checked here too)."""
        if not len(self.names) == len(self.sizes) == len(self.first) == len(self.last):
            raise RecordError(f'pass log columns of lengths {len(self.names)}, '
                              f'{len(self.sizes)}, {len(self.first)}, {len(self.last)}')

    @classmethod
    def of(cls, passes: Sequence[PassRecord]) -> 'PassLog':
        """Return the log of ``passes`` (in their order)."""
        return cls(tuple(p.name for p in passes),
                   np.array([p.size for p in passes], dtype=np.int64),
                   np.array([p.first for p in passes], dtype=np.float64),
                   np.array([p.last for p in passes], dtype=np.float64))

    def __len__(self) -> int:
        """Return the number of passes."""
        return len(self.names)

    def __getitem__(self, index: int) -> PassRecord:
        """Return one pass as a record (``log[-1]``: the last one processed)."""
        return PassRecord(self.names[index], int(self.sizes[index]),
                          float(self.first[index]), float(self.last[index]))

    def __iter__(self) -> Iterator[PassRecord]:
        """Yield the passes as records, in order."""
        return (self[i] for i in range(len(self)))

    def __eq__(self, other: object) -> bool:
        """Return True for a log of the same passes (columns equal, value for value)."""
        if not isinstance(other, PassLog):
            return NotImplemented
        return (self.names == other.names and np.array_equal(self.sizes, other.sizes)
                and np.array_equal(self.first, other.first)
                and np.array_equal(self.last, other.last))

    __hash__ = None  # type: ignore[assignment]

    def keys(self) -> set[tuple[str, int]]:
        """Return the ``(name, size)`` of every pass: what makes a pass the same pass."""
        return set(zip(self.names, self.sizes.tolist()))

    def plus(self, passes: Sequence[PassRecord]) -> 'PassLog':
        """Return this log with ``passes`` after its own."""
        if not passes:
            return self
        more = PassLog.of(passes)
        return PassLog(self.names + more.names, np.concatenate([self.sizes, more.sizes]),
                       np.concatenate([self.first, more.first]),
                       np.concatenate([self.last, more.last]))


@dataclass(frozen=True)
class ComponentRecord:
    """One component's runner state: a wheel's or the gyro's (the other is None)."""

    wheel: WheelRunnerState | None = None
    gyro: GyroRunnerState | None = None


@dataclass(frozen=True)
class SpacecraftRecord:
    """One spacecraft after the last pass processed (the state folder's unit).

    ``fingerprint``: of the parameters, calibration and refined model the runners were
    made with (a run with others is refused); ``last_time``: the last stamp fed;
    ``passes``: every pass processed so far, in time order (version 2: as a
    :class:`PassLog`, where version 1 held one record per pass).
    """

    VERSION: ClassVar[int] = 2
    spacecraft: str
    fingerprint: str
    last_time: float
    passes: PassLog
    components: dict[str, ComponentRecord]


@dataclass(frozen=True)
class TrendRow:
    """One wheel's friction levels over one pass (core/trend.py pass_levels)."""

    spacecraft: str
    wheel: str
    pass_name: str
    t_start: float
    t_end: float
    samples: int
    dry: float
    dry_se: float
    viscous: float
    viscous_se: float
    relative_to: str

    def fields(self) -> dict[str, Any]:
        """Return the trend.parquet row (column ``pass``)."""
        return {'spacecraft': self.spacecraft, 'wheel': self.wheel, 'pass': self.pass_name,
                't_start': self.t_start, 't_end': self.t_end, 'samples': self.samples,
                'dry': self.dry, 'dry_se': self.dry_se, 'viscous': self.viscous,
                'viscous_se': self.viscous_se, 'relative_to': self.relative_to}

    @classmethod
    def from_fields(cls, row: Mapping[str, Any]) -> 'TrendRow':
        """Return the row of a trend table (nulls as NaN)."""
        def num(key: str) -> float:
            value = row.get(key)
            return math.nan if value is None else float(value)
        return cls(str(row['spacecraft']), str(row['wheel']), str(row['pass']),
                   num('t_start'), num('t_end'), int(row.get('samples') or 0), num('dry'),
                   num('dry_se'), num('viscous'), num('viscous_se'),
                   str(row.get('relative_to') or ''))


@dataclass(frozen=True)
class PassFacts:
    """What one pass gave, or why it could not be read.

    ``rows``: rows fed; ``rows_dropped``: rows stamped at or before the last one fed
    before it; ``wheel_samples``: samples fed to the wheels' runners (all wheels);
    ``last``: its last stamp; ``component_errors``: why a component was not fed by it.
    """

    name: str
    rows: int = 0
    rows_dropped: int = 0
    wheel_samples: int = 0
    last: float = math.nan
    error: str | None = None
    component_errors: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class WorkFacts:
    """CPU seconds, tasks and peak memory of one worker process."""

    cpu_s: float = 0.0
    tasks: int = 0
    peak_rss_mb: float = 0.0

    def plus(self, other: 'WorkFacts') -> 'WorkFacts':
        """Return the sum of two workers' facts (peak: the larger)."""
        return WorkFacts(self.cpu_s + other.cpu_s, self.tasks + other.tasks,
                         max(self.peak_rss_mb, other.peak_rss_mb))


@dataclass(frozen=True)
class Chain:
    """One spacecraft's chain after some passes of this run (a step task's result).

    ``states``: component -> runner state (before any end-of-run categorisation);
    ``events``: this run's events so far; ``end_of_run``: the end-of-run events of the
    run's last step (``finish``: final until a later run continues the record);
    ``facts``: component -> the runner's facts; ``work``: worker -> CPU and memory.
    """

    last_time: float
    states: Mapping[str, ComponentRecord]
    events: tuple[AnomalyEvent, ...] = ()
    end_of_run: tuple[AnomalyEvent, ...] = ()
    passes: tuple[PassFacts, ...] = ()
    trend: tuple[TrendRow, ...] = ()
    facts: Mapping[str, ComponentFacts] = field(default_factory=dict)
    work: Mapping[str, WorkFacts] = field(default_factory=dict)
