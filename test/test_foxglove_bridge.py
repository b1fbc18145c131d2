"""The Foxglove bridge: a WebSocket client receives an anomaly; the front's names and origins."""

import json
import pathlib
import re
import socket
import struct
import time

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import RosWorld
from sensor_msgs.msg import JointState
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import foxglove_bridge as fb
from rwa_monitor.nodes import foxglove_front as front
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


EVENT = AnomalyEvent(detector='llr', component='rw2', kind='dry', time=12.5, index=125,
                     declared_time=20.0, declared_index=200, p_value=1e-7)


def start_bridge(world, *overrides):
    """Return (bridge on a free port, wheels publisher, anomalies publisher) in ``world``."""
    bridge = world.node(fb.FoxgloveBridge, parameter_overrides=[
        Parameter('port', value=0), Parameter('use_sim_time', value=False), *overrides])
    source = world.node(Node, 'detector')
    wheels = source.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
    anomalies = source.create_publisher(DiagnosticArray, 'anomalies', EVENTS_QOS)
    return bridge, wheels, anomalies


def wheel_sample():
    """Return the wheel sample the tests publish: rw1 and rw2 at t = 19.9 s."""
    return messages.joint_state(19.9, ['rw1', 'rw2'], [10.0, 20.0], [1e-3, 2e-3])


def anomaly_array():
    """Return the DiagnosticArray of :data:`EVENT` as llr_detector publishes it."""
    array = DiagnosticArray(status=[messages.event_status(EVENT, 'llr_detector')])
    array.header.stamp = messages.to_stamp(20.0)
    return array


def test_a_websocket_client_subscribes_and_receives_an_anomaly():
    with RosWorld() as world:
        bridge, wheels, anomalies = start_bridge(world)
        assert bridge.port > 0 and bridge.params['host'] == '127.0.0.1'
        with connect(f'ws://127.0.0.1:{bridge.port}', open_timeout=5,
                     subprotocols=['foxglove.sdk.v1', 'foxglove.websocket.v1']) as ws:
            assert ws.subprotocol == 'foxglove.sdk.v1'
            channels = {c['topic']: c for c in _text(ws, 'advertise')['channels']}
            assert set(channels) >= {fb.WHEELS, fb.GYRO, fb.ANOMALIES, fb.ANOMALY_LOG,
                                     fb.HEALTH}
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 1, 'channelId': channels[fb.ANOMALIES]['id']},
                {'id': 2, 'channelId': channels[fb.WHEELS]['id']}]}))
            world.wait_until(lambda: bridge.channels[fb.ANOMALIES].has_sinks()
                             and bridge.channels[fb.WHEELS].has_sinks(), 5.0, 'subscribed')
            world.wait_for_subscribers(wheels)
            wheels.publish(wheel_sample())
            world.wait_until(lambda: bridge.counters['wheels'] == 1, 5.0, 'wheel sample')
            anomalies.publish(anomaly_array())
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


@pytest.mark.parametrize('origin, allowed, loopback, expected', [
    (None, [], False, True),                       # not a browser: always served
    ('https://viewer.example', [], True, False),   # empty list: pages of this machine only
    ('https://evil.example', [], True, False),
    ('http://localhost:3000', [], True, True),
    ('https://127.0.0.1:8443', [], True, True),
    ('http://[::1]:8080', [], True, True),
    ('http://localhost.evil.example', [], True, False),
    ('null', [], True, False),                     # a file:// or sandboxed page
    ('file://', [], True, False),
    ('http://localhost:3000', [], False, False),   # empty list beyond loopback: none
    ('https://viewer.example', [], False, False),
    ('https://viewer.example', ['https://viewer.example'], False, True),
    ('https://other.example', ['https://viewer.example'], True, False),  # a list applies
    ('https://other.example', ['*'], False, True),
])
def test_origin_rule(origin, allowed, loopback, expected):
    assert front.origin_allowed(origin, allowed, loopback) is expected


@pytest.mark.parametrize('host, loopback', [('127.0.0.1', True), ('localhost', True),
                                            ('::1', True), ('127.0.0.2', True),
                                            ('0.0.0.0', False), ('192.0.2.7', False),
                                            ('ground-station', False)])
def test_loopback_hosts(host, loopback):
    assert front.is_loopback(host) is loopback


