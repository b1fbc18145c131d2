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
counted), then rewrites the journal with its header line and only those (through
``atomic_write``), so the file does not grow without bound across restarts. A path that
is not a journal (a foreign file, a folder, a device) is refused with
:class:`~rwa_monitor.exceptions.JournalError` and left untouched (:func:`check_journal`):
a journal is recognised by a whole first line, its header or a whole record.
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
# A journal's first line: written when the journal is created or compacted.
HEADER_RECORD = 'journal'
JOURNAL_FORMAT = 'rwa_monitor alarm journal'
JOURNAL_VERSION = 1
# Longest first line read to recognise a journal (a record is well under 4 KiB).
MAX_FIRST_LINE = 1 << 16
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


def journal_header() -> str:
    """Return the first line of every journal this module creates (with its newline)."""
    return json.dumps({'record': HEADER_RECORD, 'format': JOURNAL_FORMAT,
                       'version': JOURNAL_VERSION}) + '\n'


def _head(path: pathlib.Path) -> tuple[bytes | None, bool]:
    """Return (first line without its newline or None if longer than the limit, blank).

    ``blank``: the whole file is white space (read only when it is that short).
    """
    with open(path, 'rb') as handle:
        head = handle.read(MAX_FIRST_LINE + 1)
    blank = len(head) <= MAX_FIRST_LINE and not head.strip()
    if b'\n' in head:
        return head.split(b'\n', 1)[0], blank
    return (head if len(head) <= MAX_FIRST_LINE else None), blank


def _is_first_record(line: bytes) -> bool:
    """Return True if ``line`` is a whole journal header or record (not a prefix of one)."""
    try:
        record = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        return False
    if not isinstance(record, dict):
        return False
    kind = record.get('record')
    if kind == HEADER_RECORD:
        version = record.get('version')
        return (record.get('format') == JOURNAL_FORMAT and isinstance(version, int)
                and 1 <= version <= JOURNAL_VERSION)
    if kind == 'event':
        return isinstance(record.get('key'), str) and isinstance(record.get('event'), dict)
    return kind == 'acknowledged' and isinstance(record.get('key'), str)


def check_journal(path: str | os.PathLike) -> None:
    """Raise JournalError unless ``path`` is missing, blank, or a journal this module wrote.

    A journal is recognised by its whole first line: the header :func:`journal_header`
    (written when the journal is created), or a whole event or acknowledgement record
    (journals written before the header existed). A first line that only begins like one
    (e.g. the ``{`` of a pretty-printed JSON file), a folder, a FIFO, a device or any
    other content is refused and the file left untouched.
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
        first, blank = _head(path)
    except OSError as err:
        raise JournalError(f'events_file {path}: cannot read: {err.strerror or err}') from None
    if blank:
        return
    if first is None or not _is_first_record(first):
        version = _newer_version(first)
        if version:
            raise JournalError(f'events_file {path}: a journal of format version {version}, '
                               f'newer than this version reads ({JOURNAL_VERSION}); '
                               'refusing to use or overwrite it')
        raise JournalError(f'events_file {path}: exists and is not an alarm journal (its '
                           'first line is not a whole journal record); refusing to use or '
                           'overwrite it (give a new file name)')


def _newer_version(line: bytes | None) -> int:
    """Return the version of a header newer than this module's, else 0."""
    try:
        record = json.loads(line or b'')
        version = record['version'] if record.get('record') == HEADER_RECORD else 0
    except (ValueError, UnicodeDecodeError, AttributeError, KeyError, TypeError):
        return 0
    return version if isinstance(version, int) and version > JOURNAL_VERSION else 0


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

        A missing (or blank) file is an empty journal: it is created with its header.
        Lines that are not a journal record (a write cut short by a crash) are skipped
        and counted.
        """
        if self.path is None:
            return []
        check_journal(self.path)
        text = ''
        if self.path.exists():
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
                if record.get('record') == HEADER_RECORD:
                    continue
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
            write_text_atomic(self.path, journal_header() + ''.join(lines))
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
