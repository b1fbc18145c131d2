"""Replay and detector as two OS processes over DDS on localhost; the anomaly arrives."""

import os
import shutil
import signal
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from ros_harness import Collector, RosWorld

from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import EVENTS_QOS
from rwa_monitor.pipelines import llr
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
from rwa_monitor.telemetry import read_telemetry, write_telemetry

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _script(name):
    path = shutil.which(name, path=os.path.dirname(sys.executable))
    if path is None:
        pytest.fail(f'console script {name} is not installed next to {sys.executable}')
    return path


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
    return proc.stdout.read().decode(errors='replace') if proc.stdout else ''


def _live(events):
    """Return detect's events less its end-of-record ones (a live node has no end)."""
    return [e for e in events if not e.details.get('final')]


def test_replay_and_detector_processes_deliver_the_anomaly(tmp_path):
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=3000, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'seeded.csv'
    write_telemetry(path, tele)
    config = {'window': 200, 'k_verif': 'auto', 'false_alarm_rate': 1.0e-5,
              'noise_std': 'auto'}
    expected = _live(llr.run(read_telemetry(path), config))
    assert expected
    with RosWorld() as world:
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        env = world.env()
        detector = subprocess.Popen(
            [_script('rwa-monitor-llr'), '--ros-args', '-p', 'window:=200',
             '-p', 'stale_timeout:=30.0'],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        replay = None
        try:
            world.wait_for_publishers(anomalies.subscription, timeout_sec=30.0)
            replay = subprocess.Popen(
                [_script('rwa-monitor-replay'), '--ros-args', '-p', f'file:={path}',
                 '-p', 'rate:=0.0'],
                env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
            world.wait_until(lambda: len(anomalies) > 0, 60.0, 'the anomaly from the detector')
            assert replay.wait(timeout=60) == 0, 'the replay ends by itself when done'
            world.wait_until(lambda: sum(len(m.status) for m in anomalies.messages)
                             >= len(expected), 30.0, 'every event')
        finally:
            log = _stop(detector) + (_stop(replay) if replay is not None else '')
    got = [messages.status_event(s) for m in anomalies.messages for s in m.status]
    assert [(e.component, e.kind, e.index, e.declared_index) for e in got] == \
        [(e.component, e.kind, e.index, e.declared_index) for e in expected], log
    assert detector.returncode == 0, log


def test_the_one_process_monitor_gives_the_events_of_the_separate_nodes(tmp_path):
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=3000, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'seeded.csv'
    write_telemetry(path, tele)
    expected = _live(llr.run(read_telemetry(path), {'window': 200, 'k_verif': 'auto',
                                                    'false_alarm_rate': 1.0e-5,
                                                    'noise_std': 'auto'}))
    assert expected
    with RosWorld() as world:
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        monitor = subprocess.Popen(
            [sys.executable, '-m', 'rwa_monitor.nodes.monitor', '--ros-args',
             '-p', 'llr_detector:window:=200', '-p', 'stale_timeout:=30.0'],
            env=world.env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        replay = None
        try:
            world.wait_for_publishers(anomalies.subscription, count=3, timeout_sec=60.0)
            replay = subprocess.Popen(
                [_script('rwa-monitor-replay'), '--ros-args', '-p', f'file:={path}',
                 '-p', 'rate:=0.0'],
                env=world.env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
            assert replay.wait(timeout=120) == 0, 'the replay ends by itself when done'
            world.wait_until(lambda: sum(len(m.status) for m in anomalies.messages)
                             >= len(expected), 30.0, 'every event')
        finally:
            log = _stop(monitor) + (_stop(replay) if replay is not None else '')
    got = [messages.status_event(s) for m in anomalies.messages for s in m.status]
    got = [e for e in got if e.detector == 'llr']
    assert [(e.component, e.kind, e.index, e.declared_index) for e in got] == \
        [(e.component, e.kind, e.index, e.declared_index) for e in expected], log
    assert monitor.returncode == 0 and 'Traceback' not in log, log
