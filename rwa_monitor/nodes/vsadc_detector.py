"""Node ``vsadc_detector``: gyro drift/bias health per axis from gyro and star tracker.

Subscribes ``telemetry/gyro`` (sensor_msgs/Imu, angular_velocity), ``telemetry/star_tracker``
(geometry_msgs/QuaternionStamped) and ``telemetry/reference_rate`` (Vector3Stamped; when
it has sent nothing for ``reference_timeout`` s of data time, the ``reference_rate``
parameter is used). Gyro and star-tracker samples are paired by stamp (within
``pair_tolerance`` s) and fed in stamp order to the gyro runner
(:class:`rwa_monitor.core.gyro_runner.GyroRunner`: ``feature`` residual, the
gyro-minus-star-tracker diagnosis with the ``calibration_file`` thresholds; paper: VSADC
as in Algorithm 1); one implementation and one parameter meaning for node, ``detect``,
the fleet and benchmarks. A gyro rate at or above ``saturation_rad_s`` is held and the
axis reported WARN "saturated", never diagnosed.

Publishes an event on ``anomalies`` at every state change of an axis (kind ``drift``,
``bias``, or ``healthy`` for a recovery) and each axis's health on ``/diagnostics``:
OK healthy (or still learning its nominal class), WARN bias, ERROR drift (a growing
error); STALE when paired input stops. A gyro sample with no star-tracker match (the star
tracker is past its stamp, or ``max_lag`` gyro samples wait) is fed without a quaternion:
the detector holds the labels and counts it, so a star tracker that stops makes the
axes STALE, never "drift" (docs/vsadc.md). A stamp more than ``time_jump`` s back restarts
the detector (replay loop). The pairing is :class:`rwa_monitor.core.streams.StampPairer`
(bounded buffers, shared with the other nodes).

Reliability (docs/nodes.md): anomalies (drift, bias) are latched
(:mod:`rwa_monitor.nodes.latched`: ``events_file``, ``~/acknowledge``, re-published at
start; a recovery clears a record, the acknowledgement ends it); an exception in the
detector is caught, logged once, counted, shown as ERROR and the detector restarts; an
axis that has not been examined (learning, or no usable sample for ``stale_timeout``
s) is STALE, never OK. Events kept in memory are bounded (``MAX_KEPT``).
"""

from __future__ import annotations

from collections import deque
from typing import Any, Callable, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu

from rwa_monitor.core import keys, streams
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_runner import GyroRunner
from rwa_monitor.core.schema import VSADC
from rwa_monitor.core.vsadc import STATE_NAMES
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import calibration, common, messages
from rwa_monitor.nodes.common import (declare_parameters, DiagnosticsPublisher, ERROR,
                                      EVENTS_QOS, node_help, OK, qos_event_callbacks,
                                      run_node, STALE, telemetry_qos, WARN)
from rwa_monitor.nodes.latched import LatchedAlarms
from rwa_monitor.telemetry.calibration_file import load_gyro_calibration

NODE_NAME = 'vsadc_detector'
INPUT_ID = 'gyro_star_tracker'
HEALTH_LEVEL = {0: OK, 1: ERROR, 2: WARN}
MAX_KEPT = 10_000  # events kept in memory for in-process users (demo, tests)
ERROR_HOLD_S = 60.0  # the input status shows ERROR this long after a detector failure


# Parameters: core/schema.py VSADC (the detector's, reference_rate and node-only ones).
DETECTOR_PARAMETERS = tuple(n for n in VSADC.names(('all',)) if n != 'reference_rate')
PARAMETERS = VSADC.for_node()


def kind_level(kind: str) -> bytes:
    """Return the /diagnostics level of a VSADC event kind (drift ERROR, bias WARN)."""
    return HEALTH_LEVEL.get(STATE_NAMES.index(kind), WARN) if kind in STATE_NAMES else WARN


