"""Launch-free ROS 2 test harness: one Context, domain id and executor per test.

Usage::

    from ros_harness import RosWorld

    def test_something():
        with RosWorld() as world:
            node = world.add(MyNode(context=world.context))   # or world.node(MyNode, ...)
            sub_node = world.node(rclpy.node.Node, 'collector')
            ...
            world.wait_until(lambda: len(received) >= 3, timeout_sec=10.0, what='3 msgs')

Every ``RosWorld`` initialises its own ``rclpy.Context`` on a domain id that no other
``RosWorld`` on this machine holds at the same time (a lock file per id under the temp
directory, so parallel test runs of several checkouts never hear each other), sets
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, spins with bounded loops only (every wait has a
deadline) and tears down executor -> nodes -> ``try_shutdown(context=...)``.
"""

from __future__ import annotations

import fcntl
import os
import random
import tempfile
import time
from typing import Any, Callable

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

DOMAIN_IDS = range(1, 201)
_LOCK_DIR = os.path.join(tempfile.gettempdir(), 'rwa_monitor_ros_domains')


class DomainLease:
    """An exclusive claim on a ROS domain id on this machine, held until ``release()``."""

    def __init__(self, rng: random.Random | None = None) -> None:
        os.makedirs(_LOCK_DIR, exist_ok=True)
        rng = rng or random.SystemRandom()
        candidates = list(DOMAIN_IDS)
        rng.shuffle(candidates)
        for domain_id in candidates:
            handle = open(os.path.join(_LOCK_DIR, f'{domain_id}.lock'), 'w')
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                continue
            self.domain_id = domain_id
            self._handle = handle
            return
        raise RuntimeError(f'no free ROS domain id in {DOMAIN_IDS}')

    def release(self) -> None:
        """Give the domain id back."""
        if self._handle is not None:
            fcntl.flock(self._handle, fcntl.LOCK_UN)
            self._handle.close()
            self._handle = None


class RosWorld:
    """A private ROS 2 graph for one test: context, domain id, executor and nodes.

    ``executor`` is ``'single'`` (SingleThreadedExecutor, the default) or ``'events'``
    (rclpy.experimental.EventsExecutor).
    """

    def __init__(self, executor: str = 'single') -> None:
        self._executor_kind = executor
        self.context: Context | None = None
        self.executor: Executor | None = None
        self.nodes: list[Node] = []
        self.domain_id: int | None = None
        self._lease: DomainLease | None = None

    def __enter__(self) -> 'RosWorld':
        self._lease = DomainLease()
        self.domain_id = self._lease.domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        if self._executor_kind == 'events':
            from rclpy.experimental import EventsExecutor
            self.executor = EventsExecutor(context=self.context)
        else:
            self.executor = SingleThreadedExecutor(context=self.context)
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def env(self) -> dict[str, str]:
        """Return an environment for child processes that join this world's domain."""
        env = dict(os.environ)
        env['ROS_DOMAIN_ID'] = str(self.domain_id)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        return env

    def add(self, node: Node) -> Node:
        """Add a node (created with ``context=world.context``) to the executor; return it."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def node(self, factory: Callable[..., Node], *args: Any, **kwargs: Any) -> Node:
        """Create ``factory(*args, context=world.context, **kwargs)`` and add it."""
        return self.add(factory(*args, context=self.context, **kwargs))

    def remove(self, node: Node) -> None:
        """Remove a node from the executor and destroy it."""
        self.executor.remove_node(node)
        self.nodes.remove(node)
        node.destroy_node()

    def spin_once(self, timeout_sec: float = 0.05) -> None:
        """Execute at most one ready callback, waiting at most ``timeout_sec``."""
        self.executor.spin_once(timeout_sec=timeout_sec)

    def spin_until(self, predicate: Callable[[], bool], timeout_sec: float = 10.0) -> bool:
        """Spin until ``predicate()`` is true or the deadline passes; return the predicate."""
        deadline = time.monotonic() + timeout_sec
        while not predicate():
            if time.monotonic() >= deadline:
                return bool(predicate())
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def wait_until(self, predicate: Callable[[], bool], timeout_sec: float = 10.0,
                   what: str = 'condition') -> None:
        """Spin until ``predicate()`` is true; fail the test with ``what`` on the deadline."""
        if not self.spin_until(predicate, timeout_sec):
            raise AssertionError(f'timed out after {timeout_sec} s waiting for {what}')

    def spin_for(self, duration_sec: float) -> None:
        """Spin for a fixed wall-clock time (to check that something does NOT happen)."""
        deadline = time.monotonic() + duration_sec
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))

    def wait_for_subscribers(self, publisher: Any, count: int = 1,
                             timeout_sec: float = 10.0) -> None:
        """Spin until ``publisher`` has at least ``count`` matched subscriptions."""
        self.wait_until(lambda: publisher.get_subscription_count() >= count, timeout_sec,
                        f'{count} subscriber(s) on {publisher.topic_name}')

    def wait_for_publishers(self, subscription: Any, count: int = 1,
                            timeout_sec: float = 10.0) -> None:
        """Spin until ``subscription`` has at least ``count`` matched publishers."""
        self.wait_until(lambda: subscription.get_publisher_count() >= count, timeout_sec,
                        f'{count} publisher(s) on {subscription.topic_name}')

    def close(self) -> None:
        """Tear down: executor, then nodes, then the context; release the domain id."""
        try:
            if self.executor is not None:
                self.executor.shutdown(timeout_sec=1.0)
            for node in reversed(self.nodes):
                node.destroy_node()
            self.nodes.clear()
        finally:
            if self.context is not None:
                rclpy.try_shutdown(context=self.context)
            if self._lease is not None:
                self._lease.release()
                self._lease = None


class Collector:
    """Keep every message received on a topic (for assertions)."""

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: Any = 100) -> None:
        self.messages: list[Any] = []
        self.subscription = node.create_subscription(
            msg_type, topic, lambda msg: self.messages.append(msg), qos)

    def __len__(self) -> int:
        return len(self.messages)
