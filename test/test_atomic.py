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


INTERRUPTED = '''
import signal, sys, tempfile
import numpy as np
# A child inherits an ignored SIGINT (a test worker, or a test before it, may ignore it):
# Python's own handler, as a user's command has it.
signal.signal(signal.SIGINT, signal.default_int_handler)
real = getattr(tempfile, sys.argv[1])


def made_then_interrupted(*args, **kwargs):
    out = real(*args, **kwargs)
    signal.raise_signal(signal.SIGINT)
    return out


setattr(tempfile, sys.argv[1], made_then_interrupted)
from rwa_monitor.telemetry import rosbag_io
from rwa_monitor.telemetry.atomic import write_text_atomic
from rwa_monitor.telemetry.schema import Telemetry, Wheel
try:
    if sys.argv[1] == 'mkstemp':
        write_text_atomic(sys.argv[2], 'new')
    else:
        tele = Telemetry(time=np.arange(5.0), wheels={'rw1': Wheel(np.ones(5), np.zeros(5))})
        rosbag_io.write(sys.argv[2], tele)
except KeyboardInterrupt:
    sys.exit(130)
'''


def _interrupted(function: str, target) -> int:
    """Run a write in a fresh process whose tempfile.<function> gets SIGINT inside it.

    A fresh process: the signal must reach the main thread with Python's own handler
    (test workers may run tests elsewhere or ignore SIGINT, and a child inherits an
    ignored signal, so the script sets the handler again). Held while the temporary is
    made, the signal is raised as the hold ends, after the temporary exists.
    """
    import subprocess
    import sys
    run = subprocess.run([sys.executable, '-c', INTERRUPTED, function, str(target)],
                         capture_output=True, text=True, timeout=120)
    return run.returncode


def test_an_interrupt_while_the_temporary_file_is_made_leaves_none(tmp_path):
    # Before, the name was dropped with the exception and the file stayed.
    target = tmp_path / 'out.csv'
    target.write_text('old')
    assert _interrupted('mkstemp', target) == 130
    assert [p.name for p in tmp_path.iterdir()] == ['out.csv']
    assert target.read_text() == 'old'


def test_an_interrupt_while_the_work_folder_is_made_leaves_none(tmp_path):
    # The bare .mcap path: a recording folder is built in a work folder, then its file
    # installed. The work folder used to come from tempfile.TemporaryDirectory, which
    # loses it to an interrupt between its mkdir and its own cleanup's registration.
    assert _interrupted('mkdtemp', tmp_path / 'out.mcap') == 130
    assert list(tmp_path.iterdir()) == []
