"""Journals (issue 24, item 3; issue 36): ``events_file`` opens only a journal.

On main 09648a8 a foreign file named as ``events_file`` was wiped to 0 bytes at load and a
folder only counted an error; both are now refused with JournalError (a ConfigError: a
node exits 2 on it) and left untouched. On main 91ca172 a pretty-printed JSON file (first
line ``{``, a prefix of a journal record) was still emptied: a journal is now recognised
by a whole first line, its header or a whole record.
"""

import json
import os
import stat

import pytest

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.alarms import AlarmStore, event_record, journal_header


def _event(component='rw1'):
    return AnomalyEvent(detector='llr', component=component, kind='dry', time=1.0, index=10,
                        declared_time=2.0, declared_index=20, p_value=1e-6)


PRETTY = json.dumps({'events': [{'detector': 'llr', 'component': 'rw1'}], 'summary': {}},
                    indent=2).encode()


@pytest.mark.parametrize('content', [
    b'my thesis\n', b'{"a": 1}\n', b'\x00\xff\xfe', b'[1, 2]\n{"record": "event"}\n',
    PRETTY, b'  \n' + PRETTY, b'{\n', b'{"record": "ev', b'{"record": "event"}\n',
    b'{"record": "journal", "format": "my format", "version": 1}\n', b'{' + b' ' * 70000])
def test_a_foreign_file_is_refused_and_left_byte_identical(tmp_path, content):
    path = tmp_path / 'notes.txt'
    path.write_bytes(content)
    with pytest.raises(ConfigError, match='not an alarm journal') as err:
        AlarmStore(path).load()
    assert type(err.value).__name__ == 'JournalError'
    assert path.read_bytes() == content


def test_a_folder_or_a_fifo_is_refused(tmp_path):
    with pytest.raises(ConfigError, match='is a folder'):
        AlarmStore(tmp_path).load()
    fifo = tmp_path / 'fifo'
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match='not a regular file'):
        AlarmStore(fifo).load()
    assert stat.S_ISFIFO(fifo.lstat().st_mode)


def test_a_pretty_printed_events_file_given_to_a_node_is_refused_not_emptied(tmp_path):
    """The audit's case: detect's own output named as a node's events_file."""
    path = tmp_path / 'events.json'
    path.write_bytes(PRETTY)
    with pytest.raises(ConfigError, match='not a whole journal record'):
        AlarmStore(path).load()
    assert path.read_bytes() == PRETTY


def test_a_journal_of_a_newer_format_is_refused(tmp_path):
    path = tmp_path / 'events.jsonl'
    content = (json.dumps({'record': 'journal', 'format': 'rwa_monitor alarm journal',
                           'version': 99}) + '\n').encode()
    path.write_bytes(content)
    with pytest.raises(ConfigError, match='format version 99'):
        AlarmStore(path).load()
    assert path.read_bytes() == content


def test_a_new_journal_starts_with_its_header_and_is_recognised_again(tmp_path):
    path = tmp_path / 'events.jsonl'
    store = AlarmStore(path)
    store.load()
    assert path.read_text() == journal_header()
    store.declare([_event()])
    again = AlarmStore(path)
    assert [a.key for a in again.load()] == ['llr/rw1/10']
    assert again.counters['journal_bad_lines'] == 0
    assert path.read_text().startswith(journal_header())


def test_a_journal_without_header_whose_first_record_is_whole_is_used(tmp_path):
    """Journals written before the header existed start with a whole record."""
    path = tmp_path / 'events.jsonl'
    record = {'record': 'event', 'key': 'llr/rw1/10', 'wall_time_s': 1.0,
              'event': event_record(_event())}
    path.write_text(json.dumps(record) + '\n' + '{"record": "ackn')
    store = AlarmStore(path)
    assert [a.key for a in store.load()] == ['llr/rw1/10']
    assert store.counters['journal_bad_lines'] == 1


@pytest.mark.parametrize('content', [None, b'', b'\n\n'])
def test_a_new_or_empty_journal_is_used(tmp_path, content):
    path = tmp_path / 'events.jsonl'
    if content is not None:
        path.write_bytes(content)
    store = AlarmStore(path)
    assert store.load() == []
    store.declare([_event()])
    records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()
               and line.startswith('{"record": "event", "key"')]
    assert [r['key'] for r in records] == ['llr/rw1/10']


def test_a_journal_reloads_through_a_link_and_keeps_the_link(tmp_path):
    real = tmp_path / 'journal.jsonl'
    link = tmp_path / 'events.jsonl'
    link.symlink_to(real)
    store = AlarmStore(link)
    store.load()
    store.declare([_event('rw1'), _event('rw2')])
    store.acknowledge('rw1')
    again = AlarmStore(link)
    assert [a.event.component for a in again.load()] == ['rw2']
    assert link.is_symlink() and real.is_file()
    assert again.counters['journal_errors'] == 0
