"""The fleet's cumulative event history: every run's events, what is new, what is replaced.

A run's events are those its runners declared while fed (declarations and revisions) and,
at the end of the run, the end-of-record categorisation of each open declaration
(``end_of_run``: docs/llr.md "End of record"). The next run that feeds a spacecraft new
passes continues its runners from the state taken before those end-of-run events, as a
full run would; they are then ``superseded`` (kept, marked) by what the later run finds.
So the history's events that are not superseded equal, field for field, those of one run
over the whole archive, however the archive was split into successive runs
(test/test_fleet_history.py).

Each row holds every field of the event as its own column (``detect``'s fields, the
details of every event: a field an event lacks is null), ``spacecraft``, ``run`` (the
state generation that found it, 0 without a state), ``end_of_run``, ``superseded`` and,
in a run's outputs, ``new``; ``event_json`` keeps the exact event for reading back. With
an archive epoch, ``time_utc`` and ``declared_time_utc`` (ISO 8601, UTC).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import datetime as dt
import io
import json
import math
from typing import Any, Iterable, Mapping, Sequence

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.records import decode, encode

FLAGS = ('spacecraft', 'run', 'end_of_run', 'superseded')


@dataclass(frozen=True)
class Entry:
    """One event of the history with the flags that place it.

    ``event_json``: the event's ``event_json`` text when it was read from a history
    (:func:`from_parquet`), written again as it was instead of encoding the event anew.
    """

    spacecraft: str
    event: AnomalyEvent
    run: int
    end_of_run: bool = False
    superseded: bool = False
    event_json: str | None = field(default=None, compare=False, repr=False)


def entries(spacecraft: str, events: Iterable[AnomalyEvent], run: int,
            end_of_run: bool = False) -> list[Entry]:
    """Return one run's events of a spacecraft as history entries."""
    return [Entry(spacecraft, e, run, end_of_run) for e in events]


def supersede(history: Sequence[Entry], continued: Iterable[str]) -> list[Entry]:
    """Return the history with the end-of-run events of ``continued`` spacecraft superseded.

    A spacecraft is continued when this run fed it new passes: its runners resumed from
    the state before those events, and this run's own events replace them.
    """
    continued = set(continued)
    return [replace(h, superseded=True)
            if h.end_of_run and not h.superseded and h.spacecraft in continued else h
            for h in history]


def current(history: Sequence[Entry]) -> list[Entry]:
    """Return the entries not superseded by a later run (as one run over the archive)."""
    return [h for h in history if not h.superseded]


def order(history: Iterable[Entry]) -> list[Entry]:
    """Return the entries sorted by change time, spacecraft, component and revision."""
    return sorted(history, key=lambda h: (h.event.time, h.spacecraft, h.event.component,
                                          h.event.revision, h.run))


def rows(history: Sequence[Entry], new_run: int | None = None,
         epoch: dt.datetime | None = None) -> list[dict[str, Any]]:
    """Return the events table of the module docstring, flagging the new run's events."""
    out = []
    for h in history:
        row: dict[str, Any] = {'spacecraft': h.spacecraft, **h.event.to_json()}
        if epoch is not None:
            row['time_utc'] = utc(epoch, h.event.time)
            row['declared_time_utc'] = utc(epoch, h.event.declared_time)
        row.update(run=h.run, end_of_run=h.end_of_run, superseded=h.superseded)
        if new_run is not None:
            row['new'] = h.run == new_run
        out.append(row)
    return out


def utc(epoch: dt.datetime, seconds: float) -> str | None:
    """Return ``epoch + seconds`` as ISO 8601 UTC with milliseconds (None if not finite)."""
    if not math.isfinite(seconds):
        return None
    moment = epoch + dt.timedelta(seconds=seconds)
    return moment.astimezone(dt.timezone.utc).isoformat(timespec='milliseconds').replace(
        '+00:00', 'Z')


def to_parquet(history: Sequence[Entry]) -> bytes:
    """Return the history as Parquet (flat columns plus ``event_json`` to read it back)."""
    table = rows(history)
    for row, h in zip(table, history):
        row['event_json'] = h.event_json or json.dumps(encode(h.event)[0], allow_nan=False,
                                                       sort_keys=True)
    return parquet(table, {'spacecraft': 'string', 'event_json': 'string', 'run': 'int64',
                           'end_of_run': 'bool_', 'superseded': 'bool_'})


def from_parquet(data: bytes) -> list[Entry]:
    """Return the history of :func:`to_parquet`'s bytes (ValueError if it is not one)."""
    if not data:
        return []
    import pyarrow as pa
    import pyarrow.parquet as pq
    try:
        table = pq.read_table(io.BytesIO(data), columns=['event_json', *FLAGS]).to_pylist()
    except (pa.ArrowException, OSError) as err:
        raise ValueError(f'not an event history: {err}') from None
    out = []
    for row in table:
        event = decode(AnomalyEvent, json.loads(row['event_json']), {})
        if not (isinstance(row['run'], int) and all(isinstance(row[k], bool) for k in
                                                    ('end_of_run', 'superseded'))):
            raise ValueError('an event history row has bad flags')
        out.append(Entry(str(row['spacecraft']), event, row['run'], row['end_of_run'],
                         row['superseded'], row['event_json']))
    return out


def parquet(table: Sequence[Mapping[str, Any]], empty: Mapping[str, str]) -> bytes:
    """Return rows as Parquet bytes: every key of any row is a column (null where absent).

    A column whose values differ in type between rows (or hold lists or mappings) is
    written as JSON text; ``empty``: the columns of a table without rows.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq
    if table:
        names: dict[str, None] = {}
        for row in table:
            names.update(dict.fromkeys(row))
        full = [{k: row.get(k) for k in names} for row in table]
        try:
            arrow = pa.Table.from_pylist(full)
        except pa.ArrowException:
            arrow = pa.Table.from_pylist(_uniform(full))
    else:
        arrow = pa.table({k: pa.array([], type=getattr(pa, t)()) for k, t in empty.items()})
    buffer = io.BytesIO()
    pq.write_table(arrow, buffer)
    return buffer.getvalue()


def _uniform(table: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Return the rows with every field of more than one type written as JSON text."""
    kinds: dict[str, set] = {}
    for row in table:
        for key, value in row.items():
            if value is not None:
                kinds.setdefault(key, set()).add(float if type(value) is int
                                                 else type(value))
    mixed = {k for k, found in kinds.items() if len(found) > 1 or found & {list, dict}}
    return [{k: json.dumps(v) if k in mixed and v is not None else v
             for k, v in row.items()} for row in table]
