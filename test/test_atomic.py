"""Atomic output: a failed write leaves the previous file whole, and no temporary file."""

import pytest

from rwa_monitor.exceptions import OutputError
from rwa_monitor.telemetry.atomic import atomic_write, write_text_atomic


def test_success_replaces_the_file(tmp_path):
    target = tmp_path / 'out.json'
    target.write_text('old')
    write_text_atomic(target, 'new')
    assert target.read_text() == 'new'
    assert [p.name for p in tmp_path.iterdir()] == ['out.json']


def test_failure_keeps_the_previous_file(tmp_path):
    target = tmp_path / 'out.json'
    target.write_text('old')
    with pytest.raises(RuntimeError):
        with atomic_write(target) as handle:
            handle.write('half')
            raise RuntimeError('interrupted')
    assert target.read_text() == 'old'
    assert [p.name for p in tmp_path.iterdir()] == ['out.json']


def test_missing_folder_is_created_or_named(tmp_path):
    write_text_atomic(tmp_path / 'a' / 'b' / 'x.txt', 'x')
    assert (tmp_path / 'a' / 'b' / 'x.txt').read_text() == 'x'
    with pytest.raises(OutputError, match='does not exist'):
        with atomic_write(tmp_path / 'c' / 'y.txt', make_parents=False):
            pass


def test_a_folder_is_not_overwritten(tmp_path):
    with pytest.raises(OutputError, match='is a folder'):
        write_text_atomic(tmp_path, 'x')
