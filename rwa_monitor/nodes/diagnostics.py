"""Component health on ``/diagnostics``, published the way diagnostic_updater does it.

:class:`DiagnosticsPublisher` publishes one DiagnosticStatus per component every period
(1 s) of wall time, named ``"<node>: <check>"``, ``hardware_id`` = component, KeyValues
with units in the key, STALE when the component's input stops.
"""

from __future__ import annotations

import time
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node

from rwa_monitor.nodes.qos import DIAGNOSTICS_QOS
from rwa_monitor.telemetry.codecs import key_values

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}


def publish_calibration_change(node: Node, publisher: Any, calibration: Any,
                               detector: str) -> None:
    """Publish the calibration now in force on ``anomalies`` (kind calibration_changed).

    ``calibration`` is the node's :class:`rwa_monitor.nodes.calibration.CalibrationInForce`.
    Not journalled with the alarms: it is a setting, not an anomaly (level OK).
    """
    out = DiagnosticArray()
    now = node.get_clock().now()
    out.header.stamp = now.to_msg()
    out.status = [calibration.change_status(detector, now.nanoseconds * 1e-9,
                                            node.get_name())]
    publisher.publish(out)


class ComponentHealth:
    """The health of one component: level, message, KeyValues, time of the last input."""

    def __init__(self, hardware_id: str, check: str) -> None:
        self.hardware_id = hardware_id
        self.check = check
        self.level = OK
        self.message = 'waiting for input'
        self.values: dict[str, Any] = {}
        self.last_input: float | None = None
        self.provider: Callable[[], tuple[bytes, str, dict[str, Any]]] | None = None
        self.stale_timeout: float | None = None  # None: the publisher's


class DiagnosticsPublisher:
    """Publish component health on ``/diagnostics`` the way diagnostic_updater does.

    Every ``period`` seconds of wall (steady) time, whatever the replay rate, one
    DiagnosticArray holds a status per component, named ``"<node>: <check>"`` (``"<ns>/<node>:
    <check>"`` when the node runs in a namespace); its
    stamp is the node clock (sim time under a replay). A component whose input has not
    arrived for ``stale_timeout`` seconds (its own, if set) is reported STALE (its last
    level is kept in the KeyValue ``last_level``). Staleness is measured on the steady
    clock too, because a stopped replay stops the sim clock. Only level constants are
    assigned to ``level``.
    """

    def __init__(self, node: Node, *, period: float = 1.0, stale_timeout: float = 3.0,
                 topic: str = '/diagnostics') -> None:
        self._node = node
        self.period = period
        self.stale_timeout = stale_timeout
        self.components: dict[str, ComponentHealth] = {}
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.steady_clock = self._steady  # for the node's own wall-time timers
        # "<node>" in the root namespace, "sat1/<node>" under /sat1 (the dashboard and
        # diagnostic aggregators tell spacecraft apart by it).
        self.prefix = node.get_fully_qualified_name().lstrip('/')
        self._started = self.now()
        self._last_publish = self._started
        self._pub = node.create_publisher(DiagnosticArray, topic, DIAGNOSTICS_QOS)
        self._timer = node.create_timer(period, self.publish, clock=self._steady)
        self.published = 0

    @staticmethod
    def now() -> float:
        """Return the steady-clock time (s) used for staleness.

        ``time.monotonic`` reads the same CLOCK_MONOTONIC as rclpy's STEADY_TIME clock,
        at a fraction of the cost (it is called once per message).
        """
        return time.monotonic()

    def component(self, hardware_id: str, check: str) -> ComponentHealth:
        """Return the health record of ``hardware_id`` (created on first use)."""
        health = self.components.get(hardware_id)
        if health is None:
            health = self.components[hardware_id] = ComponentHealth(hardware_id, check)
        return health

    def set(self, hardware_id: str, check: str, level: bytes, message: str,
            **values: Any) -> None:
        """Set a component's level and message; merge ``values`` into its KeyValues."""
        health = self.component(hardware_id, check)
        health.level, health.message = level, message
        health.values.update(values)

    def provide(self, hardware_id: str, check: str,
                provider: Callable[[], tuple[bytes, str, dict[str, Any]]]) -> None:
        """Compute a component's ``(level, message, values)`` by calling ``provider``.

        The provider is called only when a status is published (once a period), so a node
        need not update its health on every message.
        """
        self.component(hardware_id, check).provider = provider

    def mark_input(self, hardware_id: str, check: str, now: float | None = None) -> None:
        """Record that input for ``hardware_id`` arrived (at steady time ``now``)."""
        self.component(hardware_id, check).last_input = self.now() if now is None else now

    def remove(self, hardware_id: str) -> None:
        """Stop reporting a component."""
        self.components.pop(hardware_id, None)

    def status(self, health: ComponentHealth, now: float | None = None) -> DiagnosticStatus:
        """Return the DiagnosticStatus of one component, STALE if its input stopped."""
        now = self.now() if now is None else now
        since = now - (self._started if health.last_input is None else health.last_input)
        if health.provider is not None:
            try:
                health.level, health.message, health.values = health.provider()
            except Exception as err:  # noqa: BLE001 - a health bug must not stop the node
                health.level, health.message = ERROR, f'health check failed: {err!r}'
        values = dict(health.values)
        level, message = health.level, health.message
        timeout = self.stale_timeout if health.stale_timeout is None else health.stale_timeout
        if since > timeout:
            values['last_level'] = LEVEL_NAMES[health.level]
            level, message = STALE, f'no input for {since:.1f} s; last: {health.message}'
        values['since_input_s'] = round(since, 3)
        return DiagnosticStatus(level=level, name=f'{self.prefix}: {health.check}',
                                message=message, hardware_id=health.hardware_id,
                                values=key_values(values))

    def publish(self) -> None:
        """Publish the statuses of every component now."""
        now = self.now()
        self._last_publish = now
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = [self.status(h, now) for h in list(self.components.values())]
        self._pub.publish(msg)
        self.published += 1

    def destroy(self) -> None:
        """Destroy the timer and the publisher."""
        self._node.destroy_timer(self._timer)
        self._node.destroy_publisher(self._pub)
