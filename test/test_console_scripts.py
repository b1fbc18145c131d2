"""Every console script answers --help without starting a node; nodes stop cleanly."""

import os
import shutil
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from ros_harness import Collector, RosWorld

from rwa_monitor.cli import cmd_dashboard
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import EVENTS_QOS
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
from rwa_monitor.telemetry import write_telemetry

NODES = ('rwa-monitor-llr', 'rwa-monitor-vsadc', 'rwa-monitor-fss', 'rwa-monitor-replay',
         'rwa-monitor-bus', 'rwa-monitor-record', 'rwa-monitor-foxglove',
         'rwa-monitor-monitor')
# The same nodes under their node names, as `ros2 run rwa_monitor NAME` runs them.
NODE_NAMES = ('llr_detector', 'vsadc_detector', 'fss_diagnoser', 'telemetry_replay',
              'basilisk_bus', 'recorder', 'foxglove_bridge', 'monitor')


def _script(name):
    path = shutil.which(name, path=os.path.dirname(sys.executable))
    if path is None:
        pytest.fail(f'console script {name} is not installed next to {sys.executable}')
    return path


@pytest.mark.parametrize('name', NODES + NODE_NAMES + ('rwa-monitor',))
def test_help_lists_parameters_and_exits_0(name):
    result = subprocess.run([_script(name), '--help'], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('usage:')
    if name != 'rwa-monitor':
        assert 'parameters' in result.stdout and 'Traceback' not in result.stderr


def test_every_console_script_is_checked():
    from importlib.metadata import entry_points
    scripts = {e.name for e in entry_points(group='console_scripts')
               if e.value.startswith('rwa_monitor.')}
    assert scripts == set(NODES) | set(NODE_NAMES) | {'rwa-monitor'}


@pytest.mark.parametrize('command', ['calibrate', 'dashboard', 'demo', 'detect', 'diagnose',
                                     'fss', 'identify', 'params'])
def test_every_subcommand_help_exits_0(command, capsys):
    from rwa_monitor.cli.main import main
    with pytest.raises(SystemExit) as stop:
        main([command, '--help'])
    assert stop.value.code == 0
    assert capsys.readouterr().out.startswith('usage: rwa-monitor ' + command)


def _imported_after_help(argv):
    """Return (cmd_ modules imported, numpy imported) after ``main(argv)`` in a new process."""
    code = ('import sys\n'
            'from rwa_monitor.cli.main import main\n'
            'try:\n'
            f'    main({list(argv)!r})\n'
            'except SystemExit as stop:\n'
            '    assert stop.code == 0, stop.code\n'
            'print(sorted(m for m in sys.modules if m.startswith("rwa_monitor.cli.cmd_")))\n'
            'print("numpy" in sys.modules)\n')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    modules, numpy = done.stdout.strip().splitlines()[-2:]
    return modules, numpy == 'True'


def test_a_command_starts_with_its_own_module_only():
    # `rwa-monitor COMMAND ...` registers cmd_COMMAND alone (its start, docs/results.md).
    assert _imported_after_help(['params', '--help'])[0] == "['rwa_monitor.cli.cmd_params']"


def test_the_list_of_commands_read_from_sources_is_the_imported_one():
    # rwa-monitor --help lists the commands without importing them (cli/main.py
    # listed_help): the same text as the parser with every module registered.
    from rwa_monitor.cli.main import build_parser, listed_help, submodules
    assert all(listed_help(name) is not None for name in submodules('cmd_'))
    assert (build_parser(listing=True).format_help()
            == build_parser().format_help())
    assert _imported_after_help(['--help']) == ('[]', False)
    assert _imported_after_help(['-h', 'detect']) == ('[]', False)


def test_top_level_help_and_an_unknown_command_name_every_command(capsys):
    from rwa_monitor.cli.main import main, submodules
    commands = [name.removeprefix('cmd_') for name in submodules('cmd_')]
    with pytest.raises(SystemExit) as stop:
        main(['--debug', '--help'])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert all(f'    {c} ' in out or f'    {c}\n' in out for c in commands), out
    with pytest.raises(SystemExit) as stop:
        main(['--debug', 'detec', 'x.csv'])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'detec'" in err and all(repr(c) in err for c in commands), err


@pytest.mark.ros
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_dashboard_stops_cleanly_on_signals(sig):
    with RosWorld() as world:
        proc = subprocess.Popen([_script('rwa-monitor'), 'dashboard', '--interval', '0.2'],
                                env=world.env(), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            assert proc.stdout.readline().startswith('rwa_monitor dashboard')  # running
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode == 0 and err == '', err
    from rwa_monitor.cli.readable import levels_legend
    last = out.rstrip()
    assert last.endswith(levels_legend())           # the last view was drawn whole
    assert last[:-len(levels_legend())].rstrip().endswith('anomalies: 0')


def _latched_shown(board):
    """Return True once the restarted node's /diagnostics show rw2's latched anomaly."""
    return any(hw == 'alarms' and item['level'] > 0 and 'rw2' in str(item['fields'])
               for (_, hw), item in board.health.items())


def _wait_for_text(proc_log, text, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in proc_log.read_text(errors='replace'):
            return True
        time.sleep(0.2)
    return False


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_nodes_and_replay_stop_cleanly_on_signals(tmp_path, sig):
    tele, _ = simulate_friction_with_truth(wheels=['rw1'], n_samples=20000, rate_hz=10.0,
                                           seed=5, anomalies=[Anomaly('rw1', 'dry', 50.0,
                                                                      delta_dry=3e-4)])
    path = tmp_path / 'long.csv'
    write_telemetry(path, tele)
    with RosWorld() as world:
        env = world.env()
        procs = {}
        for name, args in (('rwa-monitor-llr', ['-p', 'window:=100']),
                           ('rwa-monitor-vsadc', []), ('rwa-monitor-fss', []),
                           ('rwa-monitor-record', ['-p', f'output:={tmp_path / "rec"}']),
                           ('rwa-monitor-foxglove', ['-p', 'port:=0']),
                           ('rwa-monitor-replay', ['-p', f'file:={path}', '-p', 'rate:=50.0',
                                                   '-p', 'min_subscribers:=2'])):
            log = tmp_path / f'{name}.log'
            procs[name] = (subprocess.Popen([_script(name), '--ros-args', *args], env=env,
                                            stdout=log.open('w'), stderr=subprocess.STDOUT),
                           log)
        # Generous: start-up takes long on a loaded machine. Signals arrive mid-replay.
        assert _wait_for_text(procs['rwa-monitor-replay'][1], 'replaying', 180.0)
        # The wheel detectors log their first wheel once running: a signal before that
        # would land in the imports (the FSS node's are the slowest), not in the node.
        for name, text in (('rwa-monitor-llr', 'monitoring wheel'),
                           ('rwa-monitor-fss', 'monitoring wheel'),
                           ('rwa-monitor-record', 'recording'),
                           ('rwa-monitor-foxglove', 'WebSocket server')):
            assert _wait_for_text(procs[name][1], text, 120.0), name
        time.sleep(3.0)
        for proc, _ in procs.values():
            proc.send_signal(sig)
        for name, (proc, log) in procs.items():
            try:
                code = proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGUSR1)      # every thread's stack into its log
                time.sleep(2.0)
                proc.kill()
                tail = log.read_text(errors='replace')[-6000:]
                pytest.fail(f'{name} did not stop on {sig.name}; its log ends:\n{tail}')
            text = log.read_text(errors='replace')
            assert 'Traceback' not in text and 'RCLError' not in text, text
            assert 'context is invalid' not in text, text    # no logging after shutdown
            # A process still importing its modules (a loaded machine) has no handler
            # yet and ends by the signal's default action: no traceback, nothing to clean.
            assert code == 0 or (code == -sig and not text.strip()), (name, code, text)


@pytest.mark.ros
@pytest.mark.slow
def test_killed_detector_restarted_shows_the_anomaly_to_a_late_subscriber(tmp_path):
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=3000, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'seeded.csv'
    write_telemetry(path, tele)
    journal = tmp_path / 'events.jsonl'
    detector_cmd = [_script('rwa-monitor-llr'), '--ros-args', '-p', 'window:=200',
                    '-p', f'events_file:={journal}']
    with RosWorld() as world:
        env = world.env()
        log = (tmp_path / 'llr.log').open('w')
        detector = subprocess.Popen(detector_cmd, env=env, stdout=log,
                                    stderr=subprocess.STDOUT)
        replay = subprocess.Popen([_script('rwa-monitor-replay'), '--ros-args', '-p',
                                   f'file:={path}', '-p', 'rate:=0.0', '-p', 'burst:=20'],
                                  env=env, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 90.0
            while time.monotonic() < deadline and not (
                    journal.exists() and '"record": "event"' in journal.read_text()):
                time.sleep(0.2)
            assert '"record": "event"' in journal.read_text(), 'no declaration was journalled'
            detector.kill()                                   # kill -9
            detector.wait(timeout=10)
        finally:
            replay.kill()
            replay.wait(timeout=10)
        restarted = subprocess.Popen(detector_cmd, env=env, stdout=log,
                                     stderr=subprocess.STDOUT)
        try:
            time.sleep(3.0)                                   # the subscriber joins later
            late = world.node(Node, 'late_subscriber')
            anomalies = Collector(late, DiagnosticArray, 'anomalies', EVENTS_QOS)
            board = cmd_dashboard.Board()                     # and the dashboard itself
            world.add(cmd_dashboard.make_node(board, context=world.context))
            world.wait_until(lambda: anomalies.messages and board.n_events
                             and _latched_shown(board), 60.0, 'the re-published anomaly')
            events = [messages.status_event(s) for m in anomalies.messages for s in m.status]
            assert {e.component for e in events} == {'rw2'}
            view = cmd_dashboard.render(board)
            assert 'anomalies: 1' in view and '  rw2 ' in view, view
        finally:
            restarted.send_signal(signal.SIGTERM)
            restarted.wait(timeout=20)


@pytest.mark.parametrize('command', ['params', 'params --yaml', 'params --markdown'])
def test_output_piped_into_head_ends_quietly(command):
    result = subprocess.run(f'{_script("rwa-monitor")} {command} | head -c 10', shell=True,
                            capture_output=True, text=True, timeout=120)
    assert result.stderr == '' and len(result.stdout) == 10


@pytest.mark.ros
@pytest.mark.slow
def test_a_node_writes_its_threads_stacks_on_sigusr1_and_goes_on(tmp_path):
    """A node asked with kill -USR1 writes where it is (docs/nodes.md) and goes on."""
    tele, _ = simulate_friction_with_truth(wheels=['rw1'], n_samples=2000, rate_hz=10.0,
                                           seed=5)
    path = tmp_path / 'short.csv'
    write_telemetry(path, tele)
    log = tmp_path / 'replay.log'
    with RosWorld() as world:
        proc = subprocess.Popen([_script('rwa-monitor-replay'), '--ros-args', '-p',
                                 f'file:={path}', '-p', 'rate:=1.0'], env=world.env(),
                                stdout=log.open('w'), stderr=subprocess.STDOUT)
        try:
            assert _wait_for_text(log, 'replaying', 180.0)
            proc.send_signal(signal.SIGUSR1)
            assert _wait_for_text(log, 'most recent call first', 30.0)
            assert proc.poll() is None                 # the dump does not stop the node
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=60) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
    text = log.read_text(errors='replace')
    assert 'in spin' in text and 'Traceback' not in text, text
