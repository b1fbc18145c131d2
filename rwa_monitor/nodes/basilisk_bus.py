"""Node ``basilisk_bus``: the simulated spacecraft, stepped live and published as telemetry.

Publishes the replay node's topics (``telemetry/wheels``, ``telemetry/gyro``,
``telemetry/star_tracker``, ``telemetry/reference_rate``, same messages and QoS) and
``/clock`` (the simulation time), and its own state on ``/diagnostics``. A steady-clock
timer steps :class:`rwa_monitor.sim.basilisk.BasiliskBus` so that the simulation time
runs at ``rate`` x real time (``rate`` 0: ``burst`` samples per executor turn, as fast as
the subscribers take them, after ``min_subscribers`` have matched).

Faults: ``faults`` (start-up, ``;``-separated specifications, see
:mod:`rwa_monitor.sim.basilisk_config`) are scheduled at start; setting ``inject`` at run
time schedules one more (``now`` = the current simulation time); a bad specification is
rejected with the reason. Nothing is recorded: each sample is published and dropped, so
memory does not grow with the run length. Needs the optional extra ``bsk``.
"""

from __future__ import annotations

import time as _time
from typing import Any, Sequence

from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import (CLOCK_QOS, declare_parameters, DiagnosticsPublisher,
                                      OK, ParamSpec, qos_event_callbacks, run_node,
                                      telemetry_qos)
from rwa_monitor.sim.basilisk_config import (available, BusConfig, describe, INSTALL_HINT,
                                             parse_fault)

NODE_NAME = 'basilisk_bus'


def _check_faults(text: str) -> None:
    for spec in filter(None, (s.strip() for s in text.split(';'))):
        try:
            parse_fault(spec)
        except ConfigError as err:
            raise ValueError(f'faults: {err}') from None


def _check_inject(text: str) -> None:
    if text.strip():
        try:
            parse_fault(text)
        except ConfigError as err:
            raise ValueError(f'inject: {err}') from None


PARAMETERS = (
    ParamSpec('rate', 1.0, 'Time factor: 1.0 real time, 50.0 fifty times faster, 0 as fast '
              'as the subscribers take it.', low=0.0, high=1.0e6),
    ParamSpec('duration_s', 0.0, 'Simulation seconds to run; 0 = until shut down.',
              low=0.0, read_only=True),
    ParamSpec('seed', 0, 'Random seed of every noise source.', low=0, high=2 ** 32 - 1,
              read_only=True),
    ParamSpec('rate_hz', BusConfig.rate_hz, 'Telemetry (and flight software) rate in Hz.',
              low=0.01, high=1000.0, read_only=True),
    ParamSpec('null_speed', BusConfig.null_speed, 'Wheel speed bias along the null space '
              '(rad/s); large values keep the wheels away from zero speed.', low=0.0,
              read_only=True),
    ParamSpec('guidance_scale', 1.0, 'Factor on the guidance rate amplitudes (0 = inertial '
              'hold; small values keep the attitude tracking error below gyro faults).',
              low=0.0, read_only=True),
    ParamSpec('friction_noise_std', BusConfig.friction_noise_std, 'White noise std of the '
              'friction telemetry (N m).', low=0.0, read_only=True),
    ParamSpec('faults', '', 'Faults scheduled at start, ";"-separated, e.g. '
              '"friction:rw2:600:dry=3e-4; gyro:x:900:drift=1e-6,level=2e-4".',
              read_only=True, validate=_check_faults),
    ParamSpec('inject', '', 'Set at run time to inject a fault, e.g. '
              '"friction:rw1:now:dry=2e-4" (TIME_S "now" = current simulation time).',
              validate=_check_inject),
    ParamSpec('min_subscribers', 0, 'Matched subscriptions (on the telemetry topic with the '
              'most) to wait for before the first step (rate 0 waits for at least 1).',
              low=0, high=1000),
    ParamSpec('burst', 1, 'Samples per executor turn at rate 0.', low=1, high=500),
    ParamSpec('exit_when_done', True, 'Shut the process down after duration_s; in-process '
              'users set false and poll `done`.'),
    ParamSpec('frame_id', 'body', 'frame_id of the gyro, star-tracker and reference-rate '
              'messages.', read_only=True),
)

_TICK = 0.005        # s of steady time between stepping turns at rate > 0
_MAX_STEPS_PER_TICK = 200