class VsadcDetectorNode(Node):
    """Run VSADC on the gyro axes; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node (``kwargs`` go to rclpy's Node: context, cli_args, ...)."""
        super().__init__(NODE_NAME, **kwargs)
        common.refuse_unknown_overrides(self, VSADC)
        self.params = declare_parameters(self, PARAMETERS, self._on_parameter,
                                         self._check_detector)
        self.reference = list(self.params['reference_rate'])
        self.calibration = calibration.CalibrationInForce(self.params[calibration.NAME])
        self.counters = {'gyro_messages': 0, 'star_tracker_messages': 0,
                         'reference_messages': 0, 'unpaired_gyro': 0,
                         'unpaired_star_tracker': 0, 'reference_from_parameter': 0,
                         'time_jump_reset': 0, 'detector_failures': 0,
                         'undecodable': 0}
        self.events: deque[AnomalyEvent] = deque(maxlen=MAX_KEPT)
        self._last_event: dict[str, AnomalyEvent] = {}
        self.samples = 0
        self._pairer = streams.StampPairer(self.params['pair_tolerance'],
                                           self.params['max_lag'], self.params['time_jump'])
        self._refs: deque = deque(maxlen=64)
        self._failure: tuple[float, str] | None = None
        try:
            self.runner = self._make_runner(self._detector_config())
        except ValueError as err:
            raise ConfigError(f'parameter {err}') from None
        self.diagnostics = DiagnosticsPublisher(
            self, period=self.params['diagnostic_period'],
            stale_timeout=self.params['stale_timeout'])
        self.diagnostics.provide(INPUT_ID, 'input', self._input_health)
        self._axis_checks()
        self._anomaly_pub = self.create_publisher(
            DiagnosticArray, 'anomalies', EVENTS_QOS,
            event_callbacks=qos_event_callbacks(self, 'anomalies', True))
        self.alarms = LatchedAlarms(self, self._anomaly_pub, self.diagnostics,
                                    self.params['events_file'], kind_level)
        subs = [self.create_subscription(msg_type, topic, self._raw(msg_type, callback),
                                         telemetry_qos(), raw=True,
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

    @property
    def detector(self) -> Any:
        """Return the gyro detector of the runner in force (its channels and counters)."""
        return self.runner.detector

    @staticmethod
    def _make_runner(config: dict[str, Any]) -> GyroRunner:
        calibration = (load_gyro_calibration(config['calibration_file'])
                       if config['calibration_file'] else None)
        return GyroRunner(config, calibration)

    def _check_detector(self, values: dict[str, Any]) -> None:
        self._make_runner(self._detector_config(values))
        calibration.check(values)

    def _on_parameter(self, name: str, value: Any) -> None:
        if name in ('pair_tolerance', 'time_jump'):
            self._pairer.tolerance = self.params['pair_tolerance']
            self._pairer.time_jump = self.params['time_jump']
        if name == calibration.NAME:
            self.get_logger().info(self.calibration.set(value))
            common.publish_calibration_change(self, self._anomaly_pub, self.calibration,
                                              'vsadc')
        if name == 'reference_rate':
            self.reference = list(value)
        elif name in DETECTOR_PARAMETERS:
            self.runner = self._make_runner(self._detector_config())
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
    def _raw(self, msg_type: Any, on_message: Callable[[Any], None]
             ) -> Callable[[bytes], None]:
        """Return the raw-bytes callback of one input topic.

        Decision (issue 17): the subscriptions are raw and decode the bytes by hand
        (:func:`messages.decode_stamped`), as llr_detector does for the wheels. Building
        the generated Python message cost more than the detector itself (an Imu, with its
        three covariance arrays, over 100 us on this machine) and made this node the
        slowest reader, holding the largest backlog (docs/nodes.md "VSADC input").
        Bytes the decoder refuses go through rclpy's deserialisation; bytes neither can
        read are counted as ``undecodable``.
        """
        count = messages.STAMPED_SIZES[msg_type.__name__]
        handle = {Imu: self._gyro_sample, QuaternionStamped: self._star_sample,
                  Vector3Stamped: self._reference_sample}[msg_type]
        counter = {Imu: 'gyro_messages', QuaternionStamped: 'star_tracker_messages',
                   Vector3Stamped: 'reference_messages'}[msg_type]

        def on_bytes(buffer: bytes) -> None:
            try:
                t, values = messages.decode_stamped(buffer, count)
            except ValueError:
                try:
                    msg = deserialize_message(buffer, msg_type)
                except Exception:  # noqa: BLE001 - undecodable input is counted, not fatal
                    self.counters[counter] += 1
                    self.counters['undecodable'] += 1
                    return
                on_message(msg)
                return
            if msg_type is Imu:
                values = values[messages.IMU_ANGULAR_VELOCITY]
            handle(t, values)
        return on_bytes

    def on_gyro(self, msg: Imu) -> None:
        """Queue one gyro sample and feed every sample that can be paired now."""
        v = msg.angular_velocity
        self._gyro_sample(messages.to_seconds(msg.header.stamp), (v.x, v.y, v.z))

    def _gyro_sample(self, t: float, rate: Sequence[float]) -> None:
        self.counters['gyro_messages'] += 1
        if self._pairer.push_gyro(t, tuple(rate)):
            self.counters['time_jump_reset'] += 1
            self.get_logger().warning(f'gyro time jumped back to t={t:.3f} s: restart')
            self.runner = self._make_runner(self._detector_config())
            for _ in range(len(self._refs)):        # keep the new pass's reference rates
                stamp, ref = self._refs.popleft()
                if stamp <= t + self.params['time_jump']:
                    self._refs.append((stamp, ref))
        self._drain()

    def on_star_tracker(self, msg: QuaternionStamped) -> None:
        """Queue one star-tracker quaternion and feed what can be paired now."""
        q = msg.quaternion
        self._star_sample(messages.to_seconds(msg.header.stamp), (q.x, q.y, q.z, q.w))

    def _star_sample(self, t: float, q: Sequence[float]) -> None:
        self.counters['star_tracker_messages'] += 1
        self._pairer.push_star(t, tuple(q))
        self._drain()

    def on_reference(self, msg: Vector3Stamped) -> None:
        """Keep the recent guidance reference rates."""
        v = msg.vector
        self._reference_sample(messages.to_seconds(msg.header.stamp), (v.x, v.y, v.z))

    def _reference_sample(self, t: float, xyz: Sequence[float]) -> None:
        self.counters['reference_messages'] += 1
        self._refs.append((t, tuple(xyz)))
        self._drain()

    def _drain(self) -> None:
        """Feed the queued gyro samples whose star-tracker partner is known (or lost)."""
        for t, rate, q, ref in self._pairer.drain(self._reference_for):
            self._feed(t, rate, q, ref)
        self.counters['unpaired_gyro'] = self._pairer.counters['unpaired_gyro']
        self.counters['unpaired_star_tracker'] = \
            self._pairer.counters['unpaired_star_tracker']

    def _reference_for(self, t: float, lagging: bool) -> Sequence[float] | None:
        tol, timeout = self.params['pair_tolerance'], self.params['reference_timeout']
        best = next(((stamp, ref) for stamp, ref in reversed(self._refs)
                     if stamp <= t + tol), None)   # the last one in arrival order
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
        detector = self.detector
        before = [ch.samples for ch in detector.channels]
        try:
            found = self.runner.update(t, rate, q, ref)
        except Exception as err:  # noqa: BLE001 - a detector failure never stops the node
            self._detector_failed(err)
            return
        finally:
            self.samples += 1
        now = self.diagnostics.now()
        self.diagnostics.mark_input(INPUT_ID, 'input', now)
        for axis, ch, n in zip(detector.axes, detector.channels, before):
            if ch.samples > n:
                self.diagnostics.mark_input(f'gyro_{axis}', f'gyro_{axis} health', now)
        if found:
            self._publish_events(found)

    def _detector_failed(self, err: Exception) -> None:
        """Count and log (once) a detector exception; restart the detector."""
        self.counters['detector_failures'] += 1
        self._failure = (self.diagnostics.now(), f'{type(err).__name__}: {err}')
        if self.counters['detector_failures'] == 1:
            self.get_logger().error(f'detector failed: {self._failure[1]}; detector '
                                    'restarted (further failures are only counted)')
        self.runner = self._make_runner(self._detector_config())
        self._axis_checks()

    # --------------------------------------------------------------------- output
    def _publish_events(self, found: list[AnomalyEvent]) -> None:
        self.alarms.record(found)   # journalled (fsynced) before it is published
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
        for event in found:
            self._last_event[event.component] = event

    def _axis_health(self, i: int) -> tuple[bytes, str, dict[str, Any]]:
        channel = self.detector.channels[i]
        state = channel.state
        values: dict[str, Any] = {
            keys.STATE: STATE_NAMES[state], keys.READY: channel.ready,
            'samples': channel.samples, keys.DISTANCE: channel.distance,
            keys.DISTANCE_SIGMA: channel.sigma, keys.SIGMA_LIM1: channel.sigma_lim1,
            keys.SIGMA_LIM2: channel.sigma_lim2}
        component = f'gyro_{self.detector.axes[i]}'
        last = self._last_event.get(component)
        if last is not None:
            values[keys.CHANGE_TIME] = last.time
        if getattr(self.detector, 'saturated_now', {}).get(self.detector.axes[i]):
            return WARN, 'gyro saturated: samples held, not diagnosed', values
        if not channel.ready:
            level, message = STALE, (f'unknown: not examined yet, learning the nominal '
                                     f'class ({channel.samples} samples)')
        else:
            level = HEALTH_LEVEL[state]
            message = STATE_NAMES[state] if last is None else \
                f'{STATE_NAMES[state]} since t={last.time:.3f} s'
        return self.alarms.merge(component, level, message, values)

    def _input_health(self) -> tuple[bytes, str, dict[str, Any]]:
        values = dict(self.counters)
        values.update(self.detector.counters)
        gyro, star = self._pairer.waiting
        values.update(waiting_gyro=gyro, waiting_star_tracker=star)
        values.update(self.calibration.values())
        message = f'{self.samples} gyro samples, {self.detector.counters["held"]} held'
        if self._failure is not None and self.diagnostics.now() - self._failure[0] < \
                ERROR_HOLD_S:
            return ERROR, f'detector failed ({self._failure[1]}), restarted; {message}', values
        return OK, message, values


NODE_CLASS = VsadcDetectorNode


def main(args: Sequence[str] | None = None) -> int:
    """Run the VSADC gyro node (console script ``rwa-monitor-vsadc``)."""
    return run_node(lambda: VsadcDetectorNode(), args, help_text=lambda: node_help(
        'rwa-monitor-vsadc', __doc__, PARAMETERS))
