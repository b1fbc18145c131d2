"""Every shell command shown in README.md and docs/*.md runs as written (clone and pip).

The commands are the lines starting with a program (PROGRAMS) in the fenced blocks (no
language, or sh/bash/console) of the documents. Each one is either run here (once), in
the order of its document, or listed in EXCEPTIONS with the reason. They run twice: in a
scratch folder beside a link to the repository's ``config/`` with this environment's
programs (a clone), and in a bare scratch folder with the programs of a clean
``pip install CLONE[foxglove,fleet]`` (test/pip_venv.py: no ``config/`` folder there, so
``--params-file config/rwa_monitor.yaml`` must find the installed copy). The scratch
folder also holds the one input a command expects from the user: a classifier model
(``model.json``); the recording from another system (``flight_bag``) is made by a
documented command.
A new documented command fails :func:`test_every_documented_command_is_covered` until it
is added to one of them. Long-running commands (nodes, the dashboard) run together until
the replay's data reaches the dashboard, then are stopped with SIGINT, as a user would.
"""

import os
import pathlib
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest
from ros_harness import DomainLease

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
BIN = pathlib.Path(sys.executable).parent
SHELL_BLOCKS = ('', 'sh', 'bash', 'shell', 'console')
# A line of a shell block is a command when it starts with one of these (other lines of
# such blocks are diagrams or output).
PROGRAMS = ('make', 'rwa-monitor', 'python', 'python3', 'ros2', 'colcon', 'npm', 'node',
            'pip')

EXCEPTIONS = {
    'make demo': 'the whole demo (minutes of replay); test_nodes_demo.py runs it on a '
                 'short file',
    'make test': 'the whole test suite, this test included',
    'rwa-monitor identify FILE [--wheel ID|all] [--inertia J] [--torque-constant K_T] -o DIR '
    '[--format telemetry|coastdown] [--run NAME|list] [--half-width H] [--alpha A] '
    '[--no-jumps]': 'a synopsis with placeholders, not a command',
    'rwa-monitor fss train data/generated/fss -o model.json':
        'trains the classifier for minutes; `fss evaluate` below runs on a copy of the '
        'shipped model instead',
    'rwa-monitor fss train data/generated/fss -o rwa_monitor/data/fss_model.json':
        'retrains the shipped model (minutes), a maintainer step',
}
# Run together as processes for a few seconds, then stopped with SIGINT.
LONG_RUNNING = {
    'rwa-monitor-replay --ros-args -p file:=run.csv -p rate:=40.0',
    'rwa-monitor-llr --ros-args --params-file config/rwa_monitor.yaml',
    'rwa-monitor-fss --ros-args --params-file config/rwa_monitor.yaml',
    'rwa-monitor dashboard',
    'rwa-monitor-record --ros-args -p output:=review',
    'rwa-monitor-foxglove --ros-args -p port:=8765',
}


def documented_commands():
    """Return [(document name, command)] in document order (comments and prompts removed)."""
    found = []
    for doc in DOCS:
        text = doc.read_text()
        for match in re.finditer(r'^```([^\n]*)\n(.*?)^```', text, re.S | re.M):
            if match.group(1).strip() not in SHELL_BLOCKS:
                continue
            lines = []
            for raw in match.group(2).replace('\\\n', ' ').splitlines():
                line = re.sub(r'\s+#.*$', '', raw).strip()
                line = line[2:] if line.startswith('$ ') else line
                if not line:
                    continue
                if line.startswith('[') and lines:  # a synopsis continued
                    lines[-1] += ' ' + line
                else:
                    lines.append(line)
            found += [(doc.name, ' '.join(line.split())) for line in lines
                      if _is_program(line.split()[0])]
    return found


def _is_program(word):
    return any(word == p or word.startswith(p + '-') for p in PROGRAMS)


