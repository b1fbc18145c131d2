"""Node ``foxglove_bridge``: serve wheels, gyro, anomalies and health to the Foxglove app.

A Foxglove WebSocket server (foxglove-sdk) on ``host``:``port`` (default 127.0.0.1:8765;
port 0 takes a free one, see :attr:`FoxgloveBridge.port`), reached through a front that
speaks both subprotocol names, ``foxglove.sdk.v1`` and ``foxglove.websocket.v1``, and
refuses browser pages from origins not in ``allowed_origins`` (default: only pages of
this machine) and clients beyond ``max_clients``; the SDK's own server listens on
loopback with TLS under a certificate only the front trusts
(:mod:`rwa_monitor.nodes.foxglove_front`). Needs the extra ``foxglove``
(``pip install 'rwa_monitor[foxglove]'``). The node subscribes to the
DESIGN.md topics and logs JSON messages on these channels, each stamped (log time) with
the telemetry time of its source so plots share one time axis:

- ``/rwa_monitor/wheels``: ``{"time_s", "wheels": {id: {"speed_rad_s", "friction_nm"}}}``
  from ``telemetry/wheels``;
- ``/rwa_monitor/gyro``: ``{"time_s", "x_rad_s", "y_rad_s", "z_rad_s"}`` from
  ``telemetry/gyro``;
- ``/rwa_monitor/anomalies``: one message per anomaly event of ``anomalies``:
  ``{"time_s" (change), "declared_time_s", "detector", "component", "kind", "level",
  "message", "fields", "speed_rad_s", "friction_nm"}``; for a wheel the last speed and
  friction received for it, so a plot of them shows the event as a marker on the curve;
- ``/rwa_monitor/anomaly_log``: the same events as ``foxglove.Log`` (the Log panel);
- ``/rwa_monitor/health``: ``{"statuses": [{"name", "hardware_id", "level", "message",
  "values"}]}`` from ``/diagnostics`` (a table).

config/foxglove_layout.json lays these out (docs/usage.md says how to open it).
"""

from __future__ import annotations

import json
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.core import keys
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import (declare_parameters, DIAGNOSTICS_QOS, ERROR, EVENTS_QOS,
                                      LEVEL_NAMES, OK, ParamSpec, qos_event_callbacks,
                                      run_node, STALE, telemetry_qos, WARN)

try:  # the extra `foxglove`: without it the node says what to install (ConfigError)
    import foxglove
    from foxglove.channels import LogChannel
    from foxglove.messages import Log, LogLevel, Timestamp

    from rwa_monitor.nodes.foxglove_front import (loopback_certificate, trusting,
                                                  WebSocketFront)
except ImportError as missing:
    _MISSING_EXTRA: ImportError | None = missing
else:
    _MISSING_EXTRA = None

MAX_CLIENTS = 32

NODE_NAME = 'foxglove_bridge'
WHEELS = '/rwa_monitor/wheels'
GYRO = '/rwa_monitor/gyro'
ANOMALIES = '/rwa_monitor/anomalies'
ANOMALY_LOG = '/rwa_monitor/anomaly_log'
HEALTH = '/rwa_monitor/health'

PARAMETERS = (
    ParamSpec('port', 8765, 'TCP port of the Foxglove WebSocket server (0: any free port).',
              low=0, high=65535, read_only=True),
    ParamSpec('host', '127.0.0.1', 'Address the server binds to (0.0.0.0 serves every '
              'interface: only on a trusted network).', read_only=True),
    ParamSpec('allowed_origins', [], 'Browser origins (scheme://host[:port]) whose pages may '
              'connect; * allows any. Empty: pages of this machine (http(s)://localhost or '
              'a loopback address) on a loopback host, none beyond it. Clients that send no '
              'Origin (not browsers) are always served.', kind=list, read_only=True),
    ParamSpec('max_clients', MAX_CLIENTS, 'Most WebSocket clients served at once (each holds '
              'three file descriptors); more are refused with HTTP 503.', low=1, high=1024,
              read_only=True),
)

