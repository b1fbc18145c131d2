"""The Foxglove bridge: a WebSocket client the project did not write receives an anomaly."""

import json
import pathlib
import re
import struct
import time

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import RosWorld
from sensor_msgs.msg import JointState
from websockets.sync.client import connect

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.nodes import foxglove_bridge as fb
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import EVENTS_QOS, telemetry_qos

pytestmark = pytest.mark.ros
LAYOUT = pathlib.Path(__file__).parents[1] / 'config' / 'foxglove_layout.json'


def _text(ws, op, timeout=5.0):
    """Return the next JSON control message with this ``op``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        frame = ws.recv(timeout=max(end - time.monotonic(), 0.01))
        if isinstance(frame, str) and json.loads(frame).get('op') == op:
            return json.loads(frame)
    raise AssertionError(f'no {op} message')


def _data(ws, subscription, timeout=5.0):
    """Return the JSON payload of the next message data frame of ``subscription``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        frame = ws.recv(timeout=max(end - time.monotonic(), 0.01))
        if isinstance(frame, bytes) and frame[0] == 0x01:
            sub_id, log_time = struct.unpack_from('<IQ', frame, 1)
            if sub_id == subscription:
                return log_time, json.loads(frame[13:])
    raise AssertionError('no message data')


def test_a_websocket_client_subscribes_and_receives_an_anomaly():
    event = AnomalyEvent(detector='llr', component='rw2', kind='dry', time=12.5, index=125,
                         declared_time=20.0, declared_index=200, p_value=1e-7)
    with RosWorld() as world:
        bridge = world.node(fb.FoxgloveBridge, parameter_overrides=[
            Parameter('port', value=0), Parameter('use_sim_time', value=False)])
        assert bridge.port > 0 and bridge.params['host'] == '127.0.0.1'
        source = world.node(Node, 'detector')
        wheels = source.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
        anomalies = source.create_publisher(DiagnosticArray, 'anomalies', EVENTS_QOS)
        with connect(f'ws://127.0.0.1:{bridge.port}', open_timeout=5,
                     subprotocols=['foxglove.sdk.v1', 'foxglove.websocket.v1']) as ws:
            channels = {c['topic']: c for c in _text(ws, 'advertise')['channels']}
            assert set(channels) >= {fb.WHEELS, fb.GYRO, fb.ANOMALIES, fb.ANOMALY_LOG,
                                     fb.HEALTH}
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 1, 'channelId': channels[fb.ANOMALIES]['id']},
                {'id': 2, 'channelId': channels[fb.WHEELS]['id']}]}))
            world.wait_until(lambda: bridge.channels[fb.ANOMALIES].has_sinks()
                             and bridge.channels[fb.WHEELS].has_sinks(), 5.0, 'subscribed')
            world.wait_for_subscribers(wheels)
            wheels.publish(messages.joint_state(19.9, ['rw1', 'rw2'], [10.0, 20.0],
                                                [1e-3, 2e-3]))
            array = DiagnosticArray(status=[messages.event_status(event, 'llr_detector')])
            array.header.stamp = messages.to_stamp(20.0)
            world.wait_until(lambda: bridge.counters['wheels'] == 1, 5.0, 'wheel sample')
            anomalies.publish(array)
            world.wait_until(lambda: bridge.counters['anomalies'] == 1, 5.0, 'anomaly')
            log_time, got = _data(ws, 1)
    assert log_time == 20_000_000_000
    assert got['component'] == 'rw2' and got['kind'] == 'dry' and got['detector'] == 'llr'
    assert got['time_s'] == 12.5 and got['declared_time_s'] == 20.0 and got['level'] == 'WARN'
    assert got['friction_nm'] == 2e-3 and got['speed_rad_s'] == 20.0  # the marker's place


def test_the_shipped_layout_uses_only_served_channels():
    layout = json.loads(LAYOUT.read_text())
    served = {fb.WHEELS, fb.GYRO, fb.ANOMALIES, fb.ANOMALY_LOG, fb.HEALTH}
    used = set(re.findall(r'/rwa_monitor/[a-z_]+', json.dumps(layout)))
    assert used and used <= served
    kinds = {panel.split('!')[0] for panel in layout['configById']}
    assert {'Plot', 'Table', 'RosOut'} <= kinds or {'Plot', 'Table', 'Log'} <= kinds
    text = ' '.join(path['value'] for panel in layout['configById'].values()
                    for path in panel.get('paths', []))
    for wheel in ('rw1', 'rw2', 'rw3', 'rw4'):
        assert f'wheels.{wheel}.friction_nm' in text and f'wheels.{wheel}.speed_rad_s' in text
        assert f'component=="{wheel}"' in text
