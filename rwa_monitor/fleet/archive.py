"""A fleet archive on disk: one folder per spacecraft, its passes and its calibration.

``ARCHIVE/<spacecraft>/`` holds recordings in any number and names: CSV files
(``.csv``), Parquet files (``.parquet``) with the same columns, rosbag2 folders, bare
``.mcap`` / ``.db3`` files, and files of CCSDS space packets (``.bin``) with their XTCE
definition and telemetry map beside them, ``telemetry.xml`` and ``telemetry_map.yaml``
for the whole folder or ``<pass>.xml`` and ``<pass>_map.yaml`` for one pass
(:func:`rwa_monitor.telemetry.read_telemetry` reads them all), and optionally
``calibration.yaml`` (``rwa-monitor calibrate``). Anything else is listed as ignored.
:func:`scan_pass` finds a pass's first stamp and columns cheaply (the first row of a CSV
file, the time column of a Parquet file, the whole of a recording or packet file), so
that passes are ordered by time, never by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import os
import pathlib

import numpy as np

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry import ARCHIVE_MAP, ARCHIVE_XTCE, is_packets, PACKET_SUFFIX
from rwa_monitor.telemetry import parquet_io
from rwa_monitor.telemetry import read_telemetry, rosbag_io, Telemetry, Wheel
from rwa_monitor.telemetry.ccsds_write import sibling_paths
from rwa_monitor.telemetry.schema import ATTITUDE, FRICTION_SUFFIX, GYRO, SPEED_SUFFIX, TIME

CALIBRATION = 'calibration.yaml'
METADATA = 'archive.yaml'
GYRO_COMPONENT = 'gyro'
# Files read as a pass, by the suffix of their name in any case (a rosbag2 folder is one
# by its content).
PASS_SUFFIXES = frozenset({*rosbag_io.BAG_SUFFIXES, '.csv', parquet_io.SUFFIX, PACKET_SUFFIX})


@dataclass(frozen=True)
class PassFile:
    """A readable pass: its name in the spacecraft's folder, path, size and first stamp."""

    name: str
    path: str
    size: int
    first: float
    columns: tuple[str, ...]


@dataclass
class Spacecraft:
    """One spacecraft's folder: candidate passes, calibration and the entries ignored.

    ``sizes``: each candidate's size in bytes when the folder was listed (a rosbag2
    folder's: its files').
    """

    id: str
    folder: str
    calibration: str | None
    candidates: list[str] = field(default_factory=list)
    ignored: dict[str, str] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)

    def name(self, path: str) -> str:
        """Return the name of a candidate (its path is the folder's, a separator, the name)."""
        return path[len(self.folder) + 1:]


def list_archive(archive: str | os.PathLike) -> list[Spacecraft]:
    """Return the spacecraft of an archive (sorted by id); ConfigError if there are none."""
    return [list_spacecraft(folder) for folder in spacecraft_folders(archive)]


def spacecraft_folders(archive: str | os.PathLike) -> list[str]:
    """Return the archive's spacecraft folders, sorted; ConfigError if there are none."""
    root = pathlib.Path(archive)
    if not root.is_dir():
        raise ConfigError(f'{root}: not a folder (expected ARCHIVE/<spacecraft>/<passes>)')
    folders = sorted(str(p) for p in root.iterdir() if p.is_dir()
                     and not p.name.startswith('.'))
    if not folders:
        raise ConfigError(f'{root}: no spacecraft folder')
    return folders


def list_folders(folders: list[str]) -> list[Spacecraft]:
    """Return :func:`list_spacecraft` of each folder (one ``list`` task, fleet/engine.py)."""
    return [list_spacecraft(folder) for folder in folders]


def list_spacecraft(folder: str | os.PathLike) -> Spacecraft:
    """Return one spacecraft folder's candidate passes with their sizes, and the rest.

    A pass is a file with a suffix of :data:`PASS_SUFFIXES` or a rosbag2 folder
    (``rosbag_io.is_recording``). The folder is listed once (``os.scandir``: names, types
    and sizes without a path object, a suffix found in one string search): a daily run
    lists every pass of the archive's life.
    """
    folder = pathlib.Path(folder)
    cal = folder / CALIBRATION
    craft = Spacecraft(folder.name, str(folder), str(cal) if cal.is_file() else None)
    with os.scandir(folder) as listing:
        entries = [(e, _suffix(e.name)) for e in sorted(listing, key=lambda e: e.name)]
    definitions = _packet_definitions(entries)
    for entry, suffix in entries:
        if entry.name.startswith('.') or entry.name == CALIBRATION \
                or entry.name in definitions:
            continue
        if suffix in PASS_SUFFIXES and entry.is_file():
            craft.sizes[entry.path] = _size(entry, folder=False)
        elif entry.is_dir() and rosbag_io.is_recording(entry.path):
            craft.sizes[entry.path] = _size(entry, folder=True)
        else:
            craft.ignored[entry.name] = ('not a recording (expected .csv, .parquet, '
                                         '.mcap, .db3, .bin or a rosbag2 folder)')
            continue
        craft.candidates.append(entry.path)
    return craft


