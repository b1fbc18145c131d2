"""Node ``vsadc_detector``: gyro drift/bias health per axis from gyro and star tracker.

Subscribes ``telemetry/gyro`` (sensor_msgs/Imu, angular_velocity), ``telemetry/star_tracker``
(geometry_msgs/QuaternionStamped) and ``telemetry/reference_rate`` (Vector3Stamped; when
it has sent nothing for ``reference_timeout`` s of data time, the ``reference_rate``
parameter is used). Gyro and star-tracker samples are paired by stamp (within
``pair_tolerance`` s) and fed in stamp order to :class:`rwa_monitor.core.vsadc.VsadcDetector`
with the keywords of :func:`rwa_monitor.core.schema.vsadc_kwargs` (one
implementation and one parameter meaning for node, ``detect`` and benchmarks).

Publishes an event on ``anomalies`` at every state change of an axis (kind ``drift``,
``bias``, or ``healthy`` for a recovery) and each axis's health on ``/diagnostics``:
OK healthy (or still learning its nominal class), WARN bias, ERROR drift (a growing
error); STALE when paired input stops. A gyro sample with no star-tracker match (the star
tracker is past its stamp, or ``max_lag`` gyro samples wait) is fed without a quaternion:
the detector holds the labels and counts it, so a star tracker that stops makes the
axes STALE, never "drift" (docs/vsadc.md). A stamp more than ``time_jump`` s back restarts
the detector (replay loop).
"""

from __future__ import annotations

from collections import deque
import math
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rclpy.node import Node
from sensor_msgs.msg import Imu

from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import VSADC, vsadc_kwargs
from rwa_monitor.core.vsadc import STATE_NAMES, VsadcDetector
from rwa_monitor.nodes import common, messages
from rwa_monitor.nodes.common import (declare_parameters, DiagnosticsPublisher, ERROR,
                                      EVENTS_QOS, OK, qos_event_callbacks, run_node,
                                      telemetry_qos, WARN)

NODE_NAME = 'vsadc_detector'
INPUT_ID = 'gyro_star_tracker'
HEALTH_LEVEL = {0: OK, 1: ERROR, 2: WARN}

# Parameters: core/schema.py VSADC (the detector's, reference_rate and node-only ones).
DETECTOR_PARAMETERS = tuple(n for n in VSADC.names(('all',)) if n != 'reference_rate')
PARAMETERS = VSADC.for_node()


