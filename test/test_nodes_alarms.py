"""Latched anomalies in the detector nodes: journal, restart, late subscriber, acknowledge."""

import json

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld
from std_srvs.srv import Trigger

from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
from rwa_monitor.telemetry import write_telemetry

pytestmark = pytest.mark.ros

CONFIG = {'window': 200, 'k_verif': 'auto', 'false_alarm_rate': 1.0e-5, 'noise_std': 'auto'}


def _seeded(tmp_path, n=3000):
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=n, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'seeded.csv'
    write_telemetry(path, tele)
    return path


def _detector(world, journal, **params):
    values = {'use_sim_time': True, **CONFIG, 'events_file': str(journal),
              'diagnostic_period': 0.2, **params}
    return world.node(LLRDetectorNode, parameter_overrides=[
        Parameter(k, value=v) for k, v in values.items()])


def _latest(collector, hardware_id):
    found = [s for m in collector.messages for s in m.status if s.hardware_id == hardware_id]
    return found[-1] if found else None


def _declared(collector):
    return [messages.status_event(s) for m in collector.messages for s in m.status]


def test_anomaly_survives_parameter_change_restart_and_reaches_a_late_subscriber(tmp_path):
    path = _seeded(tmp_path)
    journal = tmp_path / 'events.jsonl'
    with RosWorld('events') as world:
        detector = _detector(world, journal)
        sink = world.node(Node, 'sink')
        diagnostics = Collector(sink, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=0.0),
            Parameter('burst', value=50), Parameter('exit_when_done', value=False)])
        world.wait_until(lambda: detector.alarms.store.active('rw2'), 60.0, 'a declaration')
        world.wait_until(lambda: replay.done, 60.0, 'the replay to finish')
        declared = [a.event for a in detector.alarms.store.active()]
        assert {e.component for e in declared} == {'rw2'}
        # A parameter change restarts every wheel's detector; the record stays latched.
        detector.set_parameters([Parameter('false_alarm_rate', value=1e-6)])
        assert detector.wheels['rw2'].last_event is None
        count = len(diagnostics.messages)
        world.wait_until(lambda: len(diagnostics.messages) > count + 1, 5.0, 'diagnostics')
        status = _latest(diagnostics, 'rw2')
        assert status.level != b'\x00'
        assert f'latched: {declared[-1].kind} anomaly' in status.message
        assert messages.status_fields(_latest(diagnostics, 'alarms'))['active'] == 1
        world.remove(detector)     # the node goes away (its journal is already synced)
    lines = [json.loads(line) for line in journal.read_text().splitlines()]
    assert lines[0]['record'] == 'journal'     # the header the journal was created with
    assert [r['event']['component'] for r in lines[1:]] == ['rw2'] * (len(lines) - 1)

    with RosWorld('events') as world:
        restarted = _detector(world, journal)
        assert [a.event.component for a in restarted.alarms.store.active()] == ['rw2']
        late = world.node(Node, 'late_dashboard')
        anomalies = Collector(late, DiagnosticArray, 'anomalies', EVENTS_QOS)
        diagnostics = Collector(late, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        world.wait_until(lambda: _declared(anomalies), 10.0, 'the re-published anomaly')
        got = _declared(anomalies)
        assert [(e.component, e.kind, e.index) for e in got] == \
            [(e.component, e.kind, e.index) for e in declared[-1:]]
        world.wait_until(lambda: _latest(diagnostics, 'alarms') is not None, 5.0, 'status')
        assert _latest(diagnostics, 'alarms').level == messages.event_level(got[0].kind)

        client = late.create_client(Trigger, '/llr_detector/acknowledge')
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(Trigger.Request())
        world.wait_until(future.done, 5.0, 'the acknowledge response')
        assert future.result().success and 'acknowledged 1' in future.result().message
        assert restarted.alarms.store.active() == []
        world.remove(restarted)

    with RosWorld('events') as world:
        again = _detector(world, journal)
        assert again.alarms.store.active() == []


def test_detector_exception_is_caught_counted_and_restarts_only_that_wheel(tmp_path):
    path = _seeded(tmp_path)
    with RosWorld('events') as world:
        detector = _detector(world, tmp_path / 'j.jsonl', events_file='')
        broken = {'armed': True}
        original = detector._new_runner

        def fragile(wheel_id):
            runner = original(wheel_id)
            if wheel_id == 'rw1' and broken['armed']:
                broken['armed'] = False
                real = runner.update

                def update(t, w, f):
                    if t > 20.0:
                        raise ZeroDivisionError('injected')
                    return real(t, w, f)
                runner.update = update
            return runner
        detector._new_runner = fragile
        sink = world.node(Node, 'sink')
        diagnostics = Collector(sink, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=0.0),
            Parameter('burst', value=50), Parameter('exit_when_done', value=False)])
        world.wait_until(lambda: replay.done and detector.wheels['rw2'].samples == 3000,
                         60.0, 'every sample')
        world.spin_for(0.5)
        assert detector.input_counters['detector_failures'] == 1
        assert detector.wheels['rw1'].samples == 3000
        assert detector.wheels['rw1'].runner.detector.n_samples > 2500   # restarted, running
        status = _latest(diagnostics, 'rw1')
        assert status.level == b'\x02' and 'detector failed' in status.message
        assert _latest(diagnostics, 'rw2').level != b'\x02' or \
            'detector failed' not in _latest(diagnostics, 'rw2').message
