"""Node ``telemetry_replay``: publish a telemetry file or recording as ROS topics.

Topics (DESIGN.md): ``telemetry/wheels`` (JointState), ``telemetry/gyro`` (Imu),
``telemetry/star_tracker`` (QuaternionStamped), ``telemetry/reference_rate``
(Vector3Stamped) for the channels the file has, every message stamped with the telemetry
time; a recording's streams keep their own stamps and rates (parameter ``topics`` names
the recording's topics), and so do the containers of a file of space packets (parameters
``xtce_file`` and ``telemetry_map_file``); ``/clock`` (the telemetry time) for the
sim-time detectors; progress on ``/diagnostics``. Pacing uses the steady clock, never the
sim time it publishes.

``rate`` is the time factor (1.0 real time). At every rate the replay first waits for
its subscribers (:mod:`rwa_monitor.nodes.subscriber_wait`: ``min_subscribers`` on
``telemetry/wheels``, every subscriber the graph knows matched, the discovery time and
counts steady for 2 s, or ``subscriber_timeout``); a subscriber matching later is logged.
``rate`` 0 publishes as fast as the subscribers take it, without loss (at least one
wheels subscriber), ``burst`` rows per executor turn; see docs/nodes.md for why no
message is lost. ``/clock`` goes out at most every ``CLOCK_PERIOD`` s of steady time. A
loop restarts at ``start_offset`` with the file's own stamps, so subscribers see the time
jump backwards.
"""

from __future__ import annotations

import bisect
from typing import Any, Sequence

from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
import numpy as np
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.core.schema import REPLAY
from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.nodes import common, messages
from rwa_monitor.nodes.common import (CLOCK_QOS, declare_parameters, DiagnosticsPublisher,
                                      OK, qos_event_callbacks, run_node,
                                      telemetry_qos)
from rwa_monitor.nodes.subscriber_wait import SubscriberWait
from rwa_monitor.telemetry import read_telemetry, Telemetry

NODE_NAME = 'telemetry_replay'

# Parameters: core/schema.py REPLAY (``file`` is required and has no default).
PARAMETERS = REPLAY.for_node()

RCLError = rclpy_implementation.RCLError
_TICK = 0.005  # s of steady time between publishing turns at rate > 0
_MAX_ROWS_PER_TICK = 2000
_BACK_OFF = 0.05  # s of steady time without publishing after a subscriber refused a sample
# /clock at most this often (s of steady time), and with the last row: each /clock message
# costs every sim-time node a callback (docs/nodes.md "Where the time goes").
CLOCK_PERIOD = 0.01
ACK_TIMEOUT = 5.0  # s each topic waits, after the last row, for its subscribers' acknowledgements


