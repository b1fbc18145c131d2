"""The fleet's output folder (docs/contracts.md "Fleet outputs"), switched in as one set.

``events.json`` and ``events.parquet`` (the event history: every field of an event as its
own column, ``spacecraft``, UTC times where the archive has an epoch, ``new`` for this
run's events, ``superseded`` for end-of-run events a later run replaced; fleet/history.py),
``summary.json``, ``trend.parquet`` (one row per spacecraft, wheel and pass) and
``report.html`` (fleet/report.py). The five files are built in a folder beside ``-o`` and
swapped in whole (telemetry/atomic.py FolderOutput): a run killed at any point leaves the
previous set or the new one, never a mix. An existing ``-o`` folder is replaced only if it
is a fleet output folder (its summary.json says so) holding nothing but these files.
"""

from __future__ import annotations

import json
import math
import pathlib
from typing import Any, TYPE_CHECKING

from rwa_monitor.exceptions import OutputError
from rwa_monitor.fleet.history import parquet
from rwa_monitor.telemetry.atomic import FolderOutput, write_bytes_atomic, write_text_atomic

if TYPE_CHECKING:
    from rwa_monitor.fleet.result import FleetResult

FORMAT = 'rwa_monitor.fleet.outputs'
FILES = ('events.json', 'events.parquet', 'summary.json', 'trend.parquet', 'report.html')
EVENT_COLUMNS = {'spacecraft': 'string', 'detector': 'string', 'component': 'string',
                 'kind': 'string', 'time': 'float64', 'index': 'int64',
                 'declared_time': 'float64', 'declared_index': 'int64',
                 'p_value': 'float64', 'revision': 'int64', 'new': 'bool_'}


def check_output(out: pathlib.Path) -> None:
    """Raise OutputError unless ``out`` is new, empty, or an earlier fleet output folder."""
    FolderOutput(out, FILES, 'rwa-monitor fleet outputs')   # refuses foreign files
    summary = out / 'summary.json'
    present = [name for name in FILES if (out / name).exists()]
    if not present:
        return
    try:
        ours = json.loads(summary.read_text()).get('format') == FORMAT
    except (OSError, ValueError, AttributeError):
        ours = False
    if not ours:
        raise OutputError(f'{out}: not replacing this folder: its {", ".join(present)} '
                          'were not written by rwa-monitor fleet (no fleet summary.json); '
                          'choose a new or empty folder')


def write_outputs(out: pathlib.Path, result: FleetResult) -> list[pathlib.Path]:
    """Write the five output files of a FleetResult as one set; return their paths."""
    from rwa_monitor.fleet.report import render
    check_output(out)
    rows = result.rows()
    summary = {'format': FORMAT, **result.summary}
    report = render(rows, summary, result.trend, result.trends, result.epoch)
    with FolderOutput(out, FILES, 'rwa-monitor fleet outputs') as work:
        work.mkdir(exist_ok=True)
        write_text_atomic(work / FILES[0], _json({'events': rows}))
        write_bytes_atomic(work / FILES[1], parquet(rows, EVENT_COLUMNS))
        write_text_atomic(work / FILES[2], _json(summary))
        write_bytes_atomic(work / FILES[3], result.trend.to_parquet())
        write_text_atomic(work / FILES[4], report)
    if not (out / FILES[2]).exists():
        raise OutputError(f'{out}: the outputs were not written')
    return [out / name for name in FILES]


def _json(document: Any) -> str:
    """Return strict JSON (a non-finite number as null; other objects as text)."""
    return json.dumps(_strict(document), indent=1, allow_nan=False, default=str) + '\n'


def _strict(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value
