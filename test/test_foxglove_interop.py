"""The bridge watched by the protocol's published client (@foxglove/ws-protocol, npm).

That client offers only the subprotocol name ``foxglove.websocket.v1``; it runs in node
(test/interop/foxglove_client.mjs) and prints what it decodes, one JSON line per event.
"""

import json
import pathlib
import queue
import shutil
import subprocess
import threading
import time

import pytest
from rclpy.parameter import Parameter
from ros_harness import RosWorld
from test_foxglove_bridge import anomaly_array, start_bridge, wheel_sample

from rwa_monitor.nodes import foxglove_bridge as fb

pytestmark = pytest.mark.ros
INTEROP = pathlib.Path(__file__).parent / 'interop'
NODE = shutil.which('node')


class _Client:
    """The npm client in a child process; its printed events in a queue."""

    def __init__(self, port, topics, origin=None):
        if NODE is None:
            pytest.skip('node is not installed: the @foxglove/ws-protocol client cannot run')
        if not (INTEROP / 'node_modules' / '@foxglove' / 'ws-protocol').is_dir():
            pytest.skip('@foxglove/ws-protocol is not installed: `make interop` '
                        '(npm ci in test/interop)')
        args = [NODE, str(INTEROP / 'foxglove_client.mjs'), f'ws://127.0.0.1:{port}',
                ','.join(topics)] + ([origin] if origin else [])
        self.proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.events = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.events.put(json.loads(line))

    def next(self, world, kind, timeout=30.0):
        """Spin ``world`` until the client prints an event of ``kind``; return it."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            world.spin_for(0.05)
            try:
                event = self.events.get_nowait()
            except queue.Empty:
                continue
            assert event['event'] != 'error', event
            if event['event'] == kind:
                return event
        raise AssertionError(f'the npm client printed no {kind} event in {timeout} s')

    def stop(self):
        self.proc.stdin.close()     # the client closes its connection on end of input
        try:
            self.proc.wait(timeout=20)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
        return self.proc.stderr.read()


def test_the_published_client_decodes_wheels_and_anomalies():
    with RosWorld() as world:
        bridge, wheels, anomalies = start_bridge(world)
        client = _Client(bridge.port, [fb.WHEELS, fb.ANOMALIES])
        try:
            assert client.next(world, 'open')['protocol'] == 'foxglove.websocket.v1'
            channels = {c['topic']: c for c in client.next(world, 'advertise')['channels']}
            assert set(channels) == {fb.WHEELS, fb.GYRO, fb.ANOMALIES, fb.ANOMALY_LOG,
                                     fb.HEALTH}
            assert channels[fb.WHEELS]['encoding'] == 'json'
            assert channels[fb.ANOMALY_LOG]['schemaName'] == 'foxglove.Log'
            world.wait_until(lambda: bridge.channels[fb.ANOMALIES].has_sinks()
                             and bridge.channels[fb.WHEELS].has_sinks(), 30.0, 'subscribed')
            world.wait_for_subscribers(wheels)
            wheels.publish(wheel_sample())
            wheel = client.next(world, 'message')
            anomalies.publish(anomaly_array())
            anomaly = client.next(world, 'message')
        finally:
            stderr = client.stop()
    assert client.proc.returncode == 0, stderr
    assert wheel['topic'] == fb.WHEELS and wheel['logTime'] == '19900000000'
    assert wheel['data'] == {'time_s': 19.9, 'wheels': {
        'rw1': {'speed_rad_s': 10.0, 'friction_nm': 1e-3},
        'rw2': {'speed_rad_s': 20.0, 'friction_nm': 2e-3}}}
    assert anomaly['topic'] == fb.ANOMALIES and anomaly['logTime'] == '20000000000'
    got = anomaly['data']
    assert (got['component'], got['kind'], got['detector'], got['level']) == (
        'rw2', 'dry', 'llr', 'WARN')
    assert got['time_s'] == 12.5 and got['declared_time_s'] == 20.0
    assert got['friction_nm'] == 2e-3 and got['speed_rad_s'] == 20.0


def test_the_published_client_from_a_page_not_allowed_is_refused():
    with RosWorld() as world:
        bridge = start_bridge(world, Parameter('allowed_origins',
                                               value=['http://localhost:8080']))[0]
        refused = _Client(bridge.port, [fb.WHEELS], origin='https://attacker.example')
        try:
            assert refused.proc.wait(timeout=30) == 1
            assert refused.events.get(timeout=5) == {'event': 'error', 'message': 'HTTP 403'}
        finally:
            refused.stop()
        allowed = _Client(bridge.port, [fb.WHEELS], origin='http://localhost:8080')
        try:
            assert allowed.next(world, 'advertise')['channels']
        finally:
            allowed.stop()
        assert bridge.front.refused == 1
