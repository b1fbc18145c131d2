"""Journals (issue 24, item 3): ``events_file`` opens only a journal.

On main 09648a8 a foreign file named as ``events_file`` was wiped to 0 bytes at load and a
folder only counted an error; both are now refused with JournalError (a ConfigError: a
node exits 2 on it) and left untouched.
"""

import json
import os
import stat

import pytest

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.alarms import AlarmStore


def _event(component='rw1'):
    return AnomalyEvent(detector='llr', component=component, kind='dry', time=1.0, index=10,
                        declared_time=2.0, declared_index=20, p_value=1e-6)


@pytest.mark.parametrize('content', [b'my thesis\n', b'{"a": 1}\n', b'\x00\xff\xfe',
                                     b'[1, 2]\n{"record": "event"}\n'])
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


@pytest.mark.parametrize('content', [None, b'', b'\n\n', b'{"record": "ev'])
def test_a_new_empty_or_cut_short_journal_is_used(tmp_path, content):
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
