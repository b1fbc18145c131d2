"""The live side of ``rwa-monitor openmct --live``: a node that feeds the operator's view.

:class:`OpenMctBridge` finds, every ``DISCOVERY_S`` seconds, every topic named
``.../telemetry/wheels`` (JointState), ``.../telemetry/gyro`` (Imu), ``.../anomalies`` and
``/diagnostics`` (DiagnosticArray) in its ROS domain (the root namespace's at once),
subscribes to each, and hands the
decoded messages to a :class:`rwa_monitor.openmct.live.LiveFeed`, which the server reads.
Telemetry is subscribed best-effort (``telemetry_qos(reliable=False)``): a viewer that
falls behind drops samples rather than slowing a replay or the detectors; anomalies are
reliable and transient-local (late joiners get the kept events), /diagnostics reliable.
:class:`BridgeThread` runs the node in its own context and thread beside the server.
"""

from __future__ import annotations

import os
import pathlib
import threading
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS, telemetry_qos
from rwa_monitor.openmct.live import LiveFeed

BRIDGE_NAME = 'openmct_bridge'
DISCOVERY_S = 1.0
FLUSH_S = 0.05
SUFFIXES = {'/telemetry/wheels': 'sensor_msgs/msg/JointState',
            '/telemetry/gyro': 'sensor_msgs/msg/Imu',
            '/anomalies': 'diagnostic_msgs/msg/DiagnosticArray'}


class OpenMctBridge(Node):
    """Subscribe to every spacecraft's topics and feed ``feed``; see the module docstring."""

    def __init__(self, feed: LiveFeed, **kwargs: Any) -> None:
        """Create the node, subscribe to /diagnostics and start discovering the rest."""
        super().__init__(BRIDGE_NAME, **kwargs)
        self.feed = feed
        self.subscribed: set[str] = set()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_subscription(DiagnosticArray, '/diagnostics', self.on_diagnostics,
                                 DIAGNOSTICS_QOS)
        self.subscribed.add('/diagnostics')
        self.create_timer(DISCOVERY_S, self.discover, clock=steady)
        self.create_timer(FLUSH_S, feed.flush, clock=steady)
        for suffix in SUFFIXES:   # the root namespace at once: a replay started next waits
            self._subscribe(suffix, '/', suffix)   # for these subscriptions
        self.discover()

    def discover(self) -> None:
        """Subscribe to every new wheels, gyro and anomalies topic of the graph."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subscribed:
                continue
            for suffix, msg_type in SUFFIXES.items():
                if topic.endswith(suffix) and msg_type in types:
                    self._subscribe(topic, topic[:-len(suffix)] or '/', suffix)

    def _subscribe(self, topic: str, namespace: str, suffix: str) -> None:
        self.subscribed.add(topic)
        if suffix == '/telemetry/wheels':
            self.create_subscription(JointState, topic, lambda m: self.on_wheels(namespace, m),
                                     telemetry_qos(reliable=False))
        elif suffix == '/telemetry/gyro':
            self.create_subscription(Imu, topic, lambda m: self.on_gyro(namespace, m),
                                     telemetry_qos(reliable=False))
        else:
            self.create_subscription(DiagnosticArray, topic,
                                     lambda m: self.on_anomalies(namespace, m), EVENTS_QOS)
        self.get_logger().info(f'live view: subscribed to {topic}')

    def on_wheels(self, namespace: str, msg: JointState) -> None:
        """Hand one wheels sample to the feed (a message with mismatched arrays is skipped)."""
        n = len(msg.name)
        if len(msg.velocity) != n:
            return
        frictions = list(msg.effort) if len(msg.effort) == n else None
        self.feed.wheels(namespace, messages.to_seconds(msg.header.stamp), list(msg.name),
                         list(msg.velocity), frictions)

    def on_gyro(self, namespace: str, msg: Imu) -> None:
        """Hand one gyro sample to the feed."""
        v = msg.angular_velocity
        self.feed.gyro(namespace, messages.to_seconds(msg.header.stamp), (v.x, v.y, v.z))

    def on_anomalies(self, namespace: str, msg: DiagnosticArray) -> None:
        """Hand each anomaly event to the feed (a status that is not an event is skipped)."""
        for status in msg.status:
            try:
                record = messages.status_event(status).to_json()
            except (KeyError, ValueError, TypeError):
                continue
            node = status.name.split(':', 1)[0].strip().strip('/')
            self.feed.event(namespace, node, record)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """Hand each status to the feed (latched alarms and acknowledgements)."""
        stamp = messages.to_seconds(msg.header.stamp)
        for status in msg.status:
            self.feed.status(stamp, status.name, status.hardware_id,
                             messages.status_fields(status))


class BridgeThread:
    """Run an :class:`OpenMctBridge` in its own ROS context and thread."""

    def __init__(self, store: Any, domain_id: int,
                 calibration: pathlib.Path | None = None) -> None:
        """Create the context and the node (start() spins it)."""
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        cal = None
        if calibration is not None:
            from rwa_monitor.telemetry.calibration_file import load
            cal = load(calibration)
        self.feed = LiveFeed(store, cal)
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = OpenMctBridge(self.feed, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name='openmct-bridge', daemon=True)
        self._stop = threading.Event()

    def _spin(self) -> None:
        try:
            while not self._stop.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            pass

    def start(self) -> None:
        """Start spinning."""
        self._thread.start()

    def stop(self) -> None:
        """Stop spinning, destroy the node and shut the context down."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
