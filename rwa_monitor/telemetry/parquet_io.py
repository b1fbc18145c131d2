"""Telemetry Parquet files: the CSV schema's columns (docs/contracts.md), one row per sample.

Read with pyarrow: every column must be numeric (null cells are read as NaN, as empty CSV
cells are); ``time`` must be finite and strictly increasing, checked as for CSV. Any
encoding and compression pyarrow reads is accepted.

Writing (:func:`write_parquet`: tests, recordings converted by the tools, bench fleet's
archives): every column PLAIN, with no dictionary and no compression. A dictionary, the
library's default, never pays for telemetry floats, whose values hardly repeat: it is kept
for a pass of 6000 rows (48 KB of values, under the 1 MB dictionary page) and costs its
decoding and gather, and snappy saves nothing on noisy float64. Measured on 200 passes of
bench fleet's archive (6000 rows x 9 columns, CPU of ``read_parquet`` a pass, median of
7): the default 425 us and 499 KB a pass, without a dictionary 341 us and 411 KB, and
without a dictionary or compression 264 us and 435 KB; on the same rows joined into files
of 252,000 rows 449, 385 and 333 us per 6000 rows. Byte-stream split with zstd would make
files 0.59 of the default's size at the default's reading cost (446 us): the fleet reads
every pass once a day and pays the reading in CPU, so speed won.
"""

from __future__ import annotations

import math
import os

import numpy as np

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry.atomic import atomic_write
from rwa_monitor.telemetry.csv_io import _check_time
from rwa_monitor.telemetry.schema import Telemetry, TIME

SUFFIX = '.parquet'
# Parquet's physical types whose statistics are the numbers themselves (first_stamp;
# integers may carry a logical type: decimals, times).
NUMBERS = ('DOUBLE', 'FLOAT')


def is_parquet(path: str | os.PathLike) -> bool:
    """Return True for a path ending in ``.parquet`` (any case)."""
    return os.fspath(path).lower().endswith(SUFFIX)


