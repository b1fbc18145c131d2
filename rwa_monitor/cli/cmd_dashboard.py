"""``rwa-monitor dashboard``: a terminal view of ``anomalies`` and ``/diagnostics``.

The ground-tool use case: point it at any running rwa_monitor system (same ROS domain)
and it shows the health of every monitored component and the anomaly log. It discovers
every namespace that publishes ``anomalies`` or diagnostics (``/sat1/anomalies``,
``/sat2/anomalies``, ...; re-checked every ``--discovery-period`` s) and keeps each
spacecraft in its own section: a status named ``"sat1/llr_detector: rw1 friction"``
belongs to ``/sat1``. The anomaly subscriptions are TRANSIENT_LOCAL, so a dashboard that
starts late still receives the events the detectors keep (latched ones are re-published
when a detector restarts). Every status ages: one not refreshed for ``--stale-timeout``
s is shown LOST whatever its last level (a killed node). Discovery stays on this host
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) unless the environment sets it otherwise
(docs/nodes.md: watching another host). The demo draws its live view with these classes.
"""

from __future__ import annotations

import argparse
import collections
import os
import signal
import sys
import time
from typing import Any, TextIO

from rwa_monitor.cli.readable import levels_legend, p_value_text
from rwa_monitor.core import keys
from rwa_monitor.core.coverage import NOT_EXAMINED, UNKNOWN

LEVEL_NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE', 4: 'LOST', 5: 'WAIT'}
STALE = 3
LOST = 4
WAIT = 5     # shown for a STALE status of a window diagnoser filling its first window
ROOT = '/'

_COLOURS = {0: '\x1b[32m', 1: '\x1b[33m', 2: '\x1b[31m', 3: '\x1b[90m', 4: '\x1b[35m',
            5: '\x1b[36m'}
_RESET = '\x1b[0m'


def level_of(status: Any) -> int:
    """Return a DiagnosticStatus level as an int (the message holds a byte)."""
    level = status.level
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


def namespace_of(status_name: str) -> str:
    """Return the namespace of a status named ``"[ns/]node: check"`` (``/`` if none)."""
    node = status_name.split(':', 1)[0].strip().strip('/')
    return '/' + node.rsplit('/', 1)[0] if '/' in node else ROOT


def topic_namespace(topic: str) -> str:
    """Return the namespace of a topic (``/sat1/anomalies`` -> ``/sat1``)."""
    head = topic.rsplit('/', 1)[0]
    return head or ROOT


class Board:
    """What the view shows: latest health per component and anomalies, per namespace.

    ``clock`` gives the wall time used to age statuses (``stale_timeout`` s without a
    refresh: LOST).
    """

    def __init__(self, max_events: int = 200, stale_timeout: float = 5.0,
                 clock: Any = time.monotonic) -> None:
        self.health: dict[tuple[str, str], dict[str, Any]] = {}
        self.events: collections.deque[dict[str, Any]] = collections.deque(maxlen=max_events)
        self.n_events = 0
        self.by_detector: dict[str, int] = {}
        self.by_namespace: dict[str, int] = {}
        self.stale_timeout = stale_timeout
        self.clock = clock
        self._seen: set[tuple] = set()

    def on_diagnostics(self, msg: Any) -> None:
        """Keep the latest status of each (name, hardware_id), with when it arrived."""
        from rwa_monitor.nodes.messages import status_fields
        now = self.clock()
        for status in msg.status:
            self.health[(status.name, status.hardware_id)] = {
                'level': level_of(status), 'message': status.message,
                'fields': status_fields(status), 'received': now,
                'namespace': namespace_of(status.name)}

    def on_anomalies(self, msg: Any, namespace: str = ROOT) -> None:
        """Append each event of an ``anomalies`` message (once, even if re-delivered)."""
        from rwa_monitor.nodes.messages import status_fields
        for status in msg.status:
            fields = status_fields(status)
            key = (namespace, status.name, status.hardware_id,
                   tuple(sorted(fields.items(), key=str)))
            if key in self._seen:
                continue
            self._seen.add(key)
            self.n_events += 1
            detector = str(fields.get('detector', '?'))
            self.by_detector[detector] = self.by_detector.get(detector, 0) + 1
            self.by_namespace[namespace] = self.by_namespace.get(namespace, 0) + 1
            self.events.append({'level': level_of(status), 'name': status.name,
                                'component': status.hardware_id, 'fields': fields,
                                'namespace': namespace})

    def aged(self, item: dict[str, Any]) -> tuple[int, str]:
        """Return (level, message) of a status, LOST if not refreshed in time."""
        age = self.clock() - item.get('received', self.clock())
        if age > self.stale_timeout:
            return LOST, (f'LOST: no status for {age:.0f} s; last '
                          f'{LEVEL_NAMES.get(item["level"], "?")}: {item["message"]}')
        if item['level'] == STALE and keys.WAITING_SAMPLES in item['fields']:
            return WAIT, item['message']     # not examined yet: its first window fills
        return item['level'], item['message']

    def namespaces(self) -> list[str]:
        """Return every namespace seen (statuses or anomalies), sorted."""
        seen = {item.get('namespace', ROOT) for item in self.health.values()}
        return sorted(seen | set(self.by_namespace))