def test_by_default_only_pages_of_this_machine_connect():
    """Issue 36: on main 91ca172 any web page open on the operator's machine connected."""
    with RosWorld() as world:
        bridge = start_bridge(world)[0]
        url = f'ws://127.0.0.1:{bridge.port}'
        with pytest.raises(InvalidStatus) as refused:
            connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=5,
                    origin='https://evil.example')
        assert refused.value.response.status_code == 403
        for origin in ('http://localhost:3000', 'http://127.0.0.1:8080', None):
            with connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=5,
                         origin=origin) as ws:
                assert _text(ws, 'serverInfo')
        assert bridge.front.refused == 1


def test_the_sdk_port_serves_no_page_and_no_plain_client():
    """The SDK's own loopback port: TLS under a certificate only the front trusts.

    On main 91ca172 it accepted ``Origin: https://evil.example`` in the clear. A page (or
    anything else) gets neither a plain WebSocket nor a verified TLS handshake.
    """
    import ssl
    from websockets.exceptions import InvalidMessage
    with RosWorld() as world:
        bridge = start_bridge(world)[0]
        sdk = bridge.server.port
        assert sdk != bridge.port
        for origin in ('https://evil.example', None):
            with pytest.raises((InvalidMessage, OSError, EOFError)):
                connect(f'ws://127.0.0.1:{sdk}', subprotocols=['foxglove.sdk.v1'],
                        open_timeout=5, origin=origin)
            with pytest.raises(ssl.SSLCertVerificationError):
                connect(f'wss://127.0.0.1:{sdk}', subprotocols=['foxglove.sdk.v1'],
                        open_timeout=5, origin=origin)


@pytest.fixture
def sdk_front():
    """Yield (front, warnings): the front on a free loopback port before an SDK server."""
    import foxglove
    context = foxglove.Context()
    channel = foxglove.Channel('/t', schema={'type': 'object'}, context=context)
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context)
    warnings = []
    gate = front.WebSocketFront('127.0.0.1', 0, server.port, ['http://localhost:8080'],
                                warnings.append)
    try:
        yield gate, warnings, channel
    finally:
        gate.stop()
        server.stop()


@pytest.mark.parametrize('offered', [['foxglove.websocket.v1'], ['foxglove.sdk.v1'],
                                     ['foxglove.websocket.v1', 'foxglove.sdk.v1']])
def test_either_subprotocol_name_gets_the_sdk_server(sdk_front, offered):
    gate, warnings, channel = sdk_front
    with connect(f'ws://127.0.0.1:{gate.port}', subprotocols=offered, open_timeout=5) as ws:
        expected = 'foxglove.sdk.v1' if 'foxglove.sdk.v1' in offered else offered[0]
        assert ws.subprotocol == expected
        assert 'capabilities' in _text(ws, 'serverInfo')
        (advertised,) = _text(ws, 'advertise')['channels']
        ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 7, 'channelId': advertised['id']}]}))
        deadline = time.monotonic() + 5.0
        while not channel.has_sinks() and time.monotonic() < deadline:
            time.sleep(0.02)
        channel.log(b'{"x": 1}', log_time=5)
        assert _data(ws, 7) == (5, {'x': 1})
    assert warnings == []


def test_a_client_offering_no_known_subprotocol_is_refused(sdk_front):
    gate = sdk_front[0]
    for offered in ([], ['foxglove.websocket.v2']):
        with pytest.raises(InvalidStatus) as refused:
            connect(f'ws://127.0.0.1:{gate.port}', subprotocols=offered, open_timeout=5)
        assert refused.value.response.status_code == 400


def test_origins_outside_the_list_are_refused_with_a_log_line(sdk_front):
    gate, warnings, _ = sdk_front
    url = f'ws://127.0.0.1:{gate.port}'
    with pytest.raises(InvalidStatus) as refused:
        connect(url, subprotocols=['foxglove.websocket.v1'], open_timeout=5,
                origin='https://attacker.example')
    assert refused.value.response.status_code == 403
    assert gate.refused == 1 and len(warnings) == 1
    assert "Origin 'https://attacker.example'" in warnings[0]
    assert "allowed_origins ['http://localhost:8080']" in warnings[0]
    for origin in ('http://localhost:8080', None):  # listed, or not a browser
        with connect(url, subprotocols=['foxglove.websocket.v1'], open_timeout=5,
                     origin=origin) as ws:
            assert _text(ws, 'serverInfo')
    assert gate.refused == 1


