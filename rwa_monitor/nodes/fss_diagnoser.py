"""Node ``fss_diagnoser``: the FSS window diagnosis of every wheel on ``telemetry/wheels``.

Each wheel keeps a :class:`rwa_monitor.core.fss.pipeline.SlidingWindow` of the last
``window_length`` samples; every ``window_period`` samples (once the window is full) a
copy of it goes to one worker thread, which runs the four stages
(:func:`rwa_monitor.core.fss.pipeline.diagnose`, the same code as ``rwa-monitor
diagnose``). The subscription callback only appends samples, so telemetry is never
dropped while a diagnosis runs; results are published from a timer of the node.
Memory: per wheel the window (3 x window_length floats) and at most one copy in flight;
a window that falls due while the wheel's previous one is still running is skipped and
counted (``skipped_busy``).

Outputs: each anomaly that a diagnosis flags and the previous one did not is published
on ``anomalies`` (AnomalyEvent, detector ``fss``, kind ``dry``/``viscous``/``fss1``/
``fss2``), built by :func:`rwa_monitor.core.fss.events.window_events` as ``rwa-monitor
diagnose`` builds it: ``time``/``index`` = the onset of the change when the window holds
one (else the window's first sample), the declaration = the window's last sample, with
the window bounds and the extracted base dry and viscous friction; each wheel's
health on ``/diagnostics`` (OK, or WARN listing the anomalies of the last window, STALE
when telemetry stops), with the counters of bad input. Bad input: as the llr_detector
node for messages; per wheel, a stamp not after the last one is dropped and counted,
NaN/Inf samples are kept in the window (the stages skip them) and counted, and gaps in
the stamps are counted (the stages count in samples).

Reliability (docs/nodes.md): flagged anomalies are latched (:mod:`rwa_monitor.nodes.latched`:
``events_file``, ``~/acknowledge``, re-published at start); a failed diagnosis or an
exception in one wheel's input handling is caught, logged once, counted and shown as
ERROR on that wheel (its window restarts), other wheels go on; a wheel silent for
``wheel_timeout`` s of wall time is freed; events kept in memory are bounded.
"""

from __future__ import annotations

import collections
import concurrent.futures
import queue
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState

from rwa_monitor.core import keys, streams
from rwa_monitor.core.calibrate import diagnose_fss
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.fss.events import window_events
from rwa_monitor.core.fss.pipeline import diagnose, FssConfig, SlidingWindow
from rwa_monitor.core.schema import FSS, fss_config
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import calibration, common, messages, wheels_input
from rwa_monitor.nodes.common import (declare_parameters, DiagnosticsPublisher, ERROR,
                                      EVENTS_QOS, node_help, OK, qos_event_callbacks,
                                      run_node, STALE, telemetry_qos, WARN)
from rwa_monitor.nodes.latched import LatchedAlarms
from rwa_monitor.telemetry.alarms import kind_key
from rwa_monitor.telemetry.fss_model import load_model

NODE_NAME = 'fss_diagnoser'
INPUT_ID = 'telemetry/wheels'
MAX_KEPT = 10_000  # events kept in memory for in-process users (demo, tests)
ERROR_HOLD_S = 60.0  # a wheel whose diagnosis failed shows ERROR this long (wall time)

# Parameters: core/schema.py FSS (the diagnoser's and the node-only ones).
CONFIG_NAMES = FSS.names(('all',))
PARAMETERS = FSS.for_node()


class _Wheel:
    """One monitored wheel: window, stream index, last diagnosis and counters."""

    def __init__(self, length: int, period: int) -> None:
        self.window = SlidingWindow(length=length, period=period)
        self.samples = 0
        self.diagnoses = 0
        self.skipped_busy = 0
        self.failures = 0
        self.last_failure: tuple[float, str] | None = None
        self.busy = False
        self.flags: dict[str, bool] = {}
        self.result: dict | None = None
        self.window_bounds: tuple[float, float] | None = None
        self.health: Any = None