def _paint(text: str, level: int, colour: bool) -> str:
    return f'{_COLOURS.get(level, "")}{text}{_RESET}' if colour else text


def _seconds(value: Any) -> str:
    return f'{value:.1f}' if isinstance(value, (int, float)) else str(value)


def unexamined_note(fields: dict[str, Any]) -> str | None:
    """Return a note for a status whose component was not examined, else None.

    Its ``verdict`` (core/coverage.py ``Coverage.fields``) is ``unknown`` (mostly
    untested) or ``not_examined``: ``'unknown: U of N samples usable'``.
    """
    verdict = fields.get('verdict')
    if verdict not in (UNKNOWN, NOT_EXAMINED):
        return None
    counts = (f'{fields["usable_samples"]} of {fields["samples"]} samples usable'
              if 'usable_samples' in fields and 'samples' in fields else 'no counts')
    return f'{str(verdict).replace("_", " ")}: {counts}'


def render(board: Board, *, title: str = 'rwa_monitor', progress: str | None = None,
           colour: bool = False, max_log: int = 10) -> str:
    """Return the view as text: progress line, then per namespace health and anomalies."""
    lines = [title]
    if progress:
        lines.append(progress)
    if not board.health:
        lines += ['', '(no /diagnostics yet)']
    for namespace in board.namespaces() or [ROOT]:
        lines.append('')
        lines.append(f'== {namespace} ==')
        lines.append(f'{"component":<18} {"node":<16} {"level":<6} {"kind":<9} '
                     f'{"change s":>10}  status')
        items = [(key, item) for key, item in board.health.items()
                 if item.get('namespace', ROOT) == namespace]
        for (name, hardware_id), item in sorted(items, key=lambda kv: (kv[0][1], kv[0][0])):
            fields = item['fields']
            kind = fields.get('kind', fields.get('latched_kind', ''))
            change = fields.get('change_time_s', fields.get('latched_change_time_s', ''))
            node = name.split(':', 1)[0].rsplit('/', 1)[-1] if ':' in name else ''
            level, message = board.aged(item)
            note = unexamined_note(fields)
            if note:
                kind, message = 'unknown', f'{message} [{note}]'
            row = (f'{hardware_id or name:<18} {node:<16} {LEVEL_NAMES.get(level, "?"):<6} '
                   f'{str(kind):<9} {_seconds(change):>10}  {message}')
            lines.append(_paint(row, level, colour))
        lines.append(f'anomalies: {board.by_namespace.get(namespace, 0)}')
        events = [e for e in board.events if e.get('namespace', ROOT) == namespace]
        for event in events[-max_log:]:
            f = event['fields']
            text = (f'  {event["component"]:<10} {str(f.get("detector", "")):<6} '
                    f'{str(f.get("kind", "")):<8} change '
                    f't={_seconds(f.get("change_time_s", "?"))} s  declared '
                    f't={_seconds(f.get("declaration_time_s", "?"))} s'
                    f'  p={p_value_text(f.get("p_value"))}  rev {f.get("revision", 0)}')
            lines.append(_paint(text, event['level'], colour))
    lines += ['', levels_legend()]
    return '\n'.join(lines)


