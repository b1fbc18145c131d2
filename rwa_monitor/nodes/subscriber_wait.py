"""Wait for the subscribers of a publishing node before its first sample (issue 24, item 6).

A reliable publisher delivers only to the subscriptions matched when it publishes: on a
loaded machine discovery takes seconds, and a replay that started at once lost the first
hundreds of samples of a detector started beside it, without a word. The replay therefore
waits, at every rate, until

- ``telemetry/wheels`` (its first data topic) has at least ``min_subscribers`` matched
  subscriptions, and at least one at rate 0;
- every subscription the ROS graph knows on each of its topics is matched (a detector
  whose node is discovered but whose reader is not matched yet is waited for);
- at least one topic has a subscriber and these counts have not changed for
  :data:`SETTLE_S` (several detectors started together are discovered one after the
  other);

or until ``subscriber_timeout`` seconds of steady time have passed (0: do not wait). The
counts are the publisher's side of the matching: a reader that has not matched the
writer yet can still miss the first samples (measured in docs/nodes.md). At
rate 0 it never starts without a subscriber on the first topic (it would publish the
file into nothing). The counts it started with are logged and shown on /diagnostics.
"""

from __future__ import annotations

from typing import Any, Sequence

from rclpy.node import Node

SETTLE_S = 2.0   # s of steady time without a change in the matched counts


class SubscriberWait:
    """Decide when a node may start publishing; see the module docstring."""

    def __init__(self, node: Node, publishers: Sequence[Any], main: Any) -> None:
        self._node = node
        self._publishers = list(publishers)
        self._main = main
        self._since: float | None = None      # first call (steady s)
        self._counts: dict[str, tuple[int, int]] = {}
        self._changed = 0.0
        self._warned = False
        self.started_with: dict[str, int] = {}
        self.waited_s = 0.0

    def counts(self) -> dict[str, tuple[int, int]]:
        """Return topic -> (matched subscriptions, subscriptions known in the graph)."""
        return {pub.topic_name: (pub.get_subscription_count(),
                                 self._node.count_subscribers(pub.topic_name))
                for pub in self._publishers}

    def ready(self, now: float, min_subscribers: int, timeout: float,
              needs_one: bool) -> bool:
        """Return True when publishing may start (logs the counts once it may)."""
        if self._since is None:
            self._since = self._changed = now
        counts = self.counts()
        if counts != self._counts:
            self._counts, self._changed = counts, now
        main = counts[self._main.topic_name][0]
        waited = now - self._since
        if needs_one and main < 1:
            if timeout and waited >= timeout and not self._warned:
                self._warned = True
                self._node.get_logger().warning(
                    f'no subscriber on {self._main.topic_name} after {waited:.1f} s; rate 0 '
                    'waits for one (start a detector)')
            return False
        complete = (main >= min_subscribers and any(m for m, _ in counts.values())
                    and all(m >= known for m, known in counts.values())
                    and now - self._changed >= SETTLE_S)
        timed_out = not timeout or waited >= timeout
        if not (complete or timed_out):
            return False
        self.waited_s = waited
        self.started_with = {topic: m for topic, (m, _) in counts.items()}
        text = ', '.join(f'{topic} {m}' for topic, m in self.started_with.items())
        if complete:
            self._node.get_logger().info(f'starting after {waited:.1f} s with the matched '
                                         f'subscribers: {text}')
        elif timeout:
            self._node.get_logger().warning(
                f'starting after the subscriber_timeout of {timeout:g} s with the matched '
                f'subscribers: {text} (samples published before a subscriber matches are '
                'lost to it)')
        return True

    def values(self) -> dict[str, Any]:
        """Return the /diagnostics KeyValues: the counts publishing started with."""
        out: dict[str, Any] = {'subscriber_wait_s': round(self.waited_s, 3)}
        for topic, matched in self.started_with.items():
            out[f'subscribers_at_start{topic.replace("/", "_")}'] = matched
        return out