_NUMBER = {'type': 'number'}
_SCHEMAS = {
    WHEELS: {'type': 'object', 'properties': {
        'time_s': _NUMBER, 'wheels': {'type': 'object', 'additionalProperties': {
            'type': 'object', 'properties': {'speed_rad_s': _NUMBER,
                                             'friction_nm': _NUMBER}}}}},
    GYRO: {'type': 'object', 'properties': {
        'time_s': _NUMBER, 'x_rad_s': _NUMBER, 'y_rad_s': _NUMBER, 'z_rad_s': _NUMBER}},
    ANOMALIES: {'type': 'object', 'properties': {
        'time_s': _NUMBER, 'declared_time_s': _NUMBER, 'detector': {'type': 'string'},
        'component': {'type': 'string'}, 'kind': {'type': 'string'},
        'level': {'type': 'string'}, 'message': {'type': 'string'},
        'fields': {'type': 'object'}, 'speed_rad_s': _NUMBER, 'friction_nm': _NUMBER}},
    HEALTH: {'type': 'object', 'properties': {'statuses': {'type': 'array', 'items': {
        'type': 'object', 'properties': {
            'name': {'type': 'string'}, 'hardware_id': {'type': 'string'},
            'level': {'type': 'string'}, 'message': {'type': 'string'},
            'values': {'type': 'object'}}}}}},
}


def _finite(value: float) -> float | None:
    """Return ``value``, or None (JSON null) when it is NaN or infinite."""
    return value if value == value and abs(value) != float('inf') else None