class TelemetryReplay(Node):
    """Publish a telemetry file; see the module docstring."""

    def __init__(self, *, telemetry: Telemetry | None = None, **kwargs: Any) -> None:
        """Create the node; ``telemetry`` replaces the ``file`` parameter (in-process use)."""
        super().__init__(NODE_NAME, **kwargs)
        common.refuse_unknown_overrides(self, REPLAY)
        self.params = declare_parameters(self, PARAMETERS, self._on_parameter)
        if telemetry is None:
            if not self.params['file']:
                raise ConfigError('parameter file: a telemetry file is required '
                                  '(-p file:=PATH)')
            try:
                telemetry = read_telemetry(
                    self.params['file'], self.params['topics'],
                    xtce=self.params['xtce_file'] or None,
                    telemetry_map=self.params['telemetry_map_file'] or None)
            except RwaMonitorError as err:
                raise ConfigError(f'parameter file: {err}') from None
        if len(telemetry) == 0:
            raise ConfigError('parameter file: the telemetry has no samples')
        self.telemetry = telemetry
        self._time = np.asarray(telemetry.time, dtype=float)
        self._first = bisect.bisect_left(self._time.tolist(),
                                         self._time[0] + self.params['start_offset'])
        if self._first >= len(self._time):
            raise ConfigError(f'parameter start_offset: {self.params["start_offset"]} s is '
                              f'past the end of the file ({self._time[-1] - self._time[0]} s)')
        self._rows = _Rows(telemetry)
        frame = self.params['frame_id']
        self._imu = messages.imu_codec(frame)
        self._quaternion = messages.quaternion_codec(frame)
        self._vector3 = messages.vector3_codec(frame)
        self.next_row = self._first
        self.published = 0
        self.loops = 0
        self.done = False
        self.exit_code = 0
        self.back_pressure = 0
        self._burst_cap = 1_000_000
        self._resume_at: float | None = None
        self._pending: list[tuple[Any, Any]] = []
        self._started = False
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._anchor: tuple[float, float] | None = None
        self._next_progress = 0.1

        qos = telemetry_qos()
        self._wheels_pub = self._publisher(JointState, 'telemetry/wheels', qos, telemetry.wheels)
        self._gyro_pub = self._publisher(Imu, 'telemetry/gyro', qos, telemetry.gyro)
        self._star_pub = self._publisher(QuaternionStamped, 'telemetry/star_tracker', qos,
                                         telemetry.attitude)
        self._ref_pub = self._publisher(Vector3Stamped, 'telemetry/reference_rate', qos,
                                        telemetry.reference_rate)
        self._clock_pub = self.create_publisher(ClockMsg, '/clock', CLOCK_QOS)
        self._last_clock = -1.0
        self._data_pubs = [p for p in (self._wheels_pub, self._gyro_pub, self._star_pub,
                                       self._ref_pub) if p is not None]
        self._main_pub = self._data_pubs[0] if self._data_pubs else self._clock_pub
        self.subscribers = SubscriberWait(self, self._data_pubs or [self._clock_pub],
                                          self._main_pub)
        self.diagnostics = DiagnosticsPublisher(self)
        self.diagnostics.mark_input('replay', 'replay')
        self.diagnostics.provide('replay', 'replay', self._health)
        self._timer = self.create_timer(self._period(), self._tick, clock=self._steady)
        self.get_logger().info(
            f'replaying {telemetry.source or "telemetry"}: {len(self._time) - self._first} '
            f'rows, channels {", ".join(self._channels())}, rate {self.params["rate"]}')

    # ------------------------------------------------------------------ set-up helpers
    def _publisher(self, msg_type: Any, topic: str, qos: Any, channel: Any) -> Any:
        if channel is None or (isinstance(channel, dict) and not channel):
            return None
        return self.create_publisher(msg_type, topic, qos,
                                     event_callbacks=qos_event_callbacks(self, topic, True))

    def _channels(self) -> list[str]:
        pubs = {'wheels': self._wheels_pub, 'gyro': self._gyro_pub,
                'star_tracker': self._star_pub, 'reference_rate': self._ref_pub}
        return [name for name, pub in pubs.items() if pub is not None]

    def _period(self) -> float:
        """Return the turn period: 0 (every executor turn) at rate 0 once started."""
        return 0.0 if self.params['rate'] == 0.0 and self._started else _TICK

    def _restart_timer(self) -> None:
        self.destroy_timer(self._timer)
        self._timer = self.create_timer(self._period(), self._tick, clock=self._steady)

    def _on_parameter(self, name: str, value: Any) -> None:
        if name == 'rate':
            self._anchor = None
            self._restart_timer()

    # ----------------------------------------------------------------------- publishing
    @property
    def progress(self) -> float:
        """Return the fraction of the current pass already published (0..1)."""
        total = len(self._time) - self._first
        return (self.next_row - self._first) / total

    def _ready_to_start(self) -> bool:
        return self.subscribers.ready(self._steady_s(), self.params['min_subscribers'],
                                      self.params['subscriber_timeout'],
                                      self.params['rate'] == 0.0)

    def _tick(self) -> None:
        try:
            self._turn()
        except Exception:  # noqa: BLE001 - only when the context is already gone
            if self.context.ok():
                raise
            # SIGINT/SIGTERM shut the context down in the middle of a publish: the replay
            # ends with it (run_nodes stops the executor); nothing to log into a dead context.

    def _turn(self) -> None:
        if self.done:
            return
        if not self._started:
            if not self._ready_to_start():
                return
            self._started = True
            self._restart_timer()
        if self._resume_at is not None:
            if self._steady_s() < self._resume_at:
                return
            self._resume_at = None
        if self._pending and not self._flush_pending():
            return
        if self.params['rate'] == 0.0:
            end = min(self.next_row + min(self.params['burst'], self._burst_cap),
                      len(self._time))
        else:
            end = self._due_row()
        if end > self.next_row:
            self._publish_rows(self.next_row, end)
        if self.next_row >= len(self._time) and not self._pending:
            self._end_of_file()

    def _due_row(self) -> int:
        """Return one past the last row whose time has come at the current rate."""
        now = self._steady.now().nanoseconds * 1e-9
        if self._anchor is None:
            self._anchor = (now, self._time[self.next_row])
        t_due = self._anchor[1] + (now - self._anchor[0]) * self.params['rate']
        due = int(np.searchsorted(self._time, t_due, side='right'))
        return min(due, self.next_row + _MAX_ROWS_PER_TICK)

    def _row_messages(self, i: int) -> list[tuple[Any, Any]]:
        """Return (publisher, serialised message) of every channel of row ``i``."""
        t = float(self._time[i])
        rows = self._rows
        has = rows.has
        out = []
        if self._wheels_pub is not None and has('wheels', i):
            out.append((self._wheels_pub, rows.wheels(i, t)))
        if self._gyro_pub is not None and has('gyro', i):
            out.append((self._gyro_pub, self._imu.encode(t, rows.gyro[i].tolist())))
        if self._star_pub is not None and has('star_tracker', i):
            out.append((self._star_pub, self._quaternion.encode(t, rows.attitude[i].tolist())))
        if self._ref_pub is not None and has('reference_rate', i):
            out.append((self._ref_pub, self._vector3.encode(t, rows.reference[i].tolist())))
        return out

    def _flush_pending(self) -> bool:
        """Publish what a full subscriber refused before; return True when all went out.

        Telemetry topics keep all samples (common.telemetry_qos): when a subscriber lags so
        far that the history is full, publish fails after the middleware's blocking time,
        and the message is kept here and offered again on the next turn (back-pressure:
        nothing is dropped).
        """
        while self._pending:
            pub, msg = self._pending[0]
            try:
                pub.publish(msg)
            except RCLError:
                if not self.context.ok():   # shut down by a signal: not back-pressure
                    return False
                self._back_off()
                return False
            self._pending.pop(0)
        return True

    def _steady_s(self) -> float:
        return self._steady.now().nanoseconds * 1e-9

    def _back_off(self) -> None:
        """Pause after a refused sample, and publish one row per turn from now on.

        A subscriber's history is full. The failed ``publish`` already blocked for the
        middleware's blocking time; pausing another ``_BACK_OFF`` s lets a subscriber in
        this process (same executor) drain its backlog. A backlog means bursts outrun the
        subscriber, so the burst drops to 1. Nothing is lost; the refused sample is
        offered again (docs/nodes.md).
        """
        self.back_pressure += 1
        self._resume_at = self._steady_s() + _BACK_OFF
        if self._burst_cap > 1:
            self._burst_cap = 1
            self.get_logger().warning('a subscriber is lagging (its history is full): '
                                      'publishing one row per turn from now on')

    def _publish_rows(self, start: int, end: int) -> None:
        for i in range(start, end):
            self._pending = self._row_messages(i)
            self.next_row = i + 1
            self.published += 1
            if not self._flush_pending():
                break
        last = self.next_row - 1
        now = self._steady_s()
        self.subscribers.check_late(now, self.published)
        if now - self._last_clock >= CLOCK_PERIOD or self.next_row >= len(self._time):
            self._clock_pub.publish(messages.clock(float(self._time[last])))
            self._last_clock = now
        if self.progress >= self._next_progress:
            self.get_logger().info(f'replay {100 * self.progress:.0f}% '
                                   f'(t={self._time[last]:.1f} s, loop {self.loops})')
            self._next_progress = np.floor(self.progress * 10 + 1) / 10
        self.diagnostics.mark_input('replay', 'replay', now)

    def _end_of_file(self) -> None:
        if self.params['loop']:
            self.loops += 1
            self.next_row = self._first
            self._anchor = None
            self._next_progress = 0.1
            self.get_logger().info(f'replay loop {self.loops}: back to '
                                   f't={self._time[self._first]:.1f} s')
            return
        self.done = True
        self.destroy_timer(self._timer)
        self.get_logger().info(f'replay done: {self.published} rows published')
        if self.params['exit_when_done']:
            unacked = [pub.topic_name for pub in self._data_pubs if not pub.wait_for_all_acked(
                rclpy.duration.Duration(seconds=ACK_TIMEOUT))]
            if unacked:
                self.get_logger().warning(
                    f'a subscriber of {", ".join(unacked)} had not acknowledged every row '
                    f'{ACK_TIMEOUT:g} s after the last: the rows it had not received are '
                    'lost to it')
            rclpy.try_shutdown(context=self.context)

    def _health(self) -> tuple[bytes, str, dict[str, Any]]:
        state = 'done' if self.done else ('replaying' if self._started else 'waiting')
        if self.done:   # not an input that stopped: never STALE
            self.diagnostics.mark_input('replay', 'replay')
        return OK, state, {'progress_percent': round(100 * self.progress, 2),
                           'rows_published': self.published, 'loops': self.loops,
                           'back_pressure_waits': self.back_pressure,
                           **self.subscribers.values()}


