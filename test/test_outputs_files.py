"""Outputs (issue 24, item 1): links followed, FIFOs and devices streamed, umask modes.

On main 09648a8 every test here fails: a link or a FIFO at the output path was replaced
by a regular file, and new files were created with mode 0600.
"""

import os
import pathlib
import socket
import stat

import numpy as np
import pytest

from rwa_monitor.exceptions import OutputError
from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry
from rwa_monitor.telemetry.atomic import write_bytes_atomic, write_text_atomic


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_a_link_is_followed_its_target_replaced_and_the_link_kept(tmp_path):
    real = tmp_path / 'data' / 'report.json'
    real.parent.mkdir()
    real.write_text('old')
    link = tmp_path / 'latest.json'
    link.symlink_to(real)
    write_text_atomic(link, 'new')
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_text() == 'new'
    assert sorted(p.name for p in real.parent.iterdir()) == ['report.json']


def test_a_dangling_link_creates_its_target(tmp_path):
    link = tmp_path / 'out.csv'
    link.symlink_to(tmp_path / 'real.csv')
    write_text_atomic(link, 'x')
    assert link.is_symlink() and (tmp_path / 'real.csv').read_text() == 'x'


def test_a_fifo_is_streamed_into_not_replaced(tmp_path):
    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)   # a reader is there: open never blocks
    try:
        write_bytes_atomic(fifo, b'streamed')
        got = os.read(fd, 100)
    finally:
        os.close(fd)
    assert got == b'streamed'
    assert stat.S_ISFIFO(fifo.lstat().st_mode)


def test_a_link_to_dev_null_discards_and_leaves_the_device(tmp_path):
    """``-o /dev/null`` as users expect (through a link, so a regression cannot harm)."""
    null = tmp_path / 'null'
    null.symlink_to(os.devnull)
    tele = Telemetry(time=np.array([0.0, 1.0]),
                     wheels={'rw1': Wheel(np.array([1.0, 2.0]), np.zeros(2))})
    write_telemetry(null, tele)   # no suffix: a recording folder, were it not a device
    write_text_atomic(null, 'x' * 10000)
    assert null.is_symlink()
    assert stat.S_ISCHR(pathlib.Path(os.devnull).stat().st_mode)


def test_a_socket_or_folder_is_refused_untouched(tmp_path):
    sock_path = tmp_path / 's'
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(sock_path))
        with pytest.raises(OutputError, match='not a file, a FIFO or a device'):
            write_text_atomic(sock_path, 'x')
        assert stat.S_ISSOCK(sock_path.lstat().st_mode)
    with pytest.raises(OutputError, match='is a folder'):
        write_text_atomic(tmp_path, 'x')


def test_new_files_follow_the_umask_and_replaced_files_keep_their_mode(tmp_path, umask_022):
    new = tmp_path / 'new.txt'
    write_text_atomic(new, 'x')
    assert stat.S_IMODE(new.stat().st_mode) == 0o644
    kept = tmp_path / 'kept.txt'
    kept.write_text('old')
    kept.chmod(0o640)
    write_text_atomic(kept, 'new')
    assert stat.S_IMODE(kept.stat().st_mode) == 0o640
    from rwa_monitor.telemetry.atomic import append_bytes
    journal = tmp_path / 'events.jsonl'
    append_bytes(journal, b'{"record": "x"}\n')
    assert stat.S_IMODE(journal.stat().st_mode) == 0o644
    os.umask(0o077)
    private = tmp_path / 'private.txt'
    write_text_atomic(private, 'x')
    assert stat.S_IMODE(private.stat().st_mode) == 0o600


def test_a_csv_written_through_a_link_keeps_the_link(tmp_path):
    real = tmp_path / 'real.csv'
    link = tmp_path / 'run.csv'
    real.write_text('old')
    link.symlink_to(real)
    write_telemetry(link, Telemetry(
        time=np.array([0.0, 1.0]), wheels={'rw1': Wheel(np.array([1.0, 2.0]))}))
    assert link.is_symlink()
    assert real.read_text().startswith('time,rw1_speed')