def test_every_documented_command_is_covered():
    commands = [c for _, c in documented_commands()]
    assert 'rwa-monitor-replay --ros-args -p file:=run.csv -p rate:=40.0' in commands
    stale = (set(EXCEPTIONS) | LONG_RUNNING) - set(commands)
    assert not stale, f'listed here but no longer documented: {stale}'
    for command in commands:
        first = shlex.split(command)[0]
        assert command in EXCEPTIONS or command in LONG_RUNNING or (BIN / first).is_file(), \
            f'{command!r}: {first} is not installed next to {sys.executable}'


@pytest.fixture(scope='module')
def scratch(tmp_path_factory):
    """Return a scratch folder with config/ linked, as in a clone."""
    folder = tmp_path_factory.mktemp('docs')
    (folder / 'config').symlink_to(ROOT / 'config')
    shutil.copy(ROOT / 'rwa_monitor' / 'data' / 'fss_model.json', folder / 'model.json')
    return folder


def _env():
    return {**os.environ, 'PATH': f'{BIN}{os.pathsep}{os.environ.get("PATH", "")}',
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'PYTHONWARNINGS': 'ignore'}


@pytest.fixture(scope='module')
def pip_scratch(tmp_path_factory):
    """Return (a bare scratch folder, the env of a clean pip install with the extras)."""
    import pip_venv
    bin_dir, env = pip_venv.clean_install(tmp_path_factory, 'foxglove,fleet')
    folder = tmp_path_factory.mktemp('docs_pip')
    shutil.copy(ROOT / 'rwa_monitor' / 'data' / 'fss_model.json', folder / 'model.json')
    return folder, {**env, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
                    'PYTHONWARNINGS': 'ignore'}


# `detect` reports its finding in the exit code (its --help): 1 anomaly found, 3 not
# everything examined; 2 is its error.
RESULT_CODES = {'rwa-monitor detect': (0, 1, 3), 'rwa-monitor fleet': (0, 1, 3)}


def _run(command, cwd, env, timeout=600):
    result = subprocess.run(shlex.split(command), cwd=cwd, env=env, capture_output=True,
                            text=True, timeout=timeout)
    codes = next((c for p, c in RESULT_CODES.items() if command.startswith(p + ' ')), (0,))
    assert result.returncode in codes, \
        f'{command!r} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}'
    return result


def _run_every_command(folder, env):
    ran = []
    for _, command in documented_commands():
        if command in EXCEPTIONS or command in LONG_RUNNING or command in ran:
            continue
        _run(command, folder, env)
        ran.append(command)
    assert len(ran) == 19, ran
    assert (folder / 'run_bag' / 'metadata.yaml').is_file()
    assert (folder / 'id' / 'report.json').is_file()
    assert (folder / 'events_bag.json').is_file()
    assert (folder / 'flight_bag' / 'metadata.yaml').is_file()
    assert (folder / 'pass.xml').is_file() and (folder / 'events_pass.json').is_file()


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_documented_commands_run_as_written(scratch):
    _run_every_command(scratch, _env())


@pytest.mark.slow
@pytest.mark.timeout(3000)
def test_documented_commands_run_as_written_after_pip_install(pip_scratch):
    folder, env = pip_scratch
    assert not (folder / 'config').exists()
    _run_every_command(folder, env)


@pytest.mark.slow
@pytest.mark.ros
@pytest.mark.timeout(3000)
def test_documented_params_file_finds_the_installed_copy_after_pip_install(pip_scratch):
    """Issue 36: ``--params-file config/rwa_monitor.yaml`` failed for a pip user."""
    folder, env = pip_scratch
    lease = DomainLease()
    env = {**env, 'ROS_DOMAIN_ID': str(lease.domain_id)}
    procs = {c: _Process(c, folder, env) for c in sorted(LONG_RUNNING)
             if '--params-file config/rwa_monitor.yaml' in c}
    try:
        assert len(procs) == 2, procs
        _wait(lambda: all('installed copy' in p.output and 'share/rwa_monitor/config' in
                          p.output for p in procs.values()), list(procs.values()), 240,
              'the note naming the installed parameters file')
        time.sleep(3.0)         # the nodes run on it
    finally:
        codes = {c: p.stop() for c, p in procs.items()}
        lease.release()
    for command, code in codes.items():
        assert code == 0, f'{command!r} ended with {code}:\n{procs[command].output[-3000:]}'