def metadata(archive: str | os.PathLike) -> dict:
    """Return ARCHIVE/archive.yaml (e.g. ``epoch_utc``), or {} if there is none."""
    path = pathlib.Path(archive) / METADATA
    if not path.is_file():
        return {}
    from rwa_monitor.telemetry.yaml_file import read_yaml
    found = read_yaml(path)
    if not isinstance(found, dict):
        raise ConfigError(f'{path}: expected a mapping such as epoch_utc: '
                          '2026-01-01T00:00:00Z')
    return found


def _suffix(name: str) -> str:
    """Return ``os.path.splitext(name)[1].lower()`` of a bare name, in one string search."""
    dot = name.rfind('.')
    return name[dot:].lower() if dot > 0 and name[:dot].strip('.') else ''


def _size(entry: os.DirEntry, folder: bool) -> int:
    """Return an entry's size as :func:`size_of` gives it; -1 if it cannot be read."""
    try:
        return size_of(entry.path) if folder else entry.stat().st_size
    except OSError:
        return -1


def _packet_definitions(entries: list[tuple[os.DirEntry, str]]) -> set[str]:
    """Return the names of the XTCE and map files of the folder's packet passes.

    ``entries``: the folder's entries with their suffixes (:func:`_suffix`).
    """
    names = {ARCHIVE_XTCE, ARCHIVE_MAP}
    for entry, suffix in entries:
        if suffix == PACKET_SUFFIX and entry.is_file():
            names.update(p.name for p in sibling_paths(pathlib.Path(entry.path)))
    return names


def size_of(path: str) -> int:
    """Return the size in bytes of a file or of a folder's files."""
    target = pathlib.Path(path)
    if target.is_dir():
        return sum(p.stat().st_size for p in target.rglob('*') if p.is_file())
    return target.stat().st_size


def scan_pass(path: str) -> PassFile | str:
    """Return the pass's first stamp and columns, or the reason it cannot be read."""
    name = pathlib.Path(path).name
    try:
        if parquet_io.is_parquet(path):
            first, columns = parquet_io.first_stamp(path)
        elif rosbag_io.is_recording(path) or is_packets(path):
            tele = read_telemetry(path)
            first, columns = float(tele.time[0]), list(tele.columns())
        else:
            first, columns = _csv_first(path)
        return PassFile(name, path, size_of(path), first, tuple(columns))
    except Exception as err:  # noqa: BLE001 - a pass is outside data: any failure is its own
        return f'unreadable: {type(err).__name__}: {err}'


def scan_passes(paths: list[str]) -> list[PassFile | str]:
    """Return :func:`scan_pass` of each path (one ``scan`` task, fleet/plan.py)."""
    return [scan_pass(path) for path in paths]


def _csv_first(path: str) -> tuple[float, list[str]]:
    """Return the first time and the header of a CSV file (its first two lines only)."""
    import csv
    with open(path, newline='', encoding='utf-8-sig') as handle:
        reader = csv.reader(handle)
        header = [c.strip() for c in next(reader, [])]
        row = next(reader, None)
    if TIME not in header:
        raise ValueError(f'{path}: no {TIME} column in the header')
    if row is None:
        raise ValueError(f'{path}: no rows')
    return float(row[header.index(TIME)]), header


def components(columns: tuple[str, ...]) -> list[str]:
    """Return the components a pass with these columns feeds: wheels (friction), gyro."""
    found = [c[:-len(FRICTION_SUFFIX)] for c in columns if c.endswith(FRICTION_SUFFIX)
             and c[:-len(FRICTION_SUFFIX)] + SPEED_SUFFIX in columns]
    if all(c in columns for c in GYRO + ATTITUDE):
        found.append(GYRO_COMPONENT)
    return found


def read_pass(path: str) -> Telemetry | str:
    """Return a pass's telemetry, or the reason it cannot be read (never raises on data).

    A Parquet pass goes to its reader directly, as :func:`scan_pass` takes it: the general
    entry's checks for other formats cost 33 us of the 430 us of a pass of bench fleet's
    archive (6000 rows; 0.03 s of CPU over its 840 passes).
    """
    try:
        if parquet_io.is_parquet(path):
            tele = parquet_io.read_parquet(path)
        else:
            tele = read_telemetry(path)
    except Exception as err:  # noqa: BLE001 - a pass is outside data: any failure is its own
        return f'unreadable: {type(err).__name__}: {err}'
    if not len(tele):
        return 'no rows'
    return tele


def after(tele: Telemetry, last_time: float) -> tuple[Telemetry, int]:
    """Return the rows stamped after ``last_time`` and the number dropped (a prefix)."""
    start = int(np.searchsorted(tele.time, last_time, side='right'))
    if start == 0:
        return tele, 0

    def cut(values: np.ndarray | None) -> np.ndarray | None:
        return None if values is None else values[start:]

    kept = Telemetry(
        time=tele.time[start:],
        wheels={k: Wheel(cut(w.speed), cut(w.friction)) for k, w in tele.wheels.items()},
        gyro=cut(tele.gyro), attitude=cut(tele.attitude),
        reference_rate=cut(tele.reference_rate),
        aux={k: cut(v) for k, v in tele.aux.items()},
        truth={k: cut(v) for k, v in tele.truth.items()}, source=tele.source,
        present={k: cut(m) for k, m in tele.present.items()})
    return kept, start