class _Rows:
    """Row access to the telemetry arrays (each row converted when it is published).

    A multi-rate recording has rows where a stream has no sample: :meth:`has` says which.
    """

    def __init__(self, tele: Telemetry) -> None:
        self._present = {k: m.tolist() for k, m in tele.present.items()}
        self.names = list(tele.wheels)
        nan = np.full(len(tele), np.nan)
        self.speed = np.column_stack([w.speed for w in tele.wheels.values()]) \
            if tele.wheels else None
        self.friction = np.column_stack(
            [nan if w.friction is None else w.friction for w in tele.wheels.values()]
        ) if tele.wheels else None
        self.gyro = tele.gyro
        self.attitude = tele.attitude
        self.reference = tele.reference_rate
        self._codec = messages.JointStateCodec(self.names)

    def has(self, stream: str, i: int) -> bool:
        """Return True if ``stream`` has a sample on row ``i``."""
        mask = self._present.get(stream)
        return mask is None or mask[i]

    def wheels(self, i: int, t: float) -> bytes:
        """Return row ``i`` as a serialised JointState (``publish`` takes the bytes)."""
        return self._codec.encode(t, self.speed[i].tolist(), self.friction[i].tolist())


def main(args: Sequence[str] | None = None) -> int:
    """Run the replay node (console script ``rwa-monitor-replay``)."""
    return run_node(lambda: TelemetryReplay(), args)


if __name__ == '__main__':
    raise SystemExit(main())
