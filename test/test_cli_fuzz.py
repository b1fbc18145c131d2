"""Every command, given unreadable or damaged input, exits with a code and one line.

Issue 24, item 7. Commands run in-process through ``main(argv)`` (the path that maps the
package's own errors to exit 2): an exception escaping ``main`` fails the test, an
input its reader refuses must exit 2, any input exits 0-3, and nothing is ever written
outside the ``-o`` path. A few cases also run as a process: no traceback on stderr.
"""

import contextlib
import io
import os
import pathlib
import subprocess
import sys
import tempfile

from fuzz_inputs import CLI_SETTINGS, garbage, mutated, seeds, small_telemetry
from hypothesis import given, strategies as st
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.exceptions import RwaMonitorError
from rwa_monitor.telemetry import read_telemetry, write_telemetry

REPO = pathlib.Path(__file__).resolve().parents[1]
SEEDS = seeds(pathlib.Path(tempfile.mkdtemp(prefix='rwa-fuzz-cli-')))
GOOD = pathlib.Path(tempfile.mkdtemp(prefix='rwa-fuzz-good-')) / 'good.csv'
write_telemetry(GOOD, small_telemetry())


def _reads(loader):
    """Return ``path -> True if loader(path) does not refuse it``."""
    def ok(path: pathlib.Path) -> bool:
        try:
            loader(path)
        except RwaMonitorError:
            return False
        return True
    return ok


def _parameters(path):
    from rwa_monitor.telemetry.parameters_file import read_parameters_file
    read_parameters_file(path)


def _calibration(path):
    from rwa_monitor.telemetry.calibration_file import load
    load(path)


def _model(path):
    from rwa_monitor.pipelines.llr import friction_model
    friction_model(str(path), small_telemetry(20))


def _fss_model(path):
    from rwa_monitor.telemetry.fss_model import load_model
    load_model(path)


# name -> (seed kind, input file name, argv(input, out), does the input read?)
COMMANDS = {
    'detect': ('csv', 'in.csv', lambda f, o: ['detect', f, '-o', o / 'events.json'],
               _reads(read_telemetry)),
    'detect-mcap': ('mcap', 'in.mcap', lambda f, o: ['detect', f], _reads(read_telemetry)),
    'diagnose': ('csv', 'in.csv', lambda f, o: ['diagnose', f, '-o', o / 'd.json'],
                 _reads(read_telemetry)),
    # Wheels only: a record too short for the gyro calibration is item 5's (see below).
    'calibrate': ('wheels_csv', 'in.csv', lambda f, o: ['calibrate', f, '-o', o / 'cal'],
                  _reads(read_telemetry)),
    'identify': ('csv', 'in.csv', lambda f, o: ['identify', f, '-o', o / 'id'],
                 _reads(read_telemetry)),
    'detect-config': ('parameters', 'p.yaml', lambda f, o: ['detect', GOOD, '--config', f],
                      _reads(_parameters)),
    'detect-calibration': ('calibration', 'c.yaml',
                           lambda f, o: ['detect', GOOD, '--calibration', f],
                           _reads(_calibration)),
    'detect-friction-model': ('friction_model', 'm.yaml',
                              lambda f, o: ['detect', GOOD, '--friction-model', f],
                              _reads(_model)),
    'diagnose-model': ('fss_model', 'model.json',
                       lambda f, o: ['diagnose', GOOD, '-o', o / 'd.json', '--model', f],
                       _reads(_fss_model)),
}


def _tree(folder: pathlib.Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob('*')}


def run_case(command: str, data: bytes) -> None:
    kind, name, argv, readable = COMMANDS[command]
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        deep = root / 'a' / 'b'
        deep.mkdir(parents=True)
        path = deep / name
        path.write_bytes(data)
        out = deep / 'out'
        before = _tree(root)
        with contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()) as err:
            code = main([str(a) for a in argv(path, out)])
        assert code in (0, 1, 2, 3), err.getvalue()
        if not readable(path):
            assert code == 2, err.getvalue()
        new = {p for p in _tree(root) - before if not p.startswith('a/b/out')}
        assert not new, f'{command} wrote outside -o: {sorted(new)}'


@pytest.mark.parametrize('command', sorted(COMMANDS))
def test_command_with_damaged_or_random_input(command):
    kind = COMMANDS[command][0]

    @CLI_SETTINGS
    @given(st.one_of(garbage, mutated(SEEDS[kind])))
    def check(data):
        run_case(command, data)
    check()


@pytest.mark.parametrize('command', ['detect', 'diagnose', 'calibrate', 'identify',
                                     'detect-config', 'detect-calibration'])
def test_command_in_a_process_gives_one_line_and_exit_2(tmp_path, command):
    kind, name, argv, _ = COMMANDS[command]
    path = tmp_path / name
    path.write_bytes(b'\x00\xffnot a ' + kind.encode() + b' file\n' + b'\xfe' * 100)
    env = {**os.environ, 'PYTHONPATH': str(REPO)}
    done = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main',
                           *map(str, argv(path, tmp_path / 'out'))],
                          capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 2, done.stderr
    assert 'Traceback' not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / 'out').exists()


def test_calibrate_with_a_gyro_too_short_to_calibrate():
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / 'in.csv'
        path.write_bytes(SEEDS['csv'])
        with contextlib.redirect_stderr(io.StringIO()):
            code = main(['calibrate', str(path), '-o', str(pathlib.Path(tmp) / 'cal')])
        assert code in (2, 3)
