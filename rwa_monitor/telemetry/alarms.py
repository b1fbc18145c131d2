"""Latched anomaly records and their JSON Lines journal (ROS-free; docs/nodes.md "Alarms").

An anomaly a detector declares is *latched*: it stays active until an operator
acknowledges it, whatever the detector does afterwards (restart on a parameter change,
recovery, node restart). The model is the alarm model of process control: a record is
``active`` until acknowledged, and ``cleared`` once the detector reports the component
healthy again (a cleared record still waits for its acknowledgement).

:class:`AlarmStore` holds the records of one node. With a journal path every event and
every acknowledgement is appended to that file as one JSON object per line, flushed and
fsynced before :meth:`AlarmStore.declare` returns; :meth:`AlarmStore.load` reads it back
at start and keeps the unacknowledged records (a line cut short by a crash is skipped and
counted), then rewrites the journal with only those (through ``atomic_write``), so the
file does not grow without bound across restarts. A path that is not a journal (a foreign
file, a folder, a device) is refused with :class:`~rwa_monitor.exceptions.JournalError`
and left untouched (:func:`check_journal`).
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
import os
import pathlib
import stat
import time
from typing import Any, Callable, Iterable

from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import JournalError
from rwa_monitor.telemetry.atomic import append_bytes, write_text_atomic

RECOVERY_KINDS = ('healthy',)
MAX_ALARMS = 10_000
# Every journal line starts so (json.dumps of a dict whose first key is 'record').
JOURNAL_START = b'{"record": "'
_CORE = (keys.DETECTOR, keys.COMPONENT, keys.KIND, keys.CHANGE_TIME, keys.CHANGE_INDEX,
         keys.DECLARATION_TIME, keys.DECLARATION_INDEX, keys.P_VALUE, keys.REVISION)


def event_key(event: AnomalyEvent) -> str:
    """Return the identity of the change an event belongs to (revisions share it)."""
    return f'{event.detector}/{event.component}/{event.index}'


def kind_key(event: AnomalyEvent) -> str:
    """Return an identity per change and kind (detectors that flag kinds separately)."""
    return f'{event_key(event)}/{event.kind}'


def event_record(event: AnomalyEvent) -> dict[str, Any]:
    """Return the journal form of an event (``fields()``, non-finite floats as null)."""
    out = {}
    for key, value in event.fields().items():
        if isinstance(value, float) and not math.isfinite(value):
            value = None
        out[key] = value
    return out


def event_from_record(fields: dict[str, Any]) -> AnomalyEvent:
    """Return the AnomalyEvent of :func:`event_record` (ValueError/KeyError if malformed)."""
    def real(name: str) -> float:
        value = fields.get(name)
        return math.nan if value is None else float(value)

    return AnomalyEvent(
        detector=str(fields[keys.DETECTOR]), component=str(fields[keys.COMPONENT]),
        kind=str(fields[keys.KIND]), time=real(keys.CHANGE_TIME),
        index=int(fields[keys.CHANGE_INDEX]), declared_time=real(keys.DECLARATION_TIME),
        declared_index=int(fields[keys.DECLARATION_INDEX]), p_value=real(keys.P_VALUE),
        revision=int(fields.get(keys.REVISION) or 0),
        details={k: v for k, v in fields.items() if k not in _CORE})


def check_journal(path: str | os.PathLike) -> None:
    """Raise JournalError unless ``path`` is missing, empty, or a journal this module wrote.

    A journal's first line is a record written by :class:`AlarmStore` (JOURNAL_START, a
    line cut short by a crash included); a folder, a FIFO, a device or a file starting
    with anything else is refused and left untouched.
    """
    path = pathlib.Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return
    except OSError as err:
        raise JournalError(f'events_file {path}: cannot examine: {err.strerror or err}'
                           ) from None
    if not stat.S_ISREG(mode):
        kind = 'a folder' if stat.S_ISDIR(mode) else 'not a regular file'
        raise JournalError(f'events_file {path}: is {kind}, not an alarm journal; '
                           'refusing to use it (give a new file name)')
    try:
        with open(path, 'rb') as handle:
            head = handle.read(len(JOURNAL_START) + 64).lstrip()
    except OSError as err:
        raise JournalError(f'events_file {path}: cannot read: {err.strerror or err}') from None
    first = head.split(b'\n', 1)[0].strip()
    if first and not (first.startswith(JOURNAL_START) or JOURNAL_START.startswith(first)):
        raise JournalError(f'events_file {path}: exists and is not an alarm journal (its '
                           'first line is not a journal record); refusing to use or '
                           'overwrite it (give a new file name)')


@dataclass
class Alarm:
    """One latched anomaly: its latest event, when it was declared, and its state."""

    key: str
    event: AnomalyEvent
    declared_wall_s: float
    cleared: bool = False
    acknowledged: bool = False


class AlarmStore:
    """The latched anomalies of one node, optionally journalled to a JSON Lines file.

    ``key(event)`` names the record an event belongs to (:func:`event_key`: a change and
    its revisions; :func:`kind_key`: one record per kind).
    ``declare(events)`` latches each event (a revision updates its record, a recovery
    kind clears the component's records); ``acknowledge(component)`` ends the records of
    one component (or all); ``active()`` lists the unacknowledged ones, oldest first. At
    most ``max_alarms`` records are held; beyond, the oldest is dropped and counted
    (``counters['dropped']``). Journal write failures are counted (``journal_errors``)
    and leave the in-memory record latched; ``last_error`` says why.
    """

    def __init__(self, path: str | os.PathLike | None = None, *,
                 max_alarms: int = MAX_ALARMS,
                 key: Callable[[AnomalyEvent], str] = event_key) -> None:
        self.path = pathlib.Path(path) if path else None
        self.key = key
        self.max_alarms = max_alarms
        self._alarms: dict[str, Alarm] = {}
        self.counters = {'declared': 0, 'acknowledged': 0, 'cleared': 0, 'dropped': 0,
                         'journal_errors': 0, 'journal_bad_lines': 0, 'reloaded': 0}
        self.last_error = ''

    # ----------------------------------------------------------------------- journal
    def load(self) -> list[Alarm]:
        """Read the journal; keep its unacknowledged records; compact it; return them.

        A missing file is an empty journal. Lines that are not a journal record (a write
        cut short by a crash) are skipped and counted.
        """
        if self.path is None:
            return []
        check_journal(self.path)
        if not self.path.exists():
            return []
        try:
            text = self.path.read_text(encoding='utf-8', errors='replace')
        except OSError as err:
            self._failed(err)
            return []
        for line in text.splitlines():
            if not line.strip():
                continue
            try:
                record = json.loads(line)
                if record.get('record') == 'acknowledged':
                    self._acknowledge_key(str(record['key']), None)
                else:
                    self._latch(event_from_record(record['event']),
                                float(record.get('wall_time_s', 0.0)), None)
            except (ValueError, KeyError, TypeError, AttributeError):
                self.counters['journal_bad_lines'] += 1
        kept = self.active()
        self.counters['reloaded'] = len(kept)
        self._compact(kept)
        return kept

    def _compact(self, kept: list[Alarm]) -> None:
        lines = [json.dumps({'record': 'event', 'key': a.key, 'wall_time_s': a.declared_wall_s,
                             'event': event_record(a.event)}) + '\n' for a in kept]
        try:
            write_text_atomic(self.path, ''.join(lines))
        except OSError as err:
            self._failed(err)

    def _append(self, record: dict[str, Any]) -> None:
        if self.path is None:
            return
        line = (json.dumps(record, allow_nan=False) + '\n').encode('utf-8')
        try:
            append_bytes(self.path, line)
        except OSError as err:
            self._failed(err)

    def _failed(self, err: OSError) -> None:
        self.counters['journal_errors'] += 1
        self.last_error = f'{self.path}: {err.strerror or err}'

    # ------------------------------------------------------------------------ state
    def declare(self, events: Iterable[AnomalyEvent]) -> list[Alarm]:
        """Latch (and journal) each event; return the records it touched."""
        touched = []
        for event in events:
            wall = time.time()
            self._append({'record': 'event', 'key': self.key(event), 'wall_time_s': wall,
                          'event': event_record(event)})
            alarm = self._latch(event, wall, self.counters)
            if alarm is not None:
                touched.append(alarm)
        return touched

    def _latch(self, event: AnomalyEvent, wall: float, counters: dict | None
               ) -> Alarm | None:
        if event.kind in RECOVERY_KINDS:
            for alarm in self._alarms.values():
                if alarm.event.component == event.component and not alarm.cleared:
                    alarm.cleared = True
                    if counters is not None:
                        counters['cleared'] += 1
            return None
        key = self.key(event)
        alarm = self._alarms.get(key)
        if alarm is None:
            alarm = self._alarms[key] = Alarm(key, event, wall)
            if counters is not None:
                counters['declared'] += 1
            while len(self._alarms) > self.max_alarms:
                del self._alarms[next(iter(self._alarms))]
                self.counters['dropped'] += 1
        elif event.revision >= alarm.event.revision:
            alarm.event = event
        return alarm

    def acknowledge(self, component: str | None = None) -> list[Alarm]:
        """Acknowledge the active records of ``component`` (None: all); return them."""
        done = [a for a in self.active() if component is None or
                a.event.component == component]
        for alarm in done:
            self._append({'record': 'acknowledged', 'key': alarm.key,
                          'wall_time_s': time.time()})
            self._acknowledge_key(alarm.key, self.counters)
        return done

    def _acknowledge_key(self, key: str, counters: dict | None) -> None:
        if self._alarms.pop(key, None) is not None and counters is not None:
            counters['acknowledged'] += 1

    def active(self, component: str | None = None) -> list[Alarm]:
        """Return the unacknowledged records (of ``component``), oldest first."""
        return [a for a in self._alarms.values()
                if component is None or a.event.component == component]

    def components(self) -> list[str]:
        """Return the components with an active record."""
        return sorted({a.event.component for a in self._alarms.values()})

    def summary(self, component: str) -> tuple[str, dict[str, Any]] | None:
        """Return ``(message, KeyValues)`` of a component's active records, or None."""
        alarms = self.active(component)
        if not alarms:
            return None
        last = alarms[-1].event
        state = 'cleared' if alarms[-1].cleared else 'active'
        text = (f'latched: {last.kind} anomaly since t={last.time:.3f} s ({state}, '
                f'unacknowledged)')
        if len(alarms) > 1:
            text += f' and {len(alarms) - 1} more'
        return text, {'latched_alarms': len(alarms), 'latched_kind': last.kind,
                      'latched_change_time_s': last.time,
                      'latched_detector': last.detector}