class VsadcDetectorNode(Node):
    """Run VSADC on the gyro axes; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node (``kwargs`` go to rclpy's Node: context, cli_args, ...)."""
        super().__init__(NODE_NAME, **kwargs)
        common.refuse_unknown_overrides(self, VSADC)
        self.params = declare_parameters(self, PARAMETERS, self._on_parameter,
                                         self._check_detector)
        self.reference = list(self.params['reference_rate'])
        self.counters = {'gyro_messages': 0, 'star_tracker_messages': 0,
                         'reference_messages': 0, 'unpaired_gyro': 0,
                         'unpaired_star_tracker': 0, 'reference_from_parameter': 0,
                         'time_jump_reset': 0}
        self.events: list[AnomalyEvent] = []
        self.samples = 0
        self._gyro: deque = deque()
        self._star: deque = deque()
        self._refs: deque = deque(maxlen=64)
        self._last_fed = -math.inf
        self.detector = VsadcDetector(**vsadc_kwargs(self._detector_config()))
        self.diagnostics = DiagnosticsPublisher(
            self, period=self.params['diagnostic_period'],
            stale_timeout=self.params['stale_timeout'])
        self.diagnostics.provide(INPUT_ID, 'input', self._input_health)
        self._axis_checks()
        self._anomaly_pub = self.create_publisher(
            DiagnosticArray, 'anomalies', EVENTS_QOS,
            event_callbacks=qos_event_callbacks(self, 'anomalies', True))
        subs = [self.create_subscription(msg_type, topic, callback, telemetry_qos(),
                                         event_callbacks=qos_event_callbacks(self, topic))
                for msg_type, topic, callback in (
                    (Imu, 'telemetry/gyro', self.on_gyro),
                    (QuaternionStamped, 'telemetry/star_tracker', self.on_star_tracker),
                    (Vector3Stamped, 'telemetry/reference_rate', self.on_reference))]
        self._reference_sub = subs[2]

    # ------------------------------------------------------------------- parameters
    def _detector_config(self, values: Any = None) -> dict[str, Any]:
        values = self.params if values is None else values
        return {name: values[name] for name in DETECTOR_PARAMETERS}

    def _check_detector(self, values: dict[str, Any]) -> None:
        VsadcDetector(**vsadc_kwargs(self._detector_config(values)))

    def _on_parameter(self, name: str, value: Any) -> None:
        if name == 'reference_rate':
            self.reference = list(value)
        elif name in DETECTOR_PARAMETERS:
            self.detector = VsadcDetector(**vsadc_kwargs(self._detector_config()))
            self._axis_checks()
            self.get_logger().info(f'{name} = {value}: detector restarted')

    def _axis_checks(self) -> None:
        for hardware_id in list(self.diagnostics.components):
            if hardware_id != INPUT_ID:
                self.diagnostics.remove(hardware_id)
        for i, axis in enumerate(self.detector.axes):
            self.diagnostics.provide(f'gyro_{axis}', f'gyro_{axis} health',
                                     lambda i=i: self._axis_health(i))

    # ---------------------------------------------------------------------- input
    def on_gyro(self, msg: Imu) -> None:
        """Queue one gyro sample and feed every sample that can be paired now."""
        self.counters['gyro_messages'] += 1
        v = msg.angular_velocity
        t = messages.to_seconds(msg.header.stamp)
        if t < self._last_fed - self.params['time_jump']:
            self.counters['time_jump_reset'] += 1
            self.get_logger().warning(f'gyro time jumped back to t={t:.3f} s: restart')
            self.detector.reset()
            self._gyro.clear()
            self._star.clear()
            self._refs.clear()
            self._last_fed = -math.inf
        self._gyro.append((t, (v.x, v.y, v.z)))
        self._drain()

    def on_star_tracker(self, msg: QuaternionStamped) -> None:
        """Queue one star-tracker quaternion and feed what can be paired now."""
        self.counters['star_tracker_messages'] += 1
        q = msg.quaternion
        self._star.append((messages.to_seconds(msg.header.stamp), (q.x, q.y, q.z, q.w)))
        if len(self._star) > 4 * self.params['max_lag']:
            self._star.popleft()
            self.counters['unpaired_star_tracker'] += 1
        self._drain()

    def on_reference(self, msg: Vector3Stamped) -> None:
        """Keep the recent guidance reference rates."""
        self.counters['reference_messages'] += 1
        v = msg.vector
        self._refs.append((messages.to_seconds(msg.header.stamp), (v.x, v.y, v.z)))
        self._drain()

    def _drain(self) -> None:
        """Feed the queued gyro samples whose star-tracker partner is known (or lost)."""
        tol = self.params['pair_tolerance']
        while self._gyro:
            t, rate = self._gyro[0]
            while self._star and self._star[0][0] < t - tol:
                self._star.popleft()                     # a quaternion no gyro matches
                self.counters['unpaired_star_tracker'] += 1
            lagging = len(self._gyro) > self.params['max_lag']
            paired = bool(self._star) and abs(self._star[0][0] - t) <= tol
            if not (paired or self._star or lagging):
                return                                   # wait for the star tracker
            ref = self._reference_for(t, lagging)
            if ref is None:
                return                                   # wait for the reference
            q = self._star.popleft()[1] if paired else None
            self._gyro.popleft()
            if q is None:
                self.counters['unpaired_gyro'] += 1
            self._feed(t, rate, q, ref)

    def _reference_for(self, t: float, lagging: bool) -> Sequence[float] | None:
        tol, timeout = self.params['pair_tolerance'], self.params['reference_timeout']
        best = None
        for stamp, ref in self._refs:
            if stamp <= t + tol:
                best = (stamp, ref)
        if not self._refs:
            if not lagging and self._reference_sub.get_publisher_count() > 0:
                return None                              # a publisher exists: wait for it
        elif t - timeout <= self._refs[-1][0] < t - tol and not lagging:
            return None                                  # its sample is on the way
        if best is None or best[0] < t - timeout:
            self.counters['reference_from_parameter'] += 1
            return self.reference
        return best[1]

    def _feed(self, t: float, rate: Sequence[float], q: Sequence[float] | None,
              ref: Sequence[float]) -> None:
        self._last_fed = max(self._last_fed, t)
        before = self.detector.accepted
        found = self.detector.update(t, rate, q, ref, self.samples)
        self.samples += 1
        self.diagnostics.mark_input(INPUT_ID, 'input')
        if self.detector.accepted > before:
            for axis in self.detector.axes:
                self.diagnostics.mark_input(f'gyro_{axis}', f'gyro_{axis} health')
        if found:
            self._publish_events(found)

    # --------------------------------------------------------------------- output
    def _publish_events(self, found: list[AnomalyEvent]) -> None:
        out = DiagnosticArray()
        out.header.stamp = messages.to_stamp(found[-1].declared_time)
        statuses = []
        for event in found:
            status = messages.event_status(event, self.get_name())
            if event.kind == 'healthy':
                status.level = OK
                status.message = f'recovered, at t={event.time:.3f} s'
            statuses.append(status)
            self.get_logger().warning(
                f'{event.component}: {event.kind} (was {event.details[keys.PREVIOUS_KIND]}), '
                f'change at t={event.time:.3f} s, declared at t={event.declared_time:.3f} s')
        out.status = statuses
        self._anomaly_pub.publish(out)
        self.events.extend(found)

    def _axis_health(self, i: int) -> tuple[bytes, str, dict[str, Any]]:
        channel = self.detector.channels[i]
        state = channel.state
        values: dict[str, Any] = {
            keys.STATE: STATE_NAMES[state], keys.READY: channel.ready,
            'samples': channel.samples, keys.DISTANCE: channel.distance,
            keys.DISTANCE_SIGMA: channel.sigma, keys.SIGMA_LIM1: channel.sigma_lim1,
            keys.SIGMA_LIM2: channel.sigma_lim2}
        component = f'gyro_{self.detector.axes[i]}'
        last = next((e for e in reversed(self.events) if e.component == component), None)
        if last is not None:
            values[keys.CHANGE_TIME] = last.time
        if not channel.ready:
            return OK, 'learning the nominal class', values
        message = STATE_NAMES[state] if last is None else \
            f'{STATE_NAMES[state]} since t={last.time:.3f} s'
        return HEALTH_LEVEL[state], message, values

    def _input_health(self) -> tuple[bytes, str, dict[str, Any]]:
        values = dict(self.counters)
        values.update(self.detector.counters)
        return OK, f'{self.samples} gyro samples, {self.detector.held} held', values


NODE_CLASS = VsadcDetectorNode


def main(args: Sequence[str] | None = None) -> int:
    """Run the VSADC gyro node (console script ``rwa-monitor-vsadc``)."""
    return run_node(lambda: VsadcDetectorNode(), args)
