"""QoS profiles of the rwa_monitor topics, and the incompatible-QoS warning (docs/nodes.md)."""

from __future__ import annotations

from typing import Any

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# History depth of the telemetry topics when kept KEEP_LAST.
TELEMETRY_DEPTH = 1000


def telemetry_qos(depth: int = TELEMETRY_DEPTH, keep_all: bool = True,
                  reliable: bool = True) -> QoSProfile:
    """Return the telemetry QoS: RELIABLE, VOLATILE, KEEP_ALL (or KEEP_LAST ``depth``).

    Reliable and keep-all so that no sample is lost: a subscriber that lags keeps every
    sample until its history is full, then the publisher's ``publish`` fails and the replay
    offers the sample again later (docs/nodes.md). A reliable publisher also serves
    best-effort (sensor-data) subscribers; history does not affect compatibility.
    ``reliable=False`` gives the best-effort, keep-last profile a subscriber needs to hear
    a best-effort (sensor-data) publisher.
    """
    if not reliable:
        return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
    return QoSProfile(depth=depth,
                      history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


# Anomaly events: reliable, and the last 100 kept for subscribers that join late.
EVENTS_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)

# /diagnostics: reliable, volatile (a periodic state; the next one comes in 1 s).
DIAGNOSTICS_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)

# /clock publisher: reliable, so it matches the best-effort clock subscribers too.
CLOCK_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


def qos_event_callbacks(node: Node, topic: str, publisher: bool = False
                        ) -> PublisherEventCallbacks | SubscriptionEventCallbacks:
    """Return event callbacks that log an incompatible-QoS peer on ``topic`` (once)."""
    warned: set[str] = set()

    def incompatible(event: Any) -> None:
        policy = getattr(event, 'last_policy_kind', '?')
        if str(policy) not in warned:
            warned.add(str(policy))
            node.get_logger().warning(
                f'incompatible QoS with a peer on {topic}: policy {policy} '
                f'(total {event.total_count}); the peer gets no messages')

    if publisher:
        return PublisherEventCallbacks(incompatible_qos=incompatible)
    return SubscriptionEventCallbacks(incompatible_qos=incompatible)
