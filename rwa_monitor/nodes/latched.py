"""Latched anomalies in a detector node: journal, ``~/acknowledge`` and /diagnostics.

:class:`LatchedAlarms` wraps the ROS-free :class:`rwa_monitor.telemetry.alarms.AlarmStore`
for one node (docs/nodes.md "Alarms"):

- parameter ``events_file`` (read-only; empty = no journal): every event is appended to
  it (JSON Lines, flushed and fsynced per event) and the unacknowledged records are
  reloaded at start, published again on ``anomalies`` (transient local, so a subscriber
  that joins later gets them) and shown on /diagnostics;
- service ``~/acknowledge`` (std_srvs/Trigger): acknowledges every active record of the
  node; the response names how many and which;
- an ``events_file`` the journal opener refuses (a package error, e.g. a file that is not
  a journal) stops the node at start (ConfigError, exit 2, the file untouched); a journal
  that cannot be written makes the status below ERROR, naming the error;
- a status ``"<node>: latched alarms"`` (hardware_id ``alarms``) on /diagnostics, never
  STALE: OK with none, else the highest level of the latched kinds; and
  :meth:`LatchedAlarms.merge`, which raises a component's own status to its latched level.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_srvs.srv import Trigger

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DiagnosticsPublisher, ERROR, LEVEL_NAMES, OK
from rwa_monitor.telemetry.alarms import AlarmStore, event_key

ALARMS_ID = 'alarms'


class LatchedAlarms:
    """Latched anomaly records of one node; see the module docstring."""

    def __init__(self, node: Node, publisher: Any, diagnostics: DiagnosticsPublisher,
                 path: str = '', level_of: Callable[[str], bytes] = messages.event_level,
                 key: Callable[[AnomalyEvent], str] = event_key) -> None:
        self._node = node
        self._pub = publisher
        self._diagnostics = diagnostics
        self._level_of = level_of
        try:
            self.store = AlarmStore(str(path) if path else None, key=key)
            reloaded = self.store.load()
        except RwaMonitorError as err:   # e.g. a file that is not a journal: refused, untouched
            raise ConfigError(f'parameter events_file: {err}') from None
        diagnostics.provide(ALARMS_ID, 'latched alarms', self._health)
        diagnostics.component(ALARMS_ID, 'latched alarms').stale_timeout = float('inf')
        self._service = node.create_service(Trigger, '~/acknowledge', self._on_acknowledge)
        self._error_logged = False
        if reloaded:
            self.publish([a.event for a in reloaded])
            node.get_logger().warning(
                f'{len(reloaded)} unacknowledged anomalies reloaded from {path}: '
                + ', '.join(f'{a.event.component} {a.event.kind}' for a in reloaded))
        self._check_journal()

    def record(self, events: Iterable[AnomalyEvent]) -> None:
        """Latch and journal declared events (call after publishing them)."""
        self.store.declare(list(events))
        self._check_journal()

    def publish(self, events: list[AnomalyEvent]) -> None:
        """Publish ``events`` on ``anomalies`` (one DiagnosticArray)."""
        if not events:
            return
        out = DiagnosticArray()
        out.header.stamp = messages.to_stamp(max(e.declared_time for e in events))
        out.status = [messages.event_status(e, self._node.get_name()) for e in events]
        for status, event in zip(out.status, events):
            status.level = self._level_of(event.kind)
        self._pub.publish(out)

    def merge(self, component: str, level: bytes, message: str,
              values: dict[str, Any]) -> tuple[bytes, str, dict[str, Any]]:
        """Return a component's status raised to its latched records (if any)."""
        summary = self.store.summary(component)
        if summary is None:
            return level, message, values
        text, extra = summary
        latched = max(self._level_of(a.event.kind) for a in self.store.active(component))
        values.update(extra)
        return max(level, latched), f'{message}; {text}', values

    def _health(self) -> tuple[bytes, str, dict[str, Any]]:
        active = self.store.active()
        values: dict[str, Any] = {f'alarms_{k}': v for k, v in self.store.counters.items()}
        values['active'] = len(active)
        journal = ''
        if self.store.last_error:
            values['journal_last_error'] = self.store.last_error
            journal = (f'journal not written ({self.store.last_error}): anomalies latched in '
                       'memory only; ')
        if not active:
            return (ERROR if journal else OK), f'{journal}no latched anomaly', values
        level = max(self._level_of(a.event.kind) for a in active)
        if journal:
            level = ERROR
        for i, alarm in enumerate(active[-20:]):
            e = alarm.event
            values[f'alarm_{i}'] = (f'{e.detector} {e.component} {e.kind} t={e.time:.3f} s'
                                    + (' (cleared)' if alarm.cleared else ''))
        return level, (f'{journal}{len(active)} latched anomalies ({LEVEL_NAMES[level]}), '
                       f'unacknowledged'), values

    def _on_acknowledge(self, request: Trigger.Request, response: Trigger.Response
                        ) -> Trigger.Response:
        done = self.store.acknowledge()
        response.success = True
        response.message = (f'acknowledged {len(done)} anomalies'
                            + (': ' + ', '.join(f'{a.event.component} {a.event.kind}'
                                                for a in done) if done else ''))
        self._node.get_logger().info(response.message)
        self._check_journal()
        return response

    def _check_journal(self) -> None:
        if self.store.last_error and not self._error_logged:
            self._error_logged = True
            self._node.get_logger().error(
                f'events_file: {self.store.last_error}; anomalies stay latched in memory '
                '(further failures are only counted)')

    def destroy(self) -> None:
        """Destroy the service."""
        self._node.destroy_service(self._service)