class BasiliskBusNode(Node):
    """Step the simulated spacecraft and publish its telemetry; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node (keyword arguments go to ``rclpy.node.Node``)."""
        super().__init__(NODE_NAME, **kwargs)
        self.params = declare_parameters(self, PARAMETERS, self._on_parameter)
        if not available():
            raise ConfigError(INSTALL_HINT)
        from rwa_monitor.sim.basilisk import BasiliskBus
        config = BusConfig(rate_hz=self.params['rate_hz'],
                           null_speed=self.params['null_speed'],
                           ref_amplitude=tuple(self.params['guidance_scale'] * a
                                               for a in BusConfig.ref_amplitude),
                           friction_noise_std=self.params['friction_noise_std'])
        try:
            faults = [parse_fault(s) for s in self.params['faults'].split(';') if s.strip()]
            self.bus = BasiliskBus(config, faults, seed=self.params['seed'])
        except ValueError as err:
            raise ConfigError(str(err)) from None
        self.published = 0
        self.done = False
        self.exit_code = 0
        self._started = False
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._anchor: tuple[float, float] | None = None
        self._wall_start: float | None = None
        frame = self.params['frame_id']
        self._frame = frame
        qos = telemetry_qos()
        self._wheels_pub = self._publisher(JointState, 'telemetry/wheels', qos)
        self._gyro_pub = self._publisher(Imu, 'telemetry/gyro', qos)
        self._star_pub = self._publisher(QuaternionStamped, 'telemetry/star_tracker', qos)
        self._ref_pub = self._publisher(Vector3Stamped, 'telemetry/reference_rate', qos)
        self._clock_pub = self.create_publisher(ClockMsg, '/clock', CLOCK_QOS)
        self.diagnostics = DiagnosticsPublisher(self)
        self._update_health()
        self._timer = self.create_timer(self._period(), self._tick, clock=self._steady)
        for fault in self.bus.faults:
            self.get_logger().info(f'fault scheduled: {describe(fault)}')
        self.get_logger().info(f'spacecraft bus at {config.rate_hz:g} Hz, rate '
                               f'{self.params["rate"]}, seed {self.params["seed"]}')

    def _publisher(self, msg_type: Any, topic: str, qos: Any) -> Any:
        return self.create_publisher(msg_type, topic, qos,
                                     event_callbacks=qos_event_callbacks(self, topic, True))

    def _period(self) -> float:
        return 0.0 if self.params['rate'] == 0.0 else _TICK

    def _on_parameter(self, name: str, value: Any) -> None:
        if name == 'rate':
            self._anchor = None
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(self._period(), self._tick, clock=self._steady)
        elif name == 'inject' and value.strip():
            fault = parse_fault(value, now=self.bus.time)
            self.bus.schedule(fault)
            self.get_logger().info(f'fault injected: {describe(fault)}')

    # ----------------------------------------------------------------------- stepping
    def _tick(self) -> None:
        if self.done:
            return
        if not self._started:
            needed = self.params['min_subscribers']
            if self.params['rate'] == 0.0:
                needed = max(needed, 1)
            if self.subscribers() < needed:
                return
            self._started = True
            self._wall_start = _time.perf_counter()
        steps = self.params['burst'] if self.params['rate'] == 0.0 else self._due_steps()
        duration = self.params['duration_s']
        for _ in range(steps):
            if duration > 0 and self.bus.time + 0.5 * self.bus.dt >= duration:
                self._finish()
                return
            self._publish(self.bus.step())
        if steps:
            self._update_health()

    def subscribers(self) -> int:
        """Return the most subscriptions matched on any one telemetry topic."""
        return max(pub.get_subscription_count() for pub in (
            self._wheels_pub, self._gyro_pub, self._star_pub, self._ref_pub))

    def _due_steps(self) -> int:
        now = self._steady.now().nanoseconds * 1e-9
        if self._anchor is None:
            self._anchor = (now, self.bus.time)
        due = self._anchor[1] + (now - self._anchor[0]) * self.params['rate']
        return max(0, min(int((due - self.bus.time) / self.bus.dt), _MAX_STEPS_PER_TICK))

    def _publish(self, sample: Any) -> None:
        t = sample.time
        # reference and star tracker before the gyro: a gyro consumer that pairs on the
        # gyro's arrival then finds both partners already there
        self._ref_pub.publish(messages.vector3(t, sample.reference_rate, self._frame))
        self._star_pub.publish(messages.quaternion(t, sample.attitude, self._frame))
        self._gyro_pub.publish(messages.imu(t, sample.gyro, self._frame))
        self._wheels_pub.publish(messages.joint_state(t, self.bus.wheel_ids, sample.speed,
                                                      sample.friction))
        self._clock_pub.publish(messages.clock(t))
        self.published += 1

    def _finish(self) -> None:
        self.done = True
        self._update_health()
        self.get_logger().info(f'bus done: {self.published} samples, t = {self.bus.time:g} s')
        if self.params['exit_when_done']:
            for pub in (self._wheels_pub, self._gyro_pub, self._star_pub, self._ref_pub):
                pub.wait_for_all_acked(rclpy.duration.Duration(seconds=5.0))
            rclpy.try_shutdown(context=self.context)

    @property
    def real_time_factor(self) -> float:
        """Return simulation seconds per wall-clock second since the first step."""
        if self._wall_start is None:
            return 0.0
        return self.bus.time / max(_time.perf_counter() - self._wall_start, 1e-9)

    def _update_health(self) -> None:
        state = 'done' if self.done else ('running' if self._started else 'waiting')
        self.diagnostics.mark_input('bus', 'simulation')
        self.diagnostics.set('bus', 'simulation', OK, state, sim_time_s=self.bus.time,
                             samples_published=self.published,
                             real_time_factor=round(self.real_time_factor, 2),
                             faults=len(self.bus.faults))


def main(args: Sequence[str] | None = None) -> int:
    """Run the bus node (console script ``rwa-monitor-bus``)."""
    return run_node(lambda: BasiliskBusNode(), args)


if __name__ == '__main__':
    raise SystemExit(main())
