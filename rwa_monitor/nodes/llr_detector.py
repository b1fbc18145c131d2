"""Node ``llr_detector``: one online LLR friction detector per wheel on ``telemetry/wheels``.

Publishes every declared anomaly on ``anomalies`` (one DiagnosticStatus per event, the
KeyValues of ``AnomalyEvent.fields()``) and each wheel's health on ``/diagnostics``
every ``diagnostic_period`` s of the node clock: OK until an anomaly, then WARN (dry,
viscous) or ERROR (both) with the kind and change time; STALE when telemetry stops; with
the counters of rejected samples. The detector is :class:`rwa_monitor.core.llr.LLRDetector`
with the keywords of :func:`rwa_monitor.core.schema.llr_kwargs`, so the node, the
``detect`` command and the benchmarks share one implementation and one parameter meaning:
each wheel has a runner (core/wheel_runner.py), as in ``detect`` and the fleet.

Bad input (docs/nodes.md): a message whose arrays differ in length is dropped; entries
with an empty or repeated name, or a name that is not a valid wheel id (the rule of
file columns, telemetry/schema.py), are dropped; names outside ``wheels`` (when set) or
beyond ``max_wheels`` are dropped; a stamp equal to (duplicate) or up to
``time_jump`` s before (out of order) the wheel's last one is dropped; a stamp more than
``time_jump`` s before it (a replay loop) restarts that wheel's detector. NaN/Inf values
go to the detector, which skips and counts them. Each case is counted in diagnostics and
logged once; none reaches the detector's statistics. The stamp rules are
:class:`rwa_monitor.core.streams.StampGate` (shared with the other nodes).

Calibration (``calibration_file``, :mod:`rwa_monitor.nodes.calibration`): each wheel is
tested against its calibrated nominal; a change at run time restarts the wheel
detectors, is published on ``anomalies`` as an event of kind ``calibration_changed``
(level OK) and the calibration in force (file, sha256, load time) is the /diagnostics
status ``calibration``; a bad file is refused and the last good calibration stays.

Reliability (docs/nodes.md "Alarms" and "Failures"): declared anomalies are latched
(:mod:`rwa_monitor.nodes.latched`: ``events_file`` journal, ``~/acknowledge``, reloaded
and re-published at start) and survive detector restarts; an exception in one wheel's
detector is caught, logged once, counted, shown as ERROR on that wheel and its detector
restarts, while other wheels go on; a wheel silent for ``wheel_timeout`` s of wall time
is freed.
"""

from __future__ import annotations

import collections
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState

from rwa_monitor.core import keys, streams
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import LLR
from rwa_monitor.core.wheel_runner import WheelRunner
from rwa_monitor.nodes import calibration, common, messages, wheels_input
from rwa_monitor.nodes.common import (declare_parameters, DiagnosticsPublisher, ERROR,
                                      EVENTS_QOS, node_help, OK, qos_event_callbacks,
                                      run_node, telemetry_qos)
from rwa_monitor.nodes.latched import LatchedAlarms

NODE_NAME = 'llr_detector'
MAX_KEPT = 10_000  # events kept in memory for in-process users (demo, tests)
INPUT_ID = 'telemetry/wheels'
ERROR_HOLD_S = 60.0  # a wheel whose detector failed shows ERROR this long (wall time)

# Parameters: core/schema.py LLR (the detector's and the node-only ones).
DETECTOR_PARAMETERS = LLR.names(('all',))
PARAMETERS = LLR.for_node()


class _Wheel:
    """One monitored wheel: its runner, last stamp, counters and health."""

    def __init__(self, runner: WheelRunner, time_jump: float) -> None:
        self.runner = runner
        self.gate = streams.StampGate(time_jump)
        self.sensor = streams.SensorFaultMonitor()
        self.counters = self.gate.counters
        self.samples = 0
        self.events = 0
        self.failures = 0
        self.last_failure: tuple[float, str] | None = None
        self.earlier: dict[str, dict[str, int]] = {'rejected': {}, 'not_tested': {}}
        self.last_event: AnomalyEvent | None = None
        self.health: Any = None

    def restart(self, runner: WheelRunner) -> None:
        """Give the wheel a new runner, keeping the old one's counts in the totals."""
        try:
            facts = self.runner.facts()
            _add(self.earlier['rejected'], facts.rejected)
            _add(self.earlier['not_tested'], facts.not_tested)
        except Exception:  # noqa: BLE001 - a broken runner's counts are lost, not the node
            pass
        self.runner = runner
        self.gate.reset()
        self.last_event = None

    def totals(self) -> tuple[dict[str, int], dict[str, int]]:
        """Return the rejected and the untested samples by reason since the node started."""
        facts = self.runner.facts()
        rejected, untested = dict(self.earlier['rejected']), dict(self.earlier['not_tested'])
        _add(rejected, facts.rejected)
        _add(untested, facts.not_tested)
        return rejected, untested


