"""Wheel ids from live messages are checked like file columns (issue 24, item 2)."""

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from ros_harness import Collector, RosWorld
from sensor_msgs.msg import JointState

from rwa_monitor.nodes import messages, wheels_input
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, telemetry_qos
from rwa_monitor.nodes.fss_diagnoser import FssDiagnoserNode
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.telemetry.schema import valid_name

pytestmark = pytest.mark.ros

INVALID = ['../../x', 'rw 1', 'rw1\nWARN forged line', 'a' * 65, 'rw/1', 'rüd', '*', 'x' * 200_000]


@pytest.mark.parametrize('name', ['rw1', 'RW_2-b', 'a' * 64])
def test_a_valid_wheel_id_is_not_refused_for_its_name(name):
    assert wheels_input.name_refusal(name) is None


@pytest.mark.parametrize('name', INVALID)
def test_an_invalid_wheel_id_is_refused_with_a_short_message(name):
    assert not valid_name(name)
    refusal = wheels_input.name_refusal(name)
    assert refusal.counter == 'invalid_name'
    assert len(refusal.message) < 200 and '\n' not in refusal.message
    assert 'not a valid name' in refusal.message


def test_the_llr_node_drops_and_counts_invalid_wheel_ids(tmp_path):
    journal = tmp_path / 'events.jsonl'
    names = ['rw1', *INVALID]
    n = len(names)
    with RosWorld() as world:
        detector = world.node(LLRDetectorNode, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('events_file', value=str(journal)),
            Parameter('diagnostic_period', value=0.2)])
        for i in range(5):      # the raw path (the subscription) and the message path
            msg = messages.joint_state(1.0 + i, names, [5.0] * n, [1e-4] * n)
            detector.on_raw_wheels(serialize_message(msg))
            detector.on_wheels(messages.joint_state(1.5 + i, names, [5.0] * n, [1e-4] * n))
        sink = world.node(Node, 'sink')
        feeder = sink.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
        world.wait_for_subscribers(feeder)
        diagnostics = Collector(sink, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        feeder.publish(messages.joint_state(9.0, names, [5.0] * n, [1e-4] * n))
        world.wait_until(lambda: detector.input_counters['messages'] == 11, 10.0,
                         'the published message')

        def input_status():
            for msg in reversed(diagnostics.messages):
                for status in msg.status:
                    if status.hardware_id == 'telemetry/wheels':
                        return messages.status_fields(status)
            return None
        world.wait_until(lambda: (input_status() or {}).get('invalid_name') == 11 * len(INVALID),
                         10.0, 'the counter on /diagnostics')
        assert set(detector.wheels) == {'rw1'} and detector.wheels['rw1'].samples == 11
        assert detector.input_counters['invalid_name'] == 11 * len(INVALID)
        assert all(valid_name(c) or c == 'telemetry/wheels'
                   for c in detector.diagnostics.components), detector.diagnostics.components
    text = journal.read_text() if journal.exists() else ''
    assert not any(bad in text for bad in INVALID)


def test_the_fss_node_drops_and_counts_invalid_wheel_ids():
    names = ['rw1', *INVALID]
    n = len(names)
    with RosWorld() as world:
        node = world.node(FssDiagnoserNode, parameter_overrides=[
            Parameter('use_sim_time', value=True)])
        for i in range(5):
            msg = messages.joint_state(1.0 + i, names, [5.0] * n, [1e-4] * n)
            node.on_raw_wheels(serialize_message(msg))
        assert set(node.wheels) == {'rw1'} and node.wheels['rw1'].samples == 5
        assert node.input_counters['invalid_name'] == 5 * len(INVALID)
        assert all(valid_name(c) or c == 'telemetry/wheels'
                   for c in node.diagnostics.components), node.diagnostics.components


@pytest.mark.parametrize('node_class', [LLRDetectorNode, FssDiagnoserNode])
def test_distinct_valid_wheel_ids_do_not_grow_what_a_node_remembers(node_class):
    n = wheels_input.MAX_LOGGED + 500
    with RosWorld() as world:
        node = world.node(node_class, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('wheels', value='rw1')])
        for i in range(0, n, 100):
            names = [f'w{j}' for j in range(i, i + 100)]
            node.on_raw_wheels(serialize_message(
                messages.joint_state(1.0, names, [5.0] * 100, [1e-4] * 100)))
        assert node.input_counters['unknown_wheel'] == n
        assert len(node._logged) <= wheels_input.MAX_LOGGED + 1
