"""Wait for the subscribers of a publishing node before its first sample (issue 24, item 6).

A reliable publisher delivers only to the subscriptions matched when it publishes: a
replay that started at once lost the first hundreds of samples of a detector started
beside it, without a word. Measured (docs/nodes.md "Waiting for subscribers"): every
loss came from a detector whose subscription the replay had not matched yet — its
participant was found at the next discovery announcement, 1.3-3.1 s after the replay
started, while the others were matched at once; a subscription the replay had matched
never lost a sample. The replay therefore waits, at every rate, until

- ``telemetry/wheels`` (its first data topic) has at least ``min_subscribers`` matched
  subscriptions, and at least one at rate 0;
- every subscription the ROS graph knows on each of its topics is matched;
- at least one topic has a subscriber, :data:`DISCOVERY_S` have passed since the wait
  began (one discovery announcement period and a margin: a participant that missed the
  first announcements is found by then) — unless ``min_subscribers`` > 0 are matched on
  the first topic: the user said whom to expect — and the counts have not changed for
  :data:`SETTLE_S`;

or until ``subscriber_timeout`` seconds of steady time have passed (0: do not wait). At
rate 0 it never starts without a subscriber on the first topic (it would publish the
file into nothing). Each change of the counts while waiting and the counts it started
with are logged and shown on /diagnostics; a subscription that matches after the first
sample is logged as a warning (it missed what was published before) and counted.
"""

from __future__ import annotations

from typing import Any, Sequence

from rclpy.node import Node

# s of steady time: the participant-discovery announcement period of the middleware
# (3 s after an initial burst of 0.5 s) plus a margin for the endpoint exchange under load.
DISCOVERY_S = 4.5
SETTLE_S = 2.0   # s of steady time without a change in the matched counts
LATE_CHECK_S = 0.5   # s of steady time between checks for subscribers matching late


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
        self._next_late_check = 0.0
        self.started_with: dict[str, int] = {}
        self.matched: dict[str, int] = {}
        self.late = 0
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
        waited = now - self._since
        counts = self.counts()
        if counts != self._counts:
            self._counts, self._changed = counts, now
            self._node.get_logger().info(f'after {waited:.1f} s, matched subscribers: '
                                         f'{_text(counts)}')
        main = counts[self._main.topic_name][0]
        if needs_one and main < 1:
            if timeout and waited >= timeout and not self._warned:
                self._warned = True
                self._node.get_logger().warning(
                    f'no subscriber on {self._main.topic_name} after {waited:.1f} s; rate 0 '
                    'waits for one (start a detector)')
            return False
        complete = (main >= min_subscribers and any(m for m, _ in counts.values())
                    and all(m >= known for m, known in counts.values())
                    and (waited >= DISCOVERY_S or 0 < min_subscribers <= main)
                    and now - self._changed >= SETTLE_S)
        timed_out = not timeout or waited >= timeout
        if not (complete or timed_out):
            return False
        self.waited_s = waited
        self.started_with = {topic: m for topic, (m, _) in counts.items()}
        self.matched = dict(self.started_with)
        self._next_late_check = now + LATE_CHECK_S
        text = _text(counts)
        if complete:
            self._node.get_logger().info(f'starting after {waited:.1f} s with the matched '
                                         f'subscribers: {text}')
        elif timeout:
            self._node.get_logger().warning(
                f'starting after the subscriber_timeout of {timeout:g} s with the matched '
                f'subscribers: {text} (samples published before a subscriber matches are '
                'lost to it)')
        return True

    def check_late(self, now: float, published: int) -> None:
        """Warn (and count) when a subscription matched after publishing began."""
        if now < self._next_late_check:
            return
        self._next_late_check = now + LATE_CHECK_S
        for pub in self._publishers:
            matched = pub.get_subscription_count()
            before = self.matched.get(pub.topic_name, 0)
            if matched > before:
                self.late += matched - before
                self._node.get_logger().warning(
                    f'{matched - before} subscriber(s) on {pub.topic_name} matched after '
                    f'{published} rows were published: they missed those rows (start the '
                    'subscribers first; min_subscribers waits for them)')
            self.matched[pub.topic_name] = matched

    def values(self) -> dict[str, Any]:
        """Return the /diagnostics KeyValues: the counts publishing started with."""
        out: dict[str, Any] = {'subscriber_wait_s': round(self.waited_s, 3),
                               'late_subscribers': self.late}
        for topic, matched in self.started_with.items():
            out[f'subscribers_at_start{topic.replace("/", "_")}'] = matched
        return out


def _text(counts: dict[str, tuple[int, int]]) -> str:
    return ', '.join(f'{topic} {m}' for topic, (m, _) in counts.items())
