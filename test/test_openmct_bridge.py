"""The live bridge of ``rwa-monitor openmct --live`` on a private ROS graph."""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.node import Node
from ros_harness import RosWorld
from sensor_msgs.msg import JointState

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS, telemetry_qos
from rwa_monitor.nodes.openmct_bridge import OpenMctBridge
from rwa_monitor.openmct.live import LiveFeed
from rwa_monitor.openmct.store import GroundStore

pytestmark = pytest.mark.ros


def test_the_bridge_finds_a_namespaced_spacecraft_and_feeds_its_points():
    store = GroundStore(live=True)
    with RosWorld() as world:
        bridge = world.node(OpenMctBridge, LiveFeed(store))
        source = world.node(Node, 'detector', namespace='sat7')
        wheels = source.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
        anomalies = source.create_publisher(DiagnosticArray, 'anomalies', EVENTS_QOS)
        health = source.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        world.wait_until(lambda: {'/sat7/telemetry/wheels', '/sat7/anomalies'}
                         <= bridge.subscribed, 15.0, 'the bridge to find /sat7')
        world.wait_for_subscribers(wheels)
        world.wait_for_subscribers(anomalies)
        for k in range(20):
            wheels.publish(messages.joint_state(0.1 * k, ['rw1', 'rw2'], [10.0, 20.0],
                                                [-2e-4, -3e-4]))
        event = AnomalyEvent('llr', 'rw2', 'dry', time=1.0, index=10, declared_time=1.5,
                             declared_index=15, p_value=1e-9)
        anomalies.publish(DiagnosticArray(status=[messages.event_status(
            event, 'sat7/llr_detector')]))
        world.wait_until(lambda: 'sat7.rw2.events' in store.series
                         and len(store.series.get('sat7.rw1.speed', [])) == 20, 15.0,
                         'the samples and the event in the store')
        world.wait_until(lambda: store.history('sat7.rw2.state', -1, 1e9)[-1]['value'] == 1.0,
                         5.0, 'the anomaly state')
        array = DiagnosticArray(status=[DiagnosticStatus(
            name='sat7/llr_detector: rw2 friction', hardware_id='rw2',
            level=DiagnosticStatus.OK)])
        array.header.stamp = messages.to_stamp(5.0)       # after the declaration: acked
        world.wait_for_subscribers(health)
        health.publish(array)
        world.wait_until(lambda: store.history('sat7.rw2.state', -1, 1e9)[-1]['value'] == 0.0,
                         10.0, 'the acknowledgement to clear the state')
    assert store.history('sat7.rw1.friction', -1, 1e9)[0]['value'] == -2e-4
    assert store.history('sat7.rw2.events', -1, 1e9)[0]['kind'] == 'dry'