def _add(into: dict[str, int], counts: Any) -> None:
    for reason, count in counts.items():
        into[reason] = into.get(reason, 0) + int(count)


class LLRDetectorNode(Node):
    """Run one LLR detector per wheel; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node (``kwargs`` go to rclpy's Node: context, cli_args, ...)."""
        super().__init__(NODE_NAME, **kwargs)
        common.refuse_unknown_overrides(self, LLR)
        self.params = declare_parameters(self, PARAMETERS, self._on_parameter,
                                         self._check_detector)
        self._values = self._detector_config()
        self.calibration = calibration.CalibrationInForce(self.params[calibration.NAME])
        self.wheels: dict[str, _Wheel] = {}
        self.input_counters = {'messages': 0, 'length_mismatch': 0,
                               'empty_name': 0, 'duplicate_name': 0, 'invalid_name': 0,
                               'unknown_wheel': 0,
                               'too_many_wheels': 0, 'undecodable': 0,
                               'uncalibrated_wheel': 0, 'detector_failures': 0,
                               'wheels_freed': 0}
        self.events: collections.deque[AnomalyEvent] = collections.deque(maxlen=MAX_KEPT)
        self._decoder = wheels_input.WheelsDecoder()
        self._logged: set[tuple[str, str]] = set()
        self._allowed = common.wheel_names(self.params['wheels'])
        self.diagnostics = DiagnosticsPublisher(
            self, period=self.params['diagnostic_period'],
            stale_timeout=self.params['stale_timeout'])
        self.diagnostics.provide(INPUT_ID, 'input', self._input_health)
        self.diagnostics.provide(calibration.COMPONENT, 'calibration', self.calibration.health)
        self.diagnostics.component(calibration.COMPONENT, 'calibration').stale_timeout = (
            float('inf'))   # a setting, not an input: never stale
        self._anomaly_pub = self.create_publisher(
            DiagnosticArray, 'anomalies', EVENTS_QOS,
            event_callbacks=qos_event_callbacks(self, 'anomalies', True))
        self.alarms = LatchedAlarms(self, self._anomaly_pub, self.diagnostics,
                                    self.params['events_file'])
        self._silence = streams.SilenceTracker(self.params['wheel_timeout'])
        self._sweeper = self.create_timer(1.0, self._free_silent_wheels,
                                          clock=self.diagnostics.steady_clock)
        reliable = self.params['telemetry_reliability'] == 'reliable'
        self.create_subscription(
            JointState, 'telemetry/wheels', self.on_raw_wheels,
            telemetry_qos(reliable=reliable),
            event_callbacks=qos_event_callbacks(self, 'telemetry/wheels'), raw=True)

    # ------------------------------------------------------------------- parameters
    def _detector_config(self, values: Any = None) -> dict[str, Any]:
        values = self.params if values is None else values
        return {name: values[name] for name in DETECTOR_PARAMETERS}

    def _check_detector(self, values: dict[str, Any]) -> None:
        """Build a runner from ``values`` (ValueError naming a parameter if it fails)."""
        WheelRunner('check', self._detector_config(values))
        calibration.check(values)

    def _on_parameter(self, name: str, value: Any) -> None:
        if name in DETECTOR_PARAMETERS:
            self._values = self._detector_config()
            for wheel_id, wheel in self.wheels.items():
                wheel.restart(self._new_runner(wheel_id))
            self.get_logger().info(f'{name} = {value}: every wheel detector restarted '
                                   '(latched anomalies stay)')
        elif name == calibration.NAME:
            self.get_logger().info(self.calibration.set(value))
            for wheel_id, wheel in self.wheels.items():
                wheel.restart(self._new_runner(wheel_id))
            common.publish_calibration_change(self, self._anomaly_pub, self.calibration,
                                              'llr')
        elif name == 'wheels':
            self._allowed = common.wheel_names(self.params['wheels'])

    def _new_runner(self, wheel_id: str) -> WheelRunner:
        return WheelRunner(wheel_id, self._values,
                           nominal=self.calibration.nominal(wheel_id))

    # ---------------------------------------------------------------------- input
    def _log_once(self, reason: str, subject: str, text: str) -> None:
        if wheels_input.first_time(self._logged, reason, subject):
            self.get_logger().warning(f'{text} (further cases are only counted)')

    def _reject(self, reason: str, subject: str, text: str, count: int = 1) -> None:
        self.input_counters[reason] += count
        self._log_once(reason, subject, text)

    def on_raw_wheels(self, buffer: bytes) -> None:
        """Feed one serialised ``telemetry/wheels`` message (the subscription is raw)."""
        fields = self._decoder.decode(buffer)
        if fields is None:
            self.input_counters['messages'] += 1
            self._reject('undecodable', '', 'dropped an undecodable telemetry/wheels message')
            return
        self._process(*fields)

    def on_wheels(self, msg: JointState) -> None:
        """Feed one ``telemetry/wheels`` message to the wheels' detectors."""
        self._process(*wheels_input.fields_of(msg))

    def _process(self, seconds: float, names: Sequence[str], speeds: Sequence[float],
                 efforts: Sequence[float]) -> None:
        self.input_counters['messages'] += 1
        now = self.diagnostics.now()
        self.diagnostics.mark_input(INPUT_ID, 'input', now)
        try:
            seconds, samples = messages.samples_of(seconds, names, speeds, efforts)
        except messages.BadMessage as err:
            self._reject(err.reason, '', f'dropped a telemetry/wheels message: {err}')
            return
        if len(samples) != len(names):
            for reason, count in messages.wheel_name_problems(names).items():
                if count:
                    self._reject(reason, '', f'dropped {count} entries: {reason}', count)
        for wheel_id, speed, friction in samples:
            wheel = self._wheel(wheel_id)
            if wheel is not None:
                wheel.health.last_input = now
                self._silence.heard(wheel_id, now)
                self._feed(wheel_id, wheel, seconds, speed, friction)

    def _wheel(self, wheel_id: str) -> _Wheel | None:
        wheel = self.wheels.get(wheel_id)
        if wheel is not None:
            return wheel
        invalid = wheels_input.name_refusal(wheel_id)
        if invalid is not None:     # logged once whatever the name: names are unbounded
            self._reject(invalid.counter, '', invalid.message)
            return None
        refusal = common.wheel_refusal(wheel_id, self._allowed, len(self.wheels),
                                       self.params['max_wheels'])
        if refusal is None and not self.calibration.covers(wheel_id):
            refusal = ('uncalibrated_wheel', f'{wheel_id}: not in the calibration in force '
                       f'({self.calibration.describe()}): not monitored')
        if refusal is not None:
            self._reject(refusal[0], wheel_id, refusal[1])
            return None
        wheel = self.wheels[wheel_id] = _Wheel(self._new_runner(wheel_id),
                                               self.params['time_jump'])
        wheel.health = self.diagnostics.component(wheel_id, f'{wheel_id} friction')
        self.diagnostics.provide(wheel_id, f'{wheel_id} friction',
                                 lambda: self._wheel_health(wheel))
        self.get_logger().info(f'monitoring wheel {wheel_id!r}')
        return wheel

    def _feed(self, wheel_id: str, wheel: _Wheel, seconds: float, speed: float,
              friction: float) -> None:
        gate = wheel.gate
        gate.time_jump = self.params['time_jump']
        last = gate.last
        verdict = gate.check(seconds)
        if verdict == streams.TIME_JUMP:
            self._log_once(verdict, wheel_id, f'{wheel_id}: time jumped back '
                           f'{last - seconds:.3f} s: detector restarted')
            wheel.restart(self._new_runner(wheel_id))
            gate.check(seconds)
        elif verdict != streams.ACCEPT:
            self._log_once(verdict, wheel_id, f'{wheel_id}: dropped a sample: {verdict} '
                           f'(t={seconds!r} after {last!r})')
            return
        wheel.samples += 1
        try:
            found = wheel.runner.update(seconds, speed, friction)
        except Exception as err:  # noqa: BLE001 - one wheel's failure never stops the node
            self._detector_failed(wheel_id, wheel, err)
            return
        if found:
            self._publish_events(wheel, found)

    def _detector_failed(self, wheel_id: str, wheel: _Wheel, err: Exception) -> None:
        """Count and log (once per wheel) a detector exception; restart that detector."""
        wheel.failures += 1
        self.input_counters['detector_failures'] += 1
        wheel.last_failure = (self.diagnostics.now(), f'{type(err).__name__}: {err}')
        if wheels_input.first_time(self._logged, 'detector_failure', wheel_id):
            self.get_logger().error(
                f'{wheel_id}: detector failed: {type(err).__name__}: {err}; detector '
                'restarted (further failures are only counted)')
        wheel.restart(self._new_runner(wheel_id))

    def _free_silent_wheels(self) -> None:
        """Free the wheels silent for ``wheel_timeout`` s (timer on the steady clock)."""
        self._silence.timeout = self.params['wheel_timeout']
        for wheel_id in self._silence.silent(self.diagnostics.now()):
            self._silence.forget(wheel_id)
            if self.wheels.pop(wheel_id, None) is not None:
                self.diagnostics.remove(wheel_id)
                self.input_counters['wheels_freed'] += 1
                self.get_logger().info(f'wheel {wheel_id!r} silent for more than '
                                       f'{self._silence.timeout:g} s: freed')

    # --------------------------------------------------------------------- output
    def _publish_events(self, wheel: _Wheel, found: list[AnomalyEvent]) -> None:
        self.alarms.record(found)   # journalled (fsynced) before it is published
        out = DiagnosticArray()
        out.header.stamp = messages.to_stamp(found[-1].declared_time)
        out.status = [messages.event_status(e, self.get_name()) for e in found]
        self._anomaly_pub.publish(out)
        for event in found:
            self.get_logger().warning(
                f'{event.component}: {event.kind} anomaly, change at t={event.time:.3f} s '
                f'(declared at t={event.declared_time:.3f} s, p={event.p_value:.3g})')
        wheel.events += len(found)
        wheel.last_event = found[-1]
        self.events.extend(found)

    def _wheel_health(self, wheel: _Wheel) -> tuple[bytes, str, dict[str, Any]]:
        values: dict[str, Any] = {'samples': wheel.samples, 'events': wheel.events}
        values.update(wheel.counters)
        rejected, untested = wheel.totals()
        values.update({f'rejected_{k}': v for k, v in rejected.items()})
        event = wheel.last_event
        if event is None:
            level, message = OK, 'no anomaly'
            values[keys.KIND] = 'none'
        else:
            level = messages.event_level(event.kind)
            message = f'{event.kind} anomaly since t={event.time:.3f} s'
            values.update({keys.KIND: event.kind, keys.CHANGE_TIME: event.time,
                           keys.P_VALUE: event.p_value})
        try:
            values[keys.NOISE_STD] = float(wheel.runner.detector.noise_std)
        except Exception:  # noqa: BLE001 - a health value never stops the node
            pass
        values['detector_failures'] = wheel.failures
        fault = wheel.sensor.update(wheel.samples, rejected.get('out_of_range', 0)
                                    + rejected.get('non_finite', 0))
        if fault is not None:
            level, message = ERROR, f'{fault}; {message}'
            values['sensor_fault'] = True
        values.update(self.calibration.values())
        values.update({f'not_tested_{k}': v for k, v in untested.items()})
        if values.get('not_tested_outside_calibrated_range'):
            message += '; telemetry outside the calibrated speed range (not tested)'
        failure = wheel.last_failure
        if failure is not None and self.diagnostics.now() - failure[0] < ERROR_HOLD_S:
            level, message = ERROR, f'detector failed ({failure[1]}), restarted; {message}'
        return self.alarms.merge(wheel.runner.component, level, message, values)

    def _input_health(self) -> tuple[bytes, str, dict[str, Any]]:
        rejected = sum(v for k, v in self.input_counters.items() if k != 'messages')
        message = (f'{len(self.wheels)} wheels' if not rejected
                   else f'{len(self.wheels)} wheels; {rejected} entries rejected')
        return OK, message, dict(self.input_counters)


def main(args: Sequence[str] | None = None) -> int:
    """Run the LLR detector node (console script ``rwa-monitor-llr``)."""
    return run_node(lambda: LLRDetectorNode(), args, help_text=lambda: node_help(
        'rwa-monitor-llr', __doc__, PARAMETERS))


if __name__ == '__main__':
    raise SystemExit(main())