class Screen:
    """Redraw a block of text in place on a terminal; print sparingly otherwise."""

    def __init__(self, out: TextIO | None = None, interval: float = 0.25,
                 plain_interval: float = 10.0) -> None:
        out = sys.stdout if out is None else out
        self.out = out
        self.tty = hasattr(out, 'isatty') and out.isatty() and os.environ.get('TERM') != 'dumb'
        self.interval = interval if self.tty else plain_interval
        self._last = -float('inf')

    def due(self) -> bool:
        """Return True when it is time to draw again."""
        return time.monotonic() - self._last >= self.interval

    def draw(self, text: str) -> None:
        """Draw ``text`` (in place on a terminal)."""
        self._last = time.monotonic()
        if self.tty:
            self.out.write('\x1b[H\x1b[J' + text + '\n')
        else:
            self.out.write(text + '\n\n')
        self.out.flush()


DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'


def make_node(board: Board, discovery_period: float = 2.0, **kwargs: Any) -> Any:
    """Return a node that feeds ``board`` from every ``anomalies`` and diagnostics topic.

    It subscribes ``/anomalies`` and ``/diagnostics`` at once, then every
    ``discovery_period`` s (steady clock) any other DiagnosticArray topic named
    ``.../anomalies`` or ``.../diagnostics`` that appeared (one per spacecraft namespace).
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.clock import Clock
    from rclpy.clock_type import ClockType
    from rclpy.node import Node

    from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS
    node = Node('rwa_monitor_dashboard', **kwargs)
    subscribed: set[str] = set()

    def subscribe(topic: str) -> None:
        if topic in subscribed:
            return
        subscribed.add(topic)
        if topic.endswith('/anomalies'):
            namespace = topic_namespace(topic)
            node.create_subscription(DiagnosticArray, topic,
                                     lambda msg: board.on_anomalies(msg, namespace),
                                     EVENTS_QOS)
        else:
            node.create_subscription(DiagnosticArray, topic, board.on_diagnostics,
                                     DIAGNOSTICS_QOS)

    def discover() -> None:
        for topic, types in node.get_topic_names_and_types():
            if DIAGNOSTICS_TYPE in types and (topic.endswith('/anomalies')
                                              or topic.endswith('/diagnostics')):
                subscribe(topic)

    subscribe('/anomalies')
    subscribe('/diagnostics')
    node.dashboard_discover = discover
    node.create_timer(discovery_period, discover,
                      clock=Clock(clock_type=ClockType.STEADY_TIME))
    return node


def run(args: argparse.Namespace) -> int:
    """Show the dashboard until Ctrl-C or SIGTERM (or for ``--duration`` seconds)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    board = Board(stale_timeout=getattr(args, 'stale_timeout', 5.0))
    node = make_node(board, getattr(args, 'discovery_period', 2.0), context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    screen = Screen(interval=args.interval, plain_interval=args.interval)
    deadline = time.monotonic() + args.duration if args.duration > 0 else float('inf')
    # Ctrl-C and SIGTERM end the loop between executor turns (exit 0, the last view
    # drawn): raised inside rclpy's take, a KeyboardInterrupt can surface as a
    # RuntimeError traceback instead.
    stop = []
    previous = {sig: signal.signal(sig, lambda *_: stop.append(True))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        while context.ok() and time.monotonic() < deadline and not stop:
            executor.spin_once(timeout_sec=0.05)
            if screen.due():
                screen.draw(render(board, title='rwa_monitor dashboard', colour=screen.tty))
        screen.draw(render(board, title='rwa_monitor dashboard', colour=screen.tty))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return 0


def register(subparsers: Any) -> None:
    """Add the ``dashboard`` sub-command."""
    parser = subparsers.add_parser(
        'dashboard', help='terminal view of the anomalies and /diagnostics of a running system',
        description=__doc__.split('\n\n')[1] if __doc__ else None)
    parser.add_argument('--domain-id', type=int,
                        default=int(os.environ.get('ROS_DOMAIN_ID', '0') or 0),
                        help='ROS domain id to join (default: $ROS_DOMAIN_ID or 0)')
    parser.add_argument('--duration', type=float, default=0.0,
                        help='stop after this many seconds (default: until Ctrl-C)')
    parser.add_argument('--interval', type=float, default=1.0,
                        help='seconds between redraws (default: 1.0)')
    parser.add_argument('--stale-timeout', type=float, default=5.0,
                        help='seconds without a status after which a component is shown '
                             'LOST (default: 5.0)')
    parser.add_argument('--discovery-period', type=float, default=2.0,
                        help='seconds between searches for new namespaces (default: 2.0)')
    parser.set_defaults(func=run)
