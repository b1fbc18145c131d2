"""Node start-up (issue 24, items 3, 4 and 6): bad files exit 2, journals, -p, subscribers."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, DomainLease, RosWorld
from sensor_msgs.msg import JointState

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.nodes import llr_detector, messages
from rwa_monitor.nodes.common import beaten_overrides, ERROR, OK, telemetry_qos
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.telemetry import alarms, Telemetry, Wheel, write_telemetry

pytestmark = pytest.mark.ros

BOMB = ''.join(f'{b}: &{b} [{", ".join([f"*{a}"] * 9)}]\n'
               for a, b in zip('abcde', 'bcdef'))


@pytest.fixture
def run_main(monkeypatch, capsys):
    """Run a console script's ``main`` in-process on a private domain; (code, stderr)."""
    def run(main, *args):
        lease = DomainLease()
        monkeypatch.setenv('ROS_DOMAIN_ID', str(lease.domain_id))
        handler = signal.getsignal(signal.SIGINT)
        try:
            code = main(['rwa-monitor-llr', '--ros-args', *args])
        finally:
            signal.signal(signal.SIGINT, handler)
            lease.release()
        return code, capsys.readouterr().err
    return run


@pytest.mark.parametrize('text, fragment', [
    ('a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]\n' + BOMB
     + 'llr_detector:\n  ros__parameters:\n    window: *f\n', 'params file'),
    ('llr_detector:\n  ros__parameters:\n    window: [1\n', 'params file'),
    ('llr_detector:\n  ros__parameters:\n    window: -5\n', 'window'),
    ('llr_detector:\n  ros__parameters:\n    false_alarm_rate: many\n', 'false_alarm_rate'),
])
def test_a_bad_parameters_file_exits_2_with_one_line(tmp_path, run_main, text, fragment):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    code, err = run_main(llr_detector.main, '--params-file', str(path))
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('error: ') and fragment in lines[0], err
    assert 'Traceback' not in err


def test_a_process_given_a_file_rcl_refuses_prints_one_line(tmp_path):
    """The node speaks for rcl (whose own [ERROR] line goes where capsys cannot see it)."""
    path = tmp_path / 'bad.yaml'
    path.write_text('llr_detector:\n  ros__parameters:\n    window: [1\n')
    lease = DomainLease()
    try:
        done = subprocess.run(
            [sys.executable, '-m', 'rwa_monitor.nodes.llr_detector', '--ros-args',
             '--params-file', str(path)], capture_output=True, text=True, timeout=120,
            env={**os.environ, 'ROS_DOMAIN_ID': str(lease.domain_id)})
    finally:
        lease.release()
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('error: '), done.stderr


def test_a_package_error_of_the_journal_opener_refuses_the_node(
        tmp_path, monkeypatch, run_main):
    journal = tmp_path / 'notes.txt'
    journal.write_text('my notes, not a journal\n')

    def refuse(self):
        raise RwaMonitorError(f'{self.path}: not an events journal')
    monkeypatch.setattr(alarms.AlarmStore, 'load', refuse)
    with RosWorld() as world:
        with pytest.raises(ConfigError, match='events_file.*not an events journal'):
            world.node(LLRDetectorNode, parameter_overrides=[
                Parameter('events_file', value=str(journal))])
    code, err = run_main(llr_detector.main, '-p', f'events_file:={journal}')
    assert code == 2 and err.strip().splitlines() == [
        f'error: parameter events_file: {journal}: not an events journal']
    assert journal.read_text() == 'my notes, not a journal\n'


def test_a_journal_that_cannot_be_written_makes_the_alarms_status_error(tmp_path):
    folder = tmp_path / 'journals'
    folder.mkdir()
    journal = folder / 'events.jsonl'     # a new journal: created at start with its header
    event = AnomalyEvent(detector='llr', component='rw1', kind='dry', time=1.0, index=10,
                         declared_time=2.0, declared_index=20, p_value=1e-9)
    with RosWorld() as world:
        node = world.node(LLRDetectorNode, parameter_overrides=[
            Parameter('events_file', value=str(journal))])
        level, message, _ = node.alarms._health()
        assert level == OK and journal.is_file()
        journal.unlink()
        folder.rmdir()
        folder.write_text('')                 # its folder is now a regular file: writes fail
        node.alarms.record([event])
        level, message, values = node.alarms._health()
    assert level == ERROR and 'journal not written' in message
    assert values['alarms_journal_errors'] == 1 and str(journal) in values['journal_last_error']


def test_a_p_value_beaten_by_a_later_parameters_file_is_named_with_its_fix(tmp_path):
    config = tmp_path / 'p.yaml'
    config.write_text('llr_detector:\n  ros__parameters:\n    events_file: ""\n'
                      '    window: 300\n')
    journal = tmp_path / 'events.jsonl'
    beaten = ['prog', '--ros-args', '-p', f'events_file:={journal}', '-p', 'window:=300',
              '--params-file', str(config)]
    kept = ['prog', '--ros-args', '--params-file', str(config),
            '-p', f'llr_detector:events_file:={journal}']
    with RosWorld() as world:
        node = world.node(LLRDetectorNode, cli_args=beaten[1:])
        assert node.params['events_file'] == ''          # rcl: the later one wins
        warnings = beaten_overrides(node, beaten)
        assert len(warnings) == 1     # window: the file gives the same value
        assert f'put -p llr_detector:events_file:={journal} after --params-file' \
            in warnings[0]
        world.remove(node)
        node = world.node(LLRDetectorNode, cli_args=kept[1:])
        assert node.params['events_file'] == str(journal)
        assert beaten_overrides(node, kept) == []


def test_the_replay_waits_for_a_subscriber_at_a_paced_rate_and_loses_nothing(tmp_path):
    n = 30
    time = 5.0 + 0.1 * np.arange(n)
    path = tmp_path / 'wheels.csv'
    write_telemetry(path, Telemetry(time=time, wheels={
        'rw1': Wheel(np.linspace(1.0, 2.0, n), np.zeros(n))}))
    with RosWorld() as world:
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=20.0),
            Parameter('subscriber_timeout', value=60.0),
            Parameter('exit_when_done', value=False)])
        world.spin_for(1.0)
        assert replay.published == 0     # rate > 0, no subscriber yet: waiting
        listener = world.node(Node, 'listener')
        wheels = Collector(listener, JointState, 'telemetry/wheels', telemetry_qos())
        world.wait_until(lambda: replay.done and len(wheels) == n, 30.0, 'every row')
        stamps = [messages.to_seconds(m.header.stamp) for m in wheels.messages]
        assert stamps == pytest.approx(time.tolist(), abs=1e-9)
        assert replay.subscribers.started_with == {'/telemetry/wheels': 1}
        assert replay.diagnostics.status(
            replay.diagnostics.components['replay']).level == OK


def test_without_subscribers_a_paced_replay_starts_after_its_timeout(tmp_path):
    path = tmp_path / 'wheels.csv'
    write_telemetry(path, Telemetry(time=np.arange(5.0), wheels={
        'rw1': Wheel(np.ones(5), np.zeros(5))}))
    with RosWorld() as world:
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=50.0),
            Parameter('subscriber_timeout', value=0.5),
            Parameter('exit_when_done', value=False)])
        world.wait_until(lambda: replay.done, 20.0, 'the end of the file')
        assert replay.subscribers.waited_s >= 0.5
        assert replay.subscribers.started_with == {'/telemetry/wheels': 0}