class FoxgloveBridge(Node):
    """Serve the monitor's topics over the Foxglove WebSocket protocol (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node, the channels and the WebSocket server."""
        super().__init__(NODE_NAME, **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        if _MISSING_EXTRA is not None:
            raise ConfigError(f'the live view needs the extra foxglove (pip install '
                              f'"rwa_monitor[foxglove]"): {_MISSING_EXTRA}')
        self.foxglove = foxglove.Context()
        self.channels = {topic: foxglove.Channel(topic, schema=schema, context=self.foxglove)
                         for topic, schema in _SCHEMAS.items()}
        self.log_channel = LogChannel(ANOMALY_LOG, context=self.foxglove)
        self._log_levels = {OK: LogLevel.Info, WARN: LogLevel.Warning, ERROR: LogLevel.Error,
                            STALE: LogLevel.Warning}
        # The SDK's server: loopback, TLS with a certificate only the front trusts, so no
        # browser page can use it (foxglove_front.py).
        certificate, key = loopback_certificate()
        self.server = foxglove.start_server(name='rwa_monitor', host='127.0.0.1', port=0,
                                            context=self.foxglove, tls_cert=certificate,
                                            tls_key=key)
        try:
            self.front = WebSocketFront(self.params['host'], self.params['port'],
                                        self.server.port, self.params['allowed_origins'],
                                        self.get_logger().warning,
                                        upstream_tls=trusting(certificate),
                                        max_clients=self.params['max_clients'])
        except OSError as err:
            self.server.stop()
            raise ConfigError(f'parameters host/port: cannot serve on '
                              f'{self.params["host"]}:{self.params["port"]}: {err}') from None
        self.port = self.front.port
        self._last_wheel: dict[str, tuple[float | None, float | None]] = {}
        self.counters = {'wheels': 0, 'gyro': 0, 'anomalies': 0, 'health': 0}
        qos = telemetry_qos()
        self.create_subscription(JointState, 'telemetry/wheels', self.on_wheels, qos,
                                 event_callbacks=qos_event_callbacks(self, 'telemetry/wheels'))
        self.create_subscription(Imu, 'telemetry/gyro', self.on_gyro, qos,
                                 event_callbacks=qos_event_callbacks(self, 'telemetry/gyro'))
        self.create_subscription(DiagnosticArray, 'anomalies', self.on_anomalies, EVENTS_QOS,
                                 event_callbacks=qos_event_callbacks(self, 'anomalies'))
        self.create_subscription(DiagnosticArray, '/diagnostics', self.on_diagnostics,
                                 DIAGNOSTICS_QOS,
                                 event_callbacks=qos_event_callbacks(self, '/diagnostics'))
        origins = (', '.join(self.front.allowed_origins) or
                   ('pages of this machine (localhost)' if self.front.loopback
                    else 'none (set allowed_origins)'))
        self.get_logger().info(f'Foxglove WebSocket server on ws://{self.params["host"]}:'
                               f'{self.port} (open it in the Foxglove app, docs/usage.md); '
                               f'browser origins allowed: {origins}')

    def _log(self, topic: str, message: dict[str, Any], stamp_ns: int) -> None:
        self.channels[topic].log(json.dumps(message, allow_nan=False).encode(),
                                 log_time=max(stamp_ns, 0))

    def on_wheels(self, msg: JointState) -> None:
        """Log one wheel sample (names with velocity and effort; others are skipped)."""
        t = messages.to_seconds(msg.header.stamp)
        wheels = {}
        efforts = list(msg.effort) if len(msg.effort) == len(msg.name) else []
        speeds = list(msg.velocity) if len(msg.velocity) == len(msg.name) else []
        for i, name in enumerate(msg.name):
            speed = _finite(float(speeds[i])) if speeds else None
            friction = _finite(float(efforts[i])) if efforts else None
            wheels[name] = {'speed_rad_s': speed, 'friction_nm': friction}
            self._last_wheel[name] = (speed, friction)
        self.counters['wheels'] += 1
        self._log(WHEELS, {'time_s': t, 'wheels': wheels}, _ns(msg.header.stamp))

    def on_gyro(self, msg: Imu) -> None:
        """Log one gyro sample."""
        v = msg.angular_velocity
        self.counters['gyro'] += 1
        self._log(GYRO, {'time_s': messages.to_seconds(msg.header.stamp),
                         'x_rad_s': _finite(v.x), 'y_rad_s': _finite(v.y),
                         'z_rad_s': _finite(v.z)}, _ns(msg.header.stamp))

    def on_anomalies(self, msg: DiagnosticArray) -> None:
        """Log each anomaly event, as JSON and as a foxglove.Log line."""
        for status in msg.status:
            fields = messages.status_fields(status)
            component = str(fields.get(keys.COMPONENT, status.hardware_id))
            change = fields.get(keys.CHANGE_TIME)
            declared = fields.get(keys.DECLARATION_TIME)
            stamp = messages.split_seconds(float(declared)) if declared is not None else (
                msg.header.stamp.sec, msg.header.stamp.nanosec)
            speed, friction = self._last_wheel.get(component, (None, None))
            level = LEVEL_NAMES.get(status.level, str(status.level))
            event = {'time_s': change, 'declared_time_s': declared,
                     'detector': fields.get(keys.DETECTOR), 'component': component,
                     'kind': fields.get(keys.KIND), 'level': level,
                     'message': status.message,
                     'fields': {k: (_finite(v) if isinstance(v, float) else v)
                                for k, v in fields.items()},
                     'speed_rad_s': speed, 'friction_nm': friction}
            stamp_ns = stamp[0] * 1_000_000_000 + stamp[1]
            self._log(ANOMALIES, event, stamp_ns)
            self.log_channel.log(Log(
                timestamp=Timestamp(sec=max(stamp[0], 0), nsec=stamp[1]),
                level=self._log_levels.get(status.level, LogLevel.Unknown),
                message=f'{component}: {status.message}', name=status.name),
                log_time=max(stamp_ns, 0))
            self.counters['anomalies'] += 1

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """Log the health table of one /diagnostics message."""
        rows = [{'name': s.name, 'hardware_id': s.hardware_id,
                 'level': LEVEL_NAMES.get(s.level, str(s.level)), 'message': s.message,
                 'values': {kv.key: kv.value for kv in s.values}} for s in msg.status]
        self.counters['health'] += 1
        self._log(HEALTH, {'statuses': rows}, _ns(msg.header.stamp))

    def destroy_node(self) -> None:
        """Stop the front and the WebSocket server, then destroy the node."""
        front, server = getattr(self, 'front', None), getattr(self, 'server', None)
        self.front = self.server = None
        if front is not None:
            front.stop()
        if server is not None:
            server.stop()
        super().destroy_node()


def _ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def main(args: Sequence[str] | None = None) -> int:
    """Run the bridge (console script ``rwa-monitor-foxglove``)."""
    return run_node(lambda: FoxgloveBridge(), args)


if __name__ == '__main__':
    raise SystemExit(main())