def read_parquet(path: str | os.PathLike, columns: list[str] | None = None) -> Telemetry:
    """Read a telemetry Parquet file; raise TelemetrySchemaError naming the file and column.

    ``columns``: read only these (``time`` is always read); None: every column.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq
    path = os.fspath(path)
    try:
        # One file object, one thread: a pass is small, and read_table's dataset machinery
        # and thread pool cost three times the reading (0.39 against 1.17 ms of CPU for a
        # pass of 6000 rows x 9 columns, bench fleet's archive). No pre-buffering: its
        # coalesced reads, on Arrow's I/O threads, are for remote file systems; on local
        # files the process's CPU for bench fleet's 840 passes went 0.35 -> 0.27 s, for
        # the same rows joined in 20 files 0.20 -> 0.18 s (median of 10, interleaved).
        # The file opened as Arrow's own file object, not by path: no file system to
        # resolve (CPU of a 6000-row pass 0.92 of the path's, median of 15 rounds over
        # 252 passes of bench fleet's archive).
        with pa.OSFile(path) as source, pq.ParquetFile(source, pre_buffer=False) as handle:
            wanted = None if columns is None else [
                c for c in handle.schema_arrow.names if c == TIME or c in columns]
            table = handle.read(columns=wanted, use_threads=False)
    except (OSError, pa.ArrowException) as err:
        raise TelemetrySchemaError(path, f'not a readable Parquet file: {err}') from None
    if TIME not in table.column_names:
        raise TelemetrySchemaError(path, 'missing required column', column=TIME)
    data: dict[str, np.ndarray] = {}
    for name, column in zip(table.column_names, table.columns):
        data[name] = _float_column(path, name, column)
    _check_time(path, data[TIME])
    try:
        return Telemetry.from_columns(data, source=path)
    except KeyError as err:
        raise TelemetrySchemaError(path, 'missing column(s) of a group',
                                   column=err.args[0]) from None


def _float_column(path: str, name: str, column) -> np.ndarray:
    """Return a numeric Arrow column as float64 values, null cells NaN.

    A float64 column without nulls in one chunk (what the fleet's passes hold) is the
    reader's own buffer seen as a writable array: no copy, and none later either, where
    the kernels want writable arrays (core/jit.py ``kernel_array``; the table is this
    reader's alone and dropped on return). Any other numeric column is converted (a
    copy; integers exactly as floats). 8,505 copies fewer on 6 spacecraft x 21 days of
    the fleet bench's archive.
    """
    import pyarrow as pa
    kind = column.type
    if kind == pa.float64() and column.num_chunks == 1 and column.null_count == 0:
        chunk = column.chunk(0)
        values = chunk.buffers()[1]
        if values is not None and values.is_mutable:
            return np.frombuffer(values, dtype=np.float64, count=len(chunk),
                                 offset=chunk.offset * 8)
    if not (pa.types.is_floating(kind) or pa.types.is_integer(kind)):
        hint = (': times are seconds as numbers (docs/contracts.md); write the stamps '
                'as seconds, e.g. since the archive epoch' if pa.types.is_temporal(
                    kind) else '')
        raise TelemetrySchemaError(path, f'not a numeric column ({kind}){hint}',
                                   column=name)
    return np.array(column, dtype=float)


def first_stamp(path: str | os.PathLike) -> tuple[float, list[str]]:
    """Return the first ``time`` of a Parquet file and its column names.

    From the footer alone where it can be: the smallest ``time`` of the first row group
    that has rows, as its statistics record it (exact for numbers), when they are there
    and count no null, and it is finite and not zero (a writer may record -0.0 for 0.0).
    That is the first stamp of every file the reader accepts (``time`` finite and strictly
    increasing); a file it refuses (statistics leave NaN out) is ordered by its smallest
    finite stamp instead, and is not examined either way (unreadable, or late in a run
    with a state). Otherwise the ``time`` column of that row group is read, on one thread.
    0.15 -> 0.05 ms of CPU a pass of 6000 rows (median of 7 over 200 passes of bench
    fleet's archive; 0.76 ms with read_schema + read_table), the same stamps on all 840.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq
    path = os.fspath(path)
    try:
        with pa.OSFile(path) as source, pq.ParquetFile(source, pre_buffer=False) as handle:
            names = handle.schema_arrow.names
            if TIME not in names:
                raise TelemetrySchemaError(path, 'missing required column', column=TIME)
            meta = handle.metadata
            groups = [g for g in range(meta.num_row_groups) if meta.row_group(g).num_rows]
            if not groups:
                raise TelemetrySchemaError(path, 'no rows')
            first = _smallest_time(meta.row_group(groups[0]))
            if first is None:
                first = handle.read_row_group(groups[0], columns=[TIME],
                                              use_threads=False).column(TIME)[0].as_py()
    except (OSError, pa.ArrowException) as err:
        raise TelemetrySchemaError(path, f'not a readable Parquet file: {err}') from None
    if not isinstance(first, (int, float)):
        raise TelemetrySchemaError(path, f'the first time is {first!r}, not a number',
                                   column=TIME)
    return float(first), names


def _smallest_time(group: object) -> float | None:
    """Return a row group's smallest ``time`` from its statistics, None if not usable."""
    for i in range(group.num_columns):
        column = group.column(i)
        if column.path_in_schema != TIME:
            continue
        stats = column.statistics
        if (stats is None or not stats.has_min_max or not stats.has_null_count
                or stats.null_count or column.physical_type not in NUMBERS):
            return None
        smallest = stats.min
        if isinstance(smallest, bool) or not isinstance(smallest, (int, float)):
            return None
        return float(smallest) if math.isfinite(smallest) and smallest != 0 else None
    return None


def write_parquet(path: str | os.PathLike, telemetry: Telemetry) -> None:
    """Write a telemetry record as Parquet (float64 columns, canonical order), atomically.

    Columns PLAIN, without a dictionary or compression (module docstring, "Writing").
    """
    import pyarrow as pa
    import pyarrow.parquet as pq
    table = pa.table({name: np.asarray(values, dtype=float)
                      for name, values in telemetry.columns().items()})
    with atomic_write(path, 'wb', encoding=None) as handle:
        pq.write_table(table, handle, use_dictionary=False, compression='none')
