"""The telemetry data model: one row per sample, SI units (REP 103).

Columns (DESIGN.md contract):
``time`` (s, strictly increasing); per wheel ``<id>_speed`` (rad/s) and ``<id>_friction``
(N m); optional ``gyro_x/y/z`` (rad/s, body frame); optional ``q_x/y/z/w`` (body attitude,
scalar last); optional ``ref_x/y/z`` (rad/s); optional ``truth_*`` (ground truth, ignored by
detectors); any other numeric column is an auxiliary channel.

Multi-rate recordings (docs/contracts.md): ``time`` is the union of every stream's stamps;
``present[stream]`` marks the rows where that stream has a sample (its other rows hold
NaN). A stream without an entry in ``present`` has a sample on every row (a CSV file).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import re

import numpy as np

TIME = 'time'
SPEED_SUFFIX = '_speed'
FRICTION_SUFFIX = '_friction'
TRUTH_PREFIX = 'truth_'
GYRO = ('gyro_x', 'gyro_y', 'gyro_z')
ATTITUDE = ('q_x', 'q_y', 'q_z', 'q_w')
REFERENCE = ('ref_x', 'ref_y', 'ref_z')
VECTOR_GROUPS = {'gyro': GYRO, 'attitude': ATTITUDE, 'reference_rate': REFERENCE}
# The streams of a recording, each with its own stamps (``columns``: aux and truth).
STREAMS = ('wheels', 'gyro', 'star_tracker', 'reference_rate', 'columns')
# Names from data are data (docs/contracts.md, "Names"): a wheel id becomes part of
# file names and diagnostics keys, so it is checked where it is read and again where a
# path is built from it (telemetry/atomic.py ``child``).
NAME_PATTERN = re.compile(r'[A-Za-z0-9_-]{1,64}')
NAME_RULE = '1 to 64 letters, digits, "_" or "-"'
MAX_COLUMN_NAME = 256


def valid_name(name: object) -> bool:
    """Return True if ``name`` is a safe name from data (NAME_RULE)."""
    return isinstance(name, str) and NAME_PATTERN.fullmatch(name) is not None


def name_problem(column: str, wheel_id: str | None) -> str | None:
    """Return why a column name (and the wheel id it gives, if any) is refused, or None."""
    if len(column) > MAX_COLUMN_NAME:
        return f'column name longer than {MAX_COLUMN_NAME} characters'
    if wheel_id is not None and not valid_name(wheel_id):
        return f'wheel id {wheel_id[:80]!r} is not a valid name ({NAME_RULE})'
    return None


def wheel_id_of(column: str) -> str | None:
    """Return the wheel id of a ``<id>_speed`` or ``<id>_friction`` column, else None."""
    if column in (TIME, *GYRO, *ATTITUDE, *REFERENCE) or column.startswith(TRUTH_PREFIX):
        return None
    for suffix in (SPEED_SUFFIX, FRICTION_SUFFIX):
        if column.endswith(suffix):
            return column[:-len(suffix)]
    return None


@dataclass
class Wheel:
    """One wheel's channels: spin rate (rad/s) and friction torque (N m, may be absent)."""

    speed: np.ndarray
    friction: np.ndarray | None = None