class _Process:
    """A documented command running in the background, its output collected by a thread."""

    def __init__(self, command, cwd, env):
        self.command = command
        self.proc = subprocess.Popen(shlex.split(command), cwd=cwd, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.lines = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line)

    @property
    def output(self):
        return ''.join(self.lines)

    def stop(self):
        """SIGINT (Ctrl-C), as a user stops a node; return the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        self._reader.join(timeout=10)
        return self.proc.returncode


def _wait(condition, procs, timeout, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return
        ended = [p for p in procs if p.proc.poll() is not None]
        assert not ended, '\n'.join(
            f'{p.command!r} ended with {p.proc.returncode}:\n{p.output[-3000:]}'
            for p in ended)
        time.sleep(0.5)
    raise AssertionError(f'no {what} within {timeout} s:\n' + '\n'.join(
        f'--- {p.command}\n{p.output[-1500:]}' for p in procs))


@pytest.mark.slow
@pytest.mark.ros
@pytest.mark.timeout(900)
def test_documented_nodes_run_together_as_written(scratch):
    """The two-process replay of docs/usage.md with the other nodes and the dashboard.

    With ``--params-file config/rwa_monitor.yaml`` the replay's block would beat ``-p``
    (``rate`` stayed 1.0): docs/usage.md gives the replay its settings on the command line.
    """
    if not (scratch / 'run.csv').is_file():
        _run('rwa-monitor simulate friction --wheels 4 --hours 3 --anomaly rw2:dry:3600:+2e-4 '
             '-o run.csv', scratch, _env())
    lease = DomainLease()
    env = {**_env(), 'ROS_DOMAIN_ID': str(lease.domain_id)}
    replay_command = next(c for c in LONG_RUNNING if c.startswith('rwa-monitor-replay'))
    procs = {}
    try:
        for command in sorted(LONG_RUNNING - {replay_command}):
            procs[command] = _Process(command, scratch, env)
        running = list(procs.values())
        board = procs['rwa-monitor dashboard']
        loggers = [p for c, p in procs.items()
                   if c.startswith(('rwa-monitor-record', 'rwa-monitor-foxglove'))]
        _wait(lambda: all(p.lines for p in loggers) and 'llr_detector' in board.output
              and 'fss_diagnoser' in board.output, running, 240, 'start-up of every node')
        procs[replay_command] = replay = _Process(replay_command, scratch, env)
        running = list(procs.values())
        _wait(lambda: 'replaying run.csv' in replay.output and 'rw2' in board.output,
              running, 240, 'replay reaching the dashboard')
        time.sleep(3.0)  # a few /diagnostics periods for the recorder
    finally:
        codes = {c: p.stop() for c, p in procs.items()}
        lease.release()
    for command, code in codes.items():
        assert code == 0, f'{command!r} ended with {code}:\n{procs[command].output[-3000:]}'
    assert 'required' not in replay.output
    assert 'rate 40.0' in replay.output  # the command line's rate is the one used
    bridge = procs['rwa-monitor-foxglove --ros-args -p port:=8765']
    assert 'Foxglove WebSocket server on ws://127.0.0.1:8765' in bridge.output
    assert (scratch / 'review' / 'metadata.yaml').is_file()
    from rosbags.rosbag2 import Reader

    from rwa_monitor.telemetry.rosbag_io import typestore
    with Reader(scratch / 'review') as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
        for conn, _, data in reader.messages():
            typestore().deserialize_cdr(data, conn.msgtype)
    assert topics.get('/diagnostics', 0) > 0
