"""The fleet's output folder (docs/contracts.md "Fleet outputs"), every file atomic.

``events.json`` and ``events.parquet`` (detect's event fields plus ``spacecraft``; in
Parquet a detail an event lacks is null, and a field whose values differ in type between
events is written as JSON text), ``summary.json``, ``trend.parquet`` (one row per
spacecraft, wheel and pass) and ``report.html`` (rwa_monitor/fleet/report.py).
"""

from __future__ import annotations

import io
import json
import pathlib
from typing import Any

from rwa_monitor.exceptions import OutputError
from rwa_monitor.telemetry.atomic import write_bytes_atomic, write_text_atomic

TREND_COLUMNS = {'spacecraft': 'string', 'wheel': 'string', 'pass': 'string',
                 't_start': 'float64', 't_end': 'float64', 'samples': 'int64',
                 'dry': 'float64', 'dry_se': 'float64', 'viscous': 'float64',
                 'viscous_se': 'float64', 'relative_to': 'string'}


def write_outputs(out: pathlib.Path, result: Any) -> list[pathlib.Path]:
    """Write the five output files of a FleetResult into ``out``; return their paths."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f'{out}: cannot make the output folder: {err}') from None
    paths = [out / name for name in ('events.json', 'events.parquet', 'summary.json',
                                     'trend.parquet', 'report.html')]
    write_text_atomic(paths[0], json.dumps({'events': result.events}, indent=1) + '\n')
    write_bytes_atomic(paths[1], _parquet(result.events, {'spacecraft': 'string'}))
    write_text_atomic(paths[2], json.dumps(result.summary, indent=1, default=str) + '\n')
    write_bytes_atomic(paths[3], _parquet(result.trend, TREND_COLUMNS))
    from rwa_monitor.fleet.report import write_report
    write_report(paths[4], result.events, result.summary, result.trend)
    return paths


def _parquet(rows: list[dict[str, Any]], empty: dict[str, str]) -> bytes:
    """Return rows as Parquet bytes (``empty``: the columns of a table without rows)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    if rows:
        try:
            table = pa.Table.from_pylist(rows)
        except pa.ArrowException:      # a field of mixed types: that column as JSON text
            table = pa.Table.from_pylist(_uniform(rows))
    else:
        table = pa.table({k: pa.array([], type=getattr(pa, t)()) for k, t in empty.items()})
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    return buffer.getvalue()


def _uniform(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Return the rows with every field of more than one type written as JSON text."""
    kinds: dict[str, set] = {}
    for row in rows:
        for key, value in row.items():
            if value is not None:
                kinds.setdefault(key, set()).add(float if type(value) is int
                                                 else type(value))
    mixed = {k for k, found in kinds.items() if len(found) > 1 or found & {list, dict}}
    return [{k: json.dumps(v) if k in mixed and v is not None else v
             for k, v in row.items()} for row in rows]
