"""Recordings and the nodes: multi-rate replay, the recorder."""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import QuaternionStamped
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Imu, JointState
from test_recordings import _multi_rate, TOPICS

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS, telemetry_qos
from rwa_monitor.nodes.recorder import Recorder
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.telemetry import rosbag_io

pytestmark = pytest.mark.ros


def test_replay_publishes_each_stream_at_its_own_rate(tmp_path):
    path = tmp_path / 'rec'
    wheel_ns, gyro_ns, star_ns = _multi_rate(path, seconds=5.0)
    with RosWorld() as world:
        node = world.node(Node, 'listener')
        qos = telemetry_qos()
        wheels = Collector(node, JointState, 'telemetry/wheels', qos)
        gyro = Collector(node, Imu, 'telemetry/gyro', qos)
        star = Collector(node, QuaternionStamped, 'telemetry/star_tracker', qos)
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('topics', value=TOPICS),
            Parameter('rate', value=0.0), Parameter('exit_when_done', value=False)])
        world.wait_until(lambda: replay.done and len(star) == len(star_ns)
                         and len(wheels) == len(wheel_ns) and len(gyro) == len(gyro_ns),
                         20.0, 'every sample of every stream')
    for got, stamps in ((wheels, wheel_ns), (gyro, gyro_ns), (star, star_ns)):
        sent = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in got.messages]
        assert sent == stamps


def test_recorder_writes_anomalies_and_diagnostics_into_a_rosbag2_folder(tmp_path):
    out = tmp_path / 'review'
    event = AnomalyEvent(detector='llr', component='rw2', kind='dry', time=12.5, index=125,
                         declared_time=20.0, declared_index=200, p_value=1e-7)
    with RosWorld() as world:
        node = world.node(Node, 'detector')
        anomalies = node.create_publisher(DiagnosticArray, 'anomalies', EVENTS_QOS)
        diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        recorder = world.node(Recorder, parameter_overrides=[
            Parameter('output', value=str(out)), Parameter('use_sim_time', value=False)])
        world.wait_for_subscribers(diagnostics)
        array = DiagnosticArray(status=[messages.event_status(event, 'llr_detector')])
        array.header.stamp = messages.to_stamp(20.0)
        anomalies.publish(array)
        for k in range(3):
            health = DiagnosticArray(status=[DiagnosticStatus(name='rw1', level=b'\x00')])
            health.header.stamp = messages.to_stamp(21.0 + k)
            diagnostics.publish(health)
        world.wait_until(lambda: recorder.counts.get('/diagnostics') == 3
                         and recorder.counts.get('/anomalies') == 1, 10.0, 'recorded')
        assert not out.exists()  # appears whole when the node ends
        world.remove(recorder)
    assert (out / 'metadata.yaml').is_file()
    store = rosbag_io.typestore()
    got = {}
    with Reader(out) as reader:
        for conn, stamp, data in reader.messages():
            got.setdefault(conn.topic, []).append((stamp, store.deserialize_cdr(
                data, conn.msgtype)))
    assert [s for s, _ in got['/diagnostics']] == [21_000_000_000, 22_000_000_000,
                                                   23_000_000_000]
    (stamp, array), = got['/anomalies']
    fields = {kv.key: kv.value for kv in array.status[0].values}
    assert stamp == 20_000_000_000 and fields['component'] == 'rw2'
    assert np.isclose(float(fields['change_time_s']), 12.5)