@dataclass
class Telemetry:
    """A telemetry record held as numpy arrays of equal length ``n``.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Stamps (s), strictly increasing.
    wheels : dict of str to Wheel
        Wheel id -> its speed (rad/s) and friction (N m) channels.
    gyro : ndarray, shape (n, 3), optional
        Gyro rates (rad/s, body frame).
    attitude : ndarray, shape (n, 4), optional
        Star-tracker attitude quaternions (x, y, z, w).
    reference_rate : ndarray, shape (n, 3), optional
        Guidance reference body rate (rad/s).
    aux : dict of str to ndarray
        Auxiliary channels (any other numeric column).
    truth : dict of str to ndarray
        Ground truth of a simulation (``truth_*`` columns), ignored by the detectors.
    source : str, optional
        Where the record was read from.
    present : dict of str to ndarray of bool
        Per stream of a multi-rate recording, the rows where it has a sample.

    Examples
    --------
    >>> import numpy as np
    >>> tele = Telemetry(time=np.arange(4) * 0.25,
    ...                  wheels={'rw1': Wheel(np.full(4, 100.0), np.full(4, -2e-4))})
    >>> len(tele), list(tele.columns())
    (4, ['time', 'rw1_speed', 'rw1_friction'])
    """

    time: np.ndarray
    wheels: dict[str, Wheel] = field(default_factory=dict)
    gyro: np.ndarray | None = None
    attitude: np.ndarray | None = None
    reference_rate: np.ndarray | None = None
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    source: str | None = None
    present: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.time)

    def rows(self, stream: str) -> np.ndarray:
        """Return the indices of the rows where ``stream`` (one of STREAMS) has a sample."""
        mask = self.present.get(stream)
        return np.arange(len(self.time)) if mask is None else np.flatnonzero(mask)

    def only(self, stream: str) -> 'Telemetry':
        """Return the record restricted to the rows where ``stream`` has a sample.

        Every channel keeps its values on those rows (NaN where another stream has no
        sample at that stamp); a single-rate record is returned as it is.
        """
        mask = self.present.get(stream)
        if mask is None:
            return self
        rows = np.flatnonzero(mask)

        def take(values: np.ndarray | None) -> np.ndarray | None:
            return None if values is None else np.asarray(values)[rows]

        return Telemetry(
            time=self.time[rows],
            wheels={k: Wheel(take(w.speed), take(w.friction)) for k, w in self.wheels.items()},
            gyro=take(self.gyro), attitude=take(self.attitude),
            reference_rate=take(self.reference_rate),
            aux={k: take(v) for k, v in self.aux.items()},
            truth={k: take(v) for k, v in self.truth.items()}, source=self.source,
            present={k: m[rows] for k, m in self.present.items()
                     if k != stream and not m[rows].all()})

    def columns(self) -> dict[str, np.ndarray]:
        """Return every channel as column name -> array, in the canonical column order."""
        cols: dict[str, np.ndarray] = {TIME: self.time}
        for wheel_id, wheel in self.wheels.items():
            cols[wheel_id + SPEED_SUFFIX] = wheel.speed
            if wheel.friction is not None:
                cols[wheel_id + FRICTION_SUFFIX] = wheel.friction
        for group, names in VECTOR_GROUPS.items():
            values = getattr(self, group)
            if values is not None:
                for i, name in enumerate(names):
                    cols[name] = values[:, i]
        cols.update(self.aux)
        cols.update({TRUTH_PREFIX + k: v for k, v in self.truth.items()})
        return cols

    @classmethod
    def from_columns(cls, columns: dict[str, np.ndarray],
                     source: str | None = None) -> 'Telemetry':
        """Build a record from column name -> array; raise KeyError naming what is missing.

        The caller (a file reader) turns KeyError into a schema error with the file name.
        """
        if TIME not in columns:
            raise KeyError(TIME)
        names = list(columns)
        tele = cls(time=np.asarray(columns[TIME], dtype=float), source=source)
        for group, members in VECTOR_GROUPS.items():
            present = [m for m in members if m in columns]
            if present and len(present) < len(members):
                missing = [m for m in members if m not in columns]
                raise KeyError(', '.join(missing))
            if present:
                setattr(tele, group, np.column_stack([columns[m] for m in members]))
        grouped = {TIME, *GYRO, *ATTITUDE, *REFERENCE}
        for name in names:
            if name.endswith(SPEED_SUFFIX) and name not in grouped:
                wheel_id = name[:-len(SPEED_SUFFIX)]
                friction = columns.get(wheel_id + FRICTION_SUFFIX)
                tele.wheels[wheel_id] = Wheel(np.asarray(columns[name], dtype=float),
                                              None if friction is None
                                              else np.asarray(friction, dtype=float))
        for name in names:
            if name in grouped or name.endswith(SPEED_SUFFIX):
                continue
            if name.endswith(FRICTION_SUFFIX):
                if name[:-len(FRICTION_SUFFIX)] not in tele.wheels:
                    raise KeyError(name[:-len(FRICTION_SUFFIX)] + SPEED_SUFFIX)
            elif name.startswith(TRUTH_PREFIX):
                tele.truth[name[len(TRUTH_PREFIX):]] = np.asarray(columns[name], dtype=float)
            else:
                tele.aux[name] = np.asarray(columns[name], dtype=float)
        return tele