class FssDiagnoserNode(Node):
    """Diagnose each wheel's sliding window in a worker thread; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node (``kwargs`` go to rclpy's Node: context, cli_args, ...)."""
        super().__init__(NODE_NAME, **kwargs)
        common.refuse_unknown_overrides(self, FSS)
        self.params = declare_parameters(self, PARAMETERS, self._on_parameter,
                                         self._check_config)
        self._config = self._make_config(self.params)
        self.calibration = calibration.CalibrationInForce(self.params[calibration.NAME])
        try:
            self._model = load_model(self.params['model'] or None)
        except (OSError, ValueError) as err:
            raise ConfigError(f'parameter model: {err}') from None
        self.wheels: dict[str, _Wheel] = {}
        self.events: collections.deque[AnomalyEvent] = collections.deque(maxlen=MAX_KEPT)
        self.input_counters = {'messages': 0, 'length_mismatch': 0, 'empty_name': 0,
                               'duplicate_name': 0, 'invalid_name': 0, 'unknown_wheel': 0,
                               'too_many_wheels': 0, 'non_increasing_time': 0,
                               'diagnosis_failed': 0, 'undecodable': 0, 'wheel_failures': 0,
                               'wheels_freed': 0}
        self._logged: set[tuple[str, str]] = set()
        self._allowed = common.wheel_names(self.params['wheels'])
        self._worker = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix='fss_diagnoser')
        self._done: queue.Queue = queue.Queue()
        self.diagnostics = DiagnosticsPublisher(
            self, period=self.params['diagnostic_period'],
            stale_timeout=self.params['stale_timeout'])
        self.diagnostics.provide(INPUT_ID, 'input', self._input_health)
        self._anomaly_pub = self.create_publisher(
            DiagnosticArray, 'anomalies', EVENTS_QOS,
            event_callbacks=qos_event_callbacks(self, 'anomalies', True))
        self.alarms = LatchedAlarms(self, self._anomaly_pub, self.diagnostics,
                                    self.params['events_file'], key=kind_key)
        self._silence = streams.SilenceTracker(self.params['wheel_timeout'])
        self._sweeper = self.create_timer(1.0, self._free_silent_wheels,
                                          clock=self.diagnostics.steady_clock)
        self._decoder = wheels_input.WheelsDecoder()
        self.create_subscription(
            JointState, 'telemetry/wheels', self.on_raw_wheels, telemetry_qos(), raw=True,
            event_callbacks=qos_event_callbacks(self, 'telemetry/wheels'))
        self._result_timer = self.create_timer(
            0.05, self.publish_results, clock=Clock(clock_type=ClockType.STEADY_TIME))

    # ------------------------------------------------------------------- parameters
    @staticmethod
    def _make_config(values: Any) -> FssConfig:
        return fss_config(values)

    def _check_config(self, values: dict[str, Any]) -> None:
        self._make_config(values)
        calibration.check(values)

    def _on_parameter(self, name: str, value: Any) -> None:
        if name in CONFIG_NAMES:
            self._config = self._make_config(self.params)
        elif name == calibration.NAME:
            self.get_logger().info(self.calibration.set(value))
            common.publish_calibration_change(self, self._anomaly_pub, self.calibration,
                                              'fss')
        elif name == 'wheels':
            self._allowed = common.wheel_names(self.params['wheels'])
        elif name == 'window_period':
            for wheel in self.wheels.values():
                wheel.window.period = int(value)

    # ---------------------------------------------------------------------- input
    def _count(self, reason: str, subject: str, text: str, count: int = 1) -> None:
        self.input_counters[reason] += count
        if wheels_input.first_time(self._logged, reason, subject):
            self.get_logger().warning(f'{text} (further cases are only counted)')

    def on_raw_wheels(self, buffer: bytes) -> None:
        """Append one serialised ``telemetry/wheels`` message (the subscription is raw)."""
        fields = self._decoder.decode(buffer)
        if fields is None:
            self.input_counters['messages'] += 1
            self._count('undecodable', '', 'dropped an undecodable telemetry/wheels message')
            return
        self._process(*fields)

    def on_wheels(self, msg: JointState) -> None:
        """Append one ``telemetry/wheels`` message to the wheels' windows."""
        self._process(*wheels_input.fields_of(msg))

    def _process(self, seconds: float, names: Sequence[str], speeds: Sequence[float],
                 efforts: Sequence[float]) -> None:
        self.input_counters['messages'] += 1
        now = self.diagnostics.now()
        self.diagnostics.mark_input(INPUT_ID, 'input', now)
        try:
            seconds, samples = messages.samples_of(seconds, names, speeds, efforts)
        except messages.BadMessage as err:
            self._count(err.reason, '', f'dropped a telemetry/wheels message: {err}')
            return
        if len(samples) != len(names):
            for reason, count in messages.wheel_name_problems(names).items():
                if count:
                    self._count(reason, '', f'dropped {count} entries: {reason}', count)
        for wheel_id, speed, friction in samples:
            wheel = self._wheel(wheel_id)
            if wheel is None:
                continue
            wheel.health.last_input = now
            self._silence.heard(wheel_id, now)
            try:
                self._append(wheel_id, wheel, seconds, speed, friction)
            except Exception as err:  # noqa: BLE001 - one wheel never stops the others
                self._failed(wheel_id, wheel, 'wheel_failures', err)
                wheel.window.reset()

    def _append(self, wheel_id: str, wheel: _Wheel, seconds: float, speed: float,
                friction: float) -> None:
        """Add one sample to a wheel's window; submit a diagnosis when one is due."""
        before = wheel.window.dropped
        due = wheel.window.update(seconds, speed, friction)
        if wheel.window.dropped != before:
            self._count('non_increasing_time', wheel_id, f'{wheel_id}: dropped a sample whose '
                        f'stamp is not after the last one (t={seconds!r})')
            return
        wheel.samples += 1
        if due:
            self._submit(wheel_id, wheel)

    def _wheel(self, wheel_id: str) -> _Wheel | None:
        wheel = self.wheels.get(wheel_id)
        if wheel is not None:
            return wheel
        invalid = wheels_input.name_refusal(wheel_id)
        if invalid is not None:     # logged once whatever the name: names are unbounded
            self._count(invalid.counter, '', invalid.message)
            return None
        refusal = common.wheel_refusal(wheel_id, self._allowed, len(self.wheels),
                                       self.params['max_wheels'])
        if refusal is not None:
            self._count(refusal[0], wheel_id, refusal[1])
            return None
        wheel = self.wheels[wheel_id] = _Wheel(self.params['window_length'],
                                               self.params['window_period'])
        check = f'{wheel_id} window diagnosis'
        wheel.health = self.diagnostics.component(wheel_id, check)
        self.diagnostics.provide(wheel_id, check, lambda: self._wheel_health(wheel))
        self.get_logger().info(f'monitoring wheel {wheel_id!r}')
        return wheel

    # --------------------------------------------------------------------- worker
    def _submit(self, wheel_id: str, wheel: _Wheel) -> None:
        if wheel.busy:
            wheel.skipped_busy += 1
            return
        wheel.busy = True
        time_s, speed, friction = wheel.window.snapshot()
        first_index = wheel.samples - time_s.size
        block = self.calibration.block(wheel_id)
        if block is not None:
            future = self._worker.submit(diagnose_fss, block, time_s, speed, friction,
                                         self._model, self._config)
        else:
            future = self._worker.submit(diagnose, speed, friction, time_s, self._model,
                                         self._config)
        future.add_done_callback(lambda f: self._done.put((wheel_id, first_index, time_s, f)))

    def publish_results(self) -> None:
        """Publish the diagnoses that the worker finished (timer callback)."""
        while True:
            try:
                wheel_id, first, time_s, future = self._done.get_nowait()
            except queue.Empty:
                return
            wheel = self.wheels[wheel_id]
            wheel.busy = False
            try:
                result = future.result()
                self._record(wheel_id, wheel, result, first, time_s)
            except Exception as err:  # noqa: BLE001 - a failed window never stops the node
                self._failed(wheel_id, wheel, 'diagnosis_failed', err)

    def _failed(self, wheel_id: str, wheel: _Wheel, reason: str, err: Exception) -> None:
        """Count and log (once per wheel and reason) a failure; show ERROR on the wheel."""
        wheel.failures += 1
        wheel.last_failure = (self.diagnostics.now(), f'{type(err).__name__}: {err}')
        self._count(reason, wheel_id, f'{wheel_id}: {reason.replace("_", " ")}: '
                    f'{wheel.last_failure[1]}')

    def _free_silent_wheels(self) -> None:
        """Free the wheels silent for ``wheel_timeout`` s (timer on the steady clock)."""
        self._silence.timeout = self.params['wheel_timeout']
        for wheel_id in self._silence.silent(self.diagnostics.now()):
            self._silence.forget(wheel_id)
            wheel = self.wheels.get(wheel_id)
            if wheel is not None and not wheel.busy:
                del self.wheels[wheel_id]
                self.diagnostics.remove(wheel_id)
                self.input_counters['wheels_freed'] += 1
                self.get_logger().info(f'wheel {wheel_id!r} silent for more than '
                                       f'{self._silence.timeout:g} s: freed')

    def _record(self, wheel_id: str, wheel: _Wheel, result: dict, first: int,
                time_s: np.ndarray) -> None:
        wheel.diagnoses += 1
        wheel.result = result
        wheel.window_bounds = (float(time_s[0]), float(time_s[-1]))
        found = window_events(wheel_id, result, time_s, first, previous=wheel.flags)
        wheel.flags = dict(result['anomalies'])
        if not found:
            return
        self.alarms.record(found)   # journalled (fsynced) before it is published
        out = DiagnosticArray()
        out.header.stamp = messages.to_stamp(found[0].declared_time)
        out.status = [messages.event_status(e, self.get_name()) for e in found]
        self._anomaly_pub.publish(out)
        start, end = wheel.window_bounds
        for event in found:
            self.get_logger().warning(f'{wheel_id}: {event.kind} anomaly from t='
                                      f'{event.time:.1f} s in the window '
                                      f't={start:.1f}..{end:.1f} s')
        self.events.extend(found)

    # --------------------------------------------------------------------- health
    def _wheel_health(self, wheel: _Wheel) -> tuple[bytes, str, dict[str, Any]]:
        values: dict[str, Any] = {'samples': wheel.samples, 'diagnoses': wheel.diagnoses,
                                  'window_samples': wheel.window.size,
                                  'non_finite': wheel.window.non_finite,
                                  'gaps': wheel.window.gaps,
                                  'skipped_busy': wheel.skipped_busy,
                                  'failures': wheel.failures}
        failure = wheel.last_failure
        if failure is not None and self.diagnostics.now() - failure[0] < ERROR_HOLD_S:
            return self.alarms.merge(wheel.health.hardware_id, ERROR,
                                     f'diagnosis failed ({failure[1]})', values)
        if wheel.result is None:
            values[keys.WAITING_SAMPLES] = wheel.window.length - wheel.window.size
            return self.alarms.merge(
                wheel.health.hardware_id, STALE, f'unknown: not examined yet, waiting for '
                f'a full window ({wheel.window.size}/{wheel.window.length} samples)', values)
        start, end = wheel.window_bounds
        est = wheel.result['estimates']
        values.update({keys.WINDOW_START: start, keys.WINDOW_END: end,
                       keys.BASE_DRY: est['base_dry_nm'], keys.VISCOUS: est['viscous_nms'],
                       keys.NOISE_STD: est['noise_std_nm'],
                       'changepoints': len(wheel.result['changepoints'])})
        values.update({f'anomaly_{k}': v for k, v in wheel.flags.items()})
        values.update(self.calibration.values())
        if wheel.result.get('status') == 'unknown':
            values['status'] = 'unknown'
            return WARN, f'unknown in t={start:.1f}..{end:.1f} s: ' \
                f'{wheel.result.get("unknown_reason")}', values
        found = [k for k, v in wheel.flags.items() if v]
        if found:
            level, text = WARN, f'anomalies {", ".join(found)} in t={start:.1f}..{end:.1f} s'
        else:
            level, text = OK, f'no anomaly in t={start:.1f}..{end:.1f} s'
        return self.alarms.merge(wheel.health.hardware_id, level, text, values)

    def _input_health(self) -> tuple[bytes, str, dict[str, Any]]:
        rejected = sum(v for k, v in self.input_counters.items() if k != 'messages')
        message = (f'{len(self.wheels)} wheels' if not rejected
                   else f'{len(self.wheels)} wheels; {rejected} entries rejected')
        return OK, message, dict(self.input_counters)

    def destroy_node(self) -> None:
        """Stop the worker (waiting for a running diagnosis), then destroy the node."""
        self._worker.shutdown(wait=True, cancel_futures=True)
        super().destroy_node()


NODE_CLASS = FssDiagnoserNode


def main(args: Sequence[str] | None = None) -> int:
    """Run the FSS window diagnoser node (console script ``rwa-monitor-fss``)."""
    return run_node(lambda: FssDiagnoserNode(), args, help_text=lambda: node_help(
        'rwa-monitor-fss', __doc__, PARAMETERS))


if __name__ == '__main__':
    raise SystemExit(main())
