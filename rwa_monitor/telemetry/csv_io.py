"""Telemetry CSV files: a header row, one row per sample, numbers only.

Empty cells, ``nan`` and ``inf`` are read as such (the detectors skip and count them);
anything else that is not a number is an error naming the file, the line and the column.
``time`` must be finite and strictly increasing. A UTF-8 byte-order mark and CRLF line
ends are accepted; bytes that are not UTF-8 text are an error naming the file.
"""

from __future__ import annotations

import csv
import math
import os
import warnings

import numpy as np

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry.atomic import atomic_write
from rwa_monitor.telemetry.schema import name_problem, Telemetry, TIME, wheel_id_of


_ENCODING = 'utf-8-sig'  # UTF-8, with or without a byte-order mark


def read_csv(path: str | os.PathLike) -> Telemetry:
    """Read a telemetry CSV file; raise TelemetrySchemaError naming file, line and column."""
    path = os.fspath(path)
    try:
        return _read(path)
    except UnicodeDecodeError as err:
        raise TelemetrySchemaError(
            path, f'not a CSV text file (byte {err.start} is not UTF-8); expected a CSV '
            'file, a rosbag2 folder, or a .mcap or .db3 file') from None


def _read(path: str) -> Telemetry:
    try:
        with open(path, newline='', encoding=_ENCODING) as handle:
            header = next(csv.reader(handle), None)
    except OSError as err:
        raise TelemetrySchemaError(path, f'cannot read: {err.strerror}') from None
    except csv.Error as err:
        raise TelemetrySchemaError(path, f'not a CSV header row: {err}', 1) from None
    if not header:
        raise TelemetrySchemaError(path, 'empty file: expected a header row', line=1)
    header = [name.strip() for name in header]
    seen: set[str] = set()     # a set, not header.index: linear in the columns
    for i, name in enumerate(header):
        if not name:
            raise TelemetrySchemaError(path, f'empty column name at position {i + 1}', 1)
        problem = name_problem(name, wheel_id_of(name))
        if problem:
            raise TelemetrySchemaError(path, problem, 1, name[:80])
        if name in seen:
            raise TelemetrySchemaError(path, 'duplicate column', 1, name)
        seen.add(name)
    if TIME not in header:
        raise TelemetrySchemaError(path, 'missing required column', 1, TIME)
    data = _parse_rows(path, header)
    columns = {name: data[:, i] for i, name in enumerate(header)}
    _check_time(path, columns[TIME])
    try:
        return Telemetry.from_columns(columns, source=path)
    except KeyError as err:
        raise TelemetrySchemaError(path, 'missing column(s) of a group', 1,
                                   err.args[0]) from None


def _parse_rows(path: str, header: list[str]) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', UserWarning)  # a header-only file is valid
        try:
            data = np.loadtxt(path, delimiter=',', skiprows=1, ndmin=2, dtype=float,
                              encoding=_ENCODING)
        except ValueError:
            data = None
    if data is not None and data.shape[0] == 0:
        return np.empty((0, len(header)))
    if data is not None and data.shape[1] == len(header):
        return data
    return _parse_slowly(path, header)


def _parse_slowly(path: str, header: list[str]) -> np.ndarray:
    """Parse cell by cell: empty cells become NaN, anything else unreadable is an error."""
    rows = []
    with open(path, newline='', encoding=_ENCODING) as handle:
        reader = csv.reader(handle)
        next(reader)
        try:
            for line, row in enumerate(reader, start=2):
                rows.append(_values(path, header, line, row))
        except csv.Error as err:
            raise TelemetrySchemaError(path, f'not a CSV row: {err}',
                                       reader.line_num) from None
    return np.array(rows, dtype=float).reshape(len(rows), len(header))


def _values(path: str, header: list[str], line: int, row: list[str]) -> list[float]:
    if len(row) != len(header):
        raise TelemetrySchemaError(
            path, f'expected {len(header)} values, found {len(row)}', line)
    values = []
    for name, cell in zip(header, row):
        text = cell.strip()
        try:
            values.append(float(text) if text else np.nan)
        except ValueError:
            shown = repr(cell) if len(cell) <= 80 else repr(cell[:80]) + '...'
            raise TelemetrySchemaError(path, f'not a number: {shown}', line, name) from None
    return values


def _check_time(path: str, time: np.ndarray) -> None:
    # Strictly increasing with finite ends: every stamp is finite (a NaN or an infinity
    # inside breaks the increase), and the file is good without the searches below. The
    # comparison of shifted views makes no array of differences (10 against 18 us for
    # 6000 stamps).
    if time.size and math.isfinite(time[0]) and math.isfinite(time[-1]) and bool(
            (time[1:] > time[:-1]).all()):
        return
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise TelemetrySchemaError(path, 'time must be finite', int(bad[0]) + 2, TIME)
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise TelemetrySchemaError(
            path, f'time must be strictly increasing ({time[k]!r} follows {time[k - 1]!r})',
            k + 2, TIME)


def write_csv(path: str | os.PathLike, telemetry: Telemetry, fmt: str = '%.10g') -> None:
    """Write a telemetry record as CSV (columns in the canonical order)."""
    columns = telemetry.columns()
    lengths = {name: len(values) for name, values in columns.items()}
    if len(set(lengths.values())) > 1:
        raise ValueError(f'columns of different lengths: {lengths}')
    table = np.column_stack([np.asarray(v, dtype=float) for v in columns.values()])
    with atomic_write(path, 'w', newline='') as handle:
        np.savetxt(handle, table, delimiter=',', fmt=fmt, header=','.join(columns),
                   comments='')
