"""``rwa-monitor dashboard``: a terminal view of ``anomalies`` and ``/diagnostics``.

The ground-tool use case: point it at any running rwa_monitor system (same ROS domain)
and it shows the health of every monitored component and the anomaly log. The anomaly
subscription is TRANSIENT_LOCAL, so a dashboard that starts late still receives the
recent events the detectors keep. The demo draws its live view with the same classes.
"""

from __future__ import annotations

import argparse
import collections
import os
import signal
import sys
import time
from typing import Any, TextIO

LEVEL_NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
_COLOURS = {0: '\x1b[32m', 1: '\x1b[33m', 2: '\x1b[31m', 3: '\x1b[90m'}
_RESET = '\x1b[0m'


def level_of(status: Any) -> int:
    """Return a DiagnosticStatus level as an int (the message holds a byte)."""
    level = status.level
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


class Board:
    """What the view shows: latest health per component, and the anomaly log."""

    def __init__(self, max_events: int = 200) -> None:
        self.health: dict[tuple[str, str], dict[str, Any]] = {}
        self.events: collections.deque[dict[str, Any]] = collections.deque(maxlen=max_events)
        self.n_events = 0
        self.by_detector: dict[str, int] = {}
        self._seen: set[tuple] = set()

    def on_diagnostics(self, msg: Any) -> None:
        """Keep the latest status of each (name, hardware_id)."""
        from rwa_monitor.nodes.messages import status_fields
        for status in msg.status:
            self.health[(status.name, status.hardware_id)] = {
                'level': level_of(status), 'message': status.message,
                'fields': status_fields(status)}

    def on_anomalies(self, msg: Any) -> None:
        """Append each event of an ``anomalies`` message (once, even if re-delivered)."""
        from rwa_monitor.nodes.messages import status_fields
        for status in msg.status:
            fields = status_fields(status)
            key = (status.name, status.hardware_id, tuple(sorted(fields.items(), key=str)))
            if key in self._seen:
                continue
            self._seen.add(key)
            self.n_events += 1
            detector = str(fields.get('detector', '?'))
            self.by_detector[detector] = self.by_detector.get(detector, 0) + 1
            self.events.append({'level': level_of(status), 'name': status.name,
                                'component': status.hardware_id, 'fields': fields})


def _paint(text: str, level: int, colour: bool) -> str:
    return f'{_COLOURS.get(level, "")}{text}{_RESET}' if colour else text


def _seconds(value: Any) -> str:
    return f'{value:.1f}' if isinstance(value, (int, float)) else str(value)


def _number(value: Any) -> float:
    return float(value) if isinstance(value, (int, float)) else float('nan')


def render(board: Board, *, title: str = 'rwa_monitor', progress: str | None = None,
           colour: bool = False, max_log: int = 10) -> str:
    """Return the view as text: optional progress line, health table, anomaly log."""
    lines = [title]
    if progress:
        lines.append(progress)
    lines.append('')
    lines.append(f'{"component":<18} {"node":<16} {"level":<6} {"kind":<9} {"change s":>10}'
                 '  status')
    for (name, hardware_id), item in sorted(board.health.items(),
                                            key=lambda kv: (kv[0][1], kv[0][0])):
        fields = item['fields']
        kind = fields.get('kind', '')
        change = fields.get('change_time_s', '')
        node = name.split(':', 1)[0] if ':' in name else ''
        row = (f'{hardware_id or name:<18} {node:<16} {LEVEL_NAMES.get(item["level"], "?"):<6} '
               f'{str(kind):<9} {_seconds(change):>10}  {item["message"]}')
        lines.append(_paint(row, item['level'], colour))
    if not board.health:
        lines.append('(no /diagnostics yet)')
    lines.append('')
    lines.append(f'anomalies: {board.n_events}')
    for event in list(board.events)[-max_log:]:
        f = event['fields']
        text = (f'  {event["component"]:<10} {str(f.get("detector", "")):<6} '
                f'{str(f.get("kind", "")):<8} change t={_seconds(f.get("change_time_s", "?"))}'
                f' s  declared t={_seconds(f.get("declaration_time_s", "?"))} s'
                f'  p={_number(f.get("p_value")):.3g}  rev {f.get("revision", 0)}')
        lines.append(_paint(text, event['level'], colour))
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


def make_node(board: Board, **kwargs: Any) -> Any:
    """Return a node that feeds ``board`` from ``anomalies`` and ``/diagnostics``."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node

    from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS
    node = Node('rwa_monitor_dashboard', **kwargs)
    node.create_subscription(DiagnosticArray, 'anomalies', board.on_anomalies, EVENTS_QOS)
    node.create_subscription(DiagnosticArray, '/diagnostics', board.on_diagnostics,
                             DIAGNOSTICS_QOS)
    return node


def run(args: argparse.Namespace) -> int:
    """Show the dashboard until Ctrl-C (or for ``--duration`` seconds)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    board = Board()
    node = make_node(board, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    screen = Screen(interval=args.interval, plain_interval=args.interval)
    deadline = time.monotonic() + args.duration if args.duration > 0 else float('inf')
    # Ctrl-C ends the loop between executor turns: raised inside rclpy's take it can
    # surface as a RuntimeError traceback instead of KeyboardInterrupt.
    stop = []
    previous = signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    try:
        while context.ok() and time.monotonic() < deadline and not stop:
            executor.spin_once(timeout_sec=0.05)
            if screen.due():
                screen.draw(render(board, title='rwa_monitor dashboard', colour=screen.tty))
        screen.draw(render(board, title='rwa_monitor dashboard', colour=screen.tty))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        signal.signal(signal.SIGINT, previous)
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
    parser.set_defaults(func=run)