def test_the_bridge_applies_its_allowed_origins_parameter():
    with RosWorld() as world:
        bridge = start_bridge(world, Parameter('allowed_origins',
                                               value=['http://localhost:8080']))[0]
        assert bridge.front.allowed_origins == ['http://localhost:8080']
        with pytest.raises(InvalidStatus):
            connect(f'ws://127.0.0.1:{bridge.port}', subprotocols=['foxglove.websocket.v1'],
                    open_timeout=5, origin='https://attacker.example')
        assert bridge.front.refused == 1


def test_a_port_in_use_is_a_config_error_naming_it():
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        with RosWorld() as world:
            with pytest.raises(ConfigError, match=f'host/port: cannot serve on 127.0.0.1:{port}'):
                world.node(fb.FoxgloveBridge, parameter_overrides=[Parameter('port', value=port)])


IDLE_CLIENT = '''
import json, sys, time
from websockets.sync.client import connect
ws = connect(sys.argv[1], subprotocols=['foxglove.sdk.v1'], ping_interval=None)
while True:
    frame = ws.recv()
    if isinstance(frame, str) and json.loads(frame).get('op') == 'advertise':
        channel = json.loads(frame)['channels'][0]['id']
        ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 1, 'channelId': channel}]}))
        break
print('subscribed', flush=True)
time.sleep(600)   # reads nothing more and answers no ping: an idle client
'''


def _open_fds():
    return len(list(pathlib.Path('/proc/self/fd').iterdir()))


def _wait(condition, timeout, what):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.1)


def test_idle_clients_that_leave_release_their_descriptors_without_tracebacks(caplog):
    """Issue 36: idle clients left 212 "keepalive ping failed" tracebacks and ~9 fds each.

    Five clients subscribe to a busy channel, stop reading (SIGSTOP) until the front's
    keepalive drops them, then are killed. The front held three descriptors per client
    and none after; nothing was logged with a traceback, nothing printed on stderr.
    """
    import logging
    import signal
    import subprocess
    import sys
    import threading
    import foxglove
    caplog.set_level(logging.DEBUG)
    context = foxglove.Context()
    channel = foxglove.Channel('/busy', schema={'type': 'object'}, context=context)
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context)
    gate = front.WebSocketFront('127.0.0.1', 0, server.port, [], print, keepalive=(0.5, 0.5))
    stop = threading.Event()

    def pump():
        payload = b'{"x": "' + b'y' * 2000 + b'"}'
        while not stop.is_set():
            channel.log(payload)
            time.sleep(0.0005)
    threading.Thread(target=pump, daemon=True).start()
    before = _open_fds()
    clients = [subprocess.Popen([sys.executable, '-c', IDLE_CLIENT,
                                 f'ws://127.0.0.1:{gate.port}'], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True) for _ in range(5)]
    try:
        for client in clients:
            assert client.stdout.readline().strip() == 'subscribed'
            client.stdout.close()
        held = _open_fds() - before
        for client in clients:
            client.send_signal(signal.SIGSTOP)
        _wait(lambda: gate.clients == 0, 30.0, 'the idle clients to be dropped')
    finally:
        for client in clients:
            client.kill()
            client.wait()
        stop.set()
    _wait(lambda: _open_fds() <= before, 30.0, 'descriptors to be released')
    gate.stop()
    server.stop()
    assert held <= 3 * 5, f'{held} descriptors for 5 clients'
    assert not [r for r in caplog.records if r.exc_info or 'Traceback' in r.getMessage()]
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


def test_clients_beyond_max_clients_are_refused_with_503():
    import foxglove
    context = foxglove.Context()
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context)
    warnings = []
    gate = front.WebSocketFront('127.0.0.1', 0, server.port, [], warnings.append,
                                max_clients=2)
    url = f'ws://127.0.0.1:{gate.port}'
    try:
        with connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=5) as one, \
                connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=5) as two:
            assert _text(one, 'serverInfo') and _text(two, 'serverInfo')
            with pytest.raises(InvalidStatus) as refused:
                connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=5)
            assert refused.value.response.status_code == 503
        assert gate.busy == 1 and '2 clients are connected' in warnings[0]
        _wait(lambda: gate.clients == 0, 10.0, 'the two clients to leave')
        with connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=5) as three:
            assert _text(three, 'serverInfo')
    finally:
        gate.stop()
        server.stop()
