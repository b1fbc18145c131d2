"""The spacecraft simulation bus: a Basilisk scenario stepped one telemetry sample at a time.

The only module of the package that imports Basilisk (the optional extra ``bsk``). The
scenario (docs/basilisk.md): a rigid hub with four reaction wheels in a pyramid, each with
Coulomb, viscous and Stribeck friction and an explicit ``omegaLimitCycle``; a guidance
whose reference body rate is a sum of sines (so that the wheel speeds swing through zero);
attitude tracking error, an MRP feedback controller, a wheel torque mapping and a
null-space speed servo; an IMU (white gyro noise from its Gauss-Markov process, bias and a
bounded bias random walk through ``senRotBias``) and a star tracker with white noise
clipped at 3 sigma. Faults (friction steps/ramps, gyro bias steps/drift ramps) are applied
before the step that ends at the sample where they start.

Traps guarded here (measured on this simulator): the wheel factory helper calls
``exit(1)`` on bad arguments, so the wheel payloads are built directly from validated
values; the gravity helper makes a network request at import, so no gravity is used; the
per-wheel output ``Omega`` may lag the speed message by a step when the wheel effector runs
before the hub, so the speed comes from ``rwSpeedOutMsg`` and the hub runs first;
``frictionTorque`` is the value of the integrator's last stage (about the end-of-step
speed; it differs from f(speed) only inside the limit-cycle band); the IMU has one
Gauss-Markov state per axis, so white noise uses it and the bias drift is ours.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Callable, Iterable

from Basilisk.architecture import messaging
from Basilisk.fswAlgorithms import attTrackingError, mrpFeedback, rwMotorTorque, rwNullSpace
from Basilisk.simulation import (imuSensor, reactionWheelStateEffector, simpleNav,
                                 spacecraft, starTracker)
from Basilisk.utilities import SimulationBaseClass
import numpy as np

from rwa_monitor.sim.basilisk_config import (AXES, BusConfig, Fault, FrictionFault,
                                             GyroFault, HEALTHY, WHEEL_IDS)
from rwa_monitor.telemetry import Telemetry, Wheel

ARCSEC = math.pi / (180.0 * 3600.0)
NULL_DIRECTION = (1.0, -1.0, 1.0, -1.0)   # G @ this = 0 for the symmetric pyramid
_NS = 1_000_000_000
# Project friction = this factor x the simulator's frictionTorque. Both oppose the motion
# (f = -f_c sign(w) - f_v w); test_basilisk.py measures the sign on the simulator.
FRICTION_SIGN = 1.0


@dataclass
class Sample:
    """One telemetry sample of the bus (SI units; quaternion scalar last)."""

    time: float
    speed: list[float]
    friction: list[float]
    motor_torque: list[float]
    gyro: list[float]
    attitude: list[float]
    reference_rate: list[float]
    truth: dict[str, float] = field(default_factory=dict)


def wheel_axes(elevation_deg: float) -> np.ndarray:
    """Return the 4 x 3 spin axes of the pyramid (azimuths 45, 135, 225, 315 deg)."""
    el = math.radians(elevation_deg)
    return np.array([[math.cos(el) * math.cos(math.radians(az)),
                      math.cos(el) * math.sin(math.radians(az)), math.sin(el)]
                     for az in (45.0, 135.0, 225.0, 315.0)])


def _qmul(p: tuple, q: tuple) -> tuple:
    """Return the Hamilton product of scalar-first quaternions (plain floats)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3, p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1, p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


def _rotate(q: tuple, v: Iterable[float]) -> list[float]:
    """Return ``q v q*``: frame components of ``v`` in the frame ``q`` is relative to."""
    r = _qmul(_qmul(q, (0.0, *v)), (q[0], -q[1], -q[2], -q[3]))
    return [r[1], r[2], r[3]]


def _mrp_to_quaternion(sigma: Iterable[float]) -> list[float]:
    """Return the quaternion ``[x, y, z, w]`` (w >= 0) of modified Rodrigues parameters."""
    s1, s2, s3 = sigma
    s2n = s1 * s1 + s2 * s2 + s3 * s3
    q = [2.0 * s1 / (1.0 + s2n), 2.0 * s2 / (1.0 + s2n), 2.0 * s3 / (1.0 + s2n),
         (1.0 - s2n) / (1.0 + s2n)]
    return q if q[3] >= 0 else [-v for v in q]


class Guidance:
    """Reference attitude whose body rate is ``A_i sin(2 pi t / T_i)`` per axis.

    The reference quaternion (scalar first, relative to inertial) is propagated with the
    exact rotation of the mid-step rate; the message carries sigma_RN, omega_RN_N and
    domega_RN_N (the inertial derivative equals the R-frame one for omega_RN).
    """

    def __init__(self, amplitude: tuple[float, ...], period: tuple[float, ...],
                 slew: tuple[float, float, float, float] = (0.0, 1.0, 1.0, 0.5)) -> None:
        self.amplitude = [float(a) for a in amplitude]
        self.omega = [2.0 * math.pi / float(p) for p in period]
        self.slew_rate, self.slew_period, self.slew_duration, self.slew_ramp = slew
        self.q = (1.0, 0.0, 0.0, 0.0)
        self.t = 0.0

    def rate(self, t: float) -> tuple[list[float], list[float]]:
        """Return the reference body rate, R frame, and its derivative at ``t`` seconds."""
        rate = [a * math.sin(w * t) for a, w in zip(self.amplitude, self.omega)]
        accel = [a * w * math.cos(w * t) for a, w in zip(self.amplitude, self.omega)]
        if self.slew_rate > 0.0:    # rest-to-rest slews about x, y, z in turn, signs alternate
            cycle, tau = divmod(t, self.slew_period)
            axis, sign = int(cycle) % 3, (1.0 if int(cycle // 3) % 2 == 0 else -1.0)
            top, ramp, end = self.slew_rate * sign, self.slew_ramp, self.slew_duration
            if tau < ramp:
                rate[axis] += top * tau / ramp
                accel[axis] += top / ramp
            elif tau < end - ramp:
                rate[axis] += top
            elif tau < end:
                rate[axis] += top * (end - tau) / ramp
                accel[axis] -= top / ramp
        return rate, accel

    def advance(self, t: float) -> None:
        """Propagate the reference attitude to time ``t``."""
        dt = t - self.t
        mid, _ = self.rate(self.t + 0.5 * dt)
        norm = math.sqrt(sum(v * v for v in mid))
        angle = norm * dt
        s = math.sin(0.5 * angle) / norm if norm > 0 else 0.5 * dt
        q = _qmul(self.q, (math.cos(0.5 * angle), mid[0] * s, mid[1] * s, mid[2] * s))
        n = math.sqrt(sum(v * v for v in q))
        self.q = tuple(v / n for v in q)
        self.t = t

    def write(self, payload: messaging.AttRefMsgPayload, t: float) -> None:
        """Fill an AttRefMsgPayload with the reference at time ``t`` (after advance)."""
        q = self.q if self.q[0] >= 0 else tuple(-v for v in self.q)
        rate, accel = self.rate(t)
        payload.sigma_RN = [q[1] / (1.0 + q[0]), q[2] / (1.0 + q[0]), q[3] / (1.0 + q[0])]
        payload.omega_RN_N = _rotate(q, rate)
        payload.domega_RN_N = _rotate(q, accel)


class BasiliskBus:
    """The simulated spacecraft; ``step()`` advances one sample and returns it.

    ``faults`` may be given at construction or added at any time with :meth:`schedule`
    (a fault whose start time has passed starts at the next sample). Memory does not grow
    with the number of steps: nothing is recorded here (``run`` fills arrays it owns).
    """

    def __init__(self, config: BusConfig | None = None, faults: Iterable[Fault] = (),
                 seed: int = 0) -> None:
        self.config = cfg = (config or BusConfig()).validated()
        self.dt = 1.0 / cfg.rate_hz
        self._dt_ns = int(round(self.dt * _NS))
        self.wheel_ids = WHEEL_IDS
        self.steps = 0
        self.faults: list[Fault] = []
        seeds = np.random.SeedSequence(seed).generate_state(4, dtype=np.uint32)
        self._noise = np.random.default_rng(int(seeds[2]))
        bias_rng = np.random.default_rng(int(seeds[3]))
        self._bias0 = bias_rng.normal(0.0, cfg.gyro_bias_std, 3).tolist()
        self._walk = [0.0, 0.0, 0.0]
        self._walk_rng = bias_rng
        self._applied = [0.0] * 4
        self._build(cfg, int(seeds[0]), int(seeds[1]))
        for fault in faults:
            self.schedule(fault)

    # ----------------------------------------------------------------------- scenario
    def _build(self, cfg: BusConfig, imu_seed: int, st_seed: int) -> None:
        sim = self._sim = SimulationBaseClass.SimBaseClass()
        process = sim.CreateNewProcess('bus')
        process.addTask(sim.CreateNewTask('dynamics', self._dt_ns))
        process.addTask(sim.CreateNewTask('fsw', self._dt_ns))
        inertia = [[cfg.inertia, 0.0, 0.0], [0.0, cfg.inertia, 0.0], [0.0, 0.0, cfg.inertia]]

        hub = self._hub = spacecraft.Spacecraft()
        hub.ModelTag = 'hub'
        hub.hub.mHub = 100.0
        hub.hub.IHubPntBc_B = inertia
        axes = self.axes = wheel_axes(cfg.elevation_deg)
        rwa = self._rwa = reactionWheelStateEffector.ReactionWheelStateEffector()
        rwa.ModelTag = 'rwa'
        self._wheels = []
        for i, wheel_id in enumerate(WHEEL_IDS):
            self._wheels.append(self._wheel(cfg, axes[i], NULL_DIRECTION[i] * cfg.null_speed,
                                            wheel_id))
            rwa.addReactionWheel(self._wheels[-1])
        hub.addStateEffector(rwa)
        sim.AddModelToTask('dynamics', hub, None, 100)   # hub first: outputs at step end
        sim.AddModelToTask('dynamics', rwa, None, 99)

        nav = self._nav = simpleNav.SimpleNav()
        nav.ModelTag = 'nav'
        nav.scStateInMsg.subscribeTo(hub.scStateOutMsg)
        sim.AddModelToTask('dynamics', nav, None, 98)
        imu = self._imu = imuSensor.ImuSensor()
        imu.ModelTag = 'imu'
        imu.scStateInMsg.subscribeTo(hub.scStateOutMsg)
        imu.PMatrixGyro = (np.eye(3) * cfg.gyro_noise_std).tolist()
        imu.setAMatrixGyro(np.zeros((3, 3)).tolist())        # white: no memory
        imu.setWalkBoundsGyro(np.full((3, 1), max(4.0 * cfg.gyro_noise_std, 1e-12)))
        imu.RNGSeed = imu_seed
        sim.AddModelToTask('dynamics', imu, None, 97)
        tracker = self._tracker = starTracker.StarTracker()
        tracker.ModelTag = 'star_tracker'
        tracker.scStateInMsg.subscribeTo(hub.scStateOutMsg)
        sigma = cfg.st_noise_arcsec * ARCSEC
        tracker.PMatrix = (np.eye(3) * sigma).tolist()
        tracker.setAMatrix(np.zeros((3, 3)).tolist())         # white, not a random walk
        tracker.setWalkBounds(np.full((3, 1), max(3.0 * sigma, 1e-12)))
        tracker.RNGSeed = st_seed
        sim.AddModelToTask('dynamics', tracker, None, 96)

        self._guidance = Guidance(cfg.ref_amplitude, cfg.ref_period,
                                  (cfg.slew_rate, cfg.slew_period, cfg.slew_duration,
                                   cfg.slew_ramp))
        self._ref = messaging.AttRefMsgPayload()
        self._guidance.write(self._ref, 0.0)
        self._ref_msg = messaging.AttRefMsg().write(self._ref)
        track = self._track = attTrackingError.attTrackingError()
        track.ModelTag = 'tracking'
        track.attNavInMsg.subscribeTo(nav.attOutMsg)
        track.attRefInMsg.subscribeTo(self._ref_msg)
        sim.AddModelToTask('fsw', track, None, 10)
        vehicle = messaging.VehicleConfigMsgPayload()
        vehicle.ISCPntB_B = [v for row in inertia for v in row]
        self._vehicle_msg = messaging.VehicleConfigMsg().write(vehicle)
        params = messaging.RWArrayConfigMsgPayload()
        params.GsMatrix_B = axes.flatten().tolist()
        params.JsList = [cfg.wheel_inertia] * 4
        params.uMax = [cfg.torque_max] * 4
        params.numRW = 4
        self._params_msg = messaging.RWArrayConfigMsg().write(params)
        control = self._control = mrpFeedback.mrpFeedback()
        control.ModelTag = 'control'
        control.guidInMsg.subscribeTo(track.attGuidOutMsg)
        control.vehConfigInMsg.subscribeTo(self._vehicle_msg)
        control.rwParamsInMsg.subscribeTo(self._params_msg)
        control.rwSpeedsInMsg.subscribeTo(rwa.rwSpeedOutMsg)
        control.K = 4.0 * cfg.kp        # MRP ~ angle / 4: torque ~ kp x angle
        control.P = cfg.kd
        control.Ki = -1.0               # no integral term
        sim.AddModelToTask('fsw', control, None, 9)
        mapping = self._mapping = rwMotorTorque.rwMotorTorque()
        mapping.ModelTag = 'torque_mapping'
        mapping.controlAxes_B = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        mapping.vehControlInMsg.subscribeTo(control.cmdTorqueOutMsg)
        mapping.rwParamsInMsg.subscribeTo(self._params_msg)
        sim.AddModelToTask('fsw', mapping, None, 8)
        self._null_msgs = self._null_servo(cfg, axes, mapping, rwa)
        sim.AddModelToTask('fsw', self._null, None, 7)
        rwa.rwMotorCmdInMsg.subscribeTo(self._null.rwMotorTorqueOutMsg)
        sim.InitializeSimulation()

    @staticmethod
    def _wheel(cfg: BusConfig, axis: np.ndarray, omega0: float,
               label: str) -> reactionWheelStateEffector.RWConfigPayload:
        """Return one wheel's payload, built from validated values (no factory helper)."""
        wheel = reactionWheelStateEffector.RWConfigPayload()
        wheel.gsHat_B = [[float(v)] for v in axis]
        w2 = np.cross(axis, [1.0, 0.0, 0.0])
        w2 /= np.linalg.norm(w2)
        w3 = np.cross(axis, w2)
        wheel.w2Hat0_B = [[float(v)] for v in w2]
        wheel.w3Hat0_B = [[float(v)] for v in w3]
        wheel.Js = cfg.wheel_inertia
        wheel.Jt = wheel.Jg = 0.5 * cfg.wheel_inertia
        wheel.mass = 1.0
        wheel.Omega = float(omega0)
        wheel.Omega_max = -1.0
        wheel.fCoulomb = cfg.coulomb
        wheel.fStatic = cfg.static
        wheel.betaStatic = cfg.stribeck_speed
        wheel.cViscous = cfg.viscous
        wheel.omegaLimitCycle = cfg.omega_limit_cycle
        wheel.u_max = cfg.torque_max
        wheel.u_min = 0.0
        wheel.RWModel = messaging.BalancedWheels
        wheel.label = label
        return wheel

    def _null_servo(self, cfg: BusConfig, axes: np.ndarray, mapping, rwa) -> tuple:
        constellation = messaging.RWConstellationMsgPayload()
        elements = []
        for axis in axes:
            element = messaging.RWConfigElementMsgPayload()
            element.gsHat_B = axis.tolist()
            element.Js = cfg.wheel_inertia
            element.uMax = cfg.torque_max
            elements.append(element)
        constellation.reactionWheels = elements
        constellation.numRW = 4
        desired = messaging.RWSpeedMsgPayload()
        desired.wheelSpeeds = [d * cfg.null_speed for d in NULL_DIRECTION]
        msgs = (messaging.RWConstellationMsg().write(constellation),
                messaging.RWSpeedMsg().write(desired))
        null = self._null = rwNullSpace.rwNullSpace()
        null.ModelTag = 'null_space'
        null.rwMotorTorqueInMsg.subscribeTo(mapping.rwMotorTorqueOutMsg)
        null.rwSpeedsInMsg.subscribeTo(rwa.rwSpeedOutMsg)
        null.rwConfigInMsg.subscribeTo(msgs[0])
        null.rwDesiredSpeedsInMsg.subscribeTo(msgs[1])
        null.OmegaGain = cfg.null_gain
        return msgs

    # ------------------------------------------------------------------------- faults
    @property
    def time(self) -> float:
        """Return the simulation time in seconds of the last sample (0 before any step)."""
        return self.steps * self.dt

    def schedule(self, fault: Fault) -> None:
        """Add a fault (FrictionFault or GyroFault); ValueError if it names no component."""
        if isinstance(fault, FrictionFault):
            if fault.wheel not in WHEEL_IDS:
                raise ValueError(f'wheel must be one of {", ".join(WHEEL_IDS)}, '
                                 f'got {fault.wheel!r}')
        elif isinstance(fault, GyroFault):
            if fault.axis not in (0, 1, 2):
                raise ValueError(f'axis must be 0, 1 or 2, got {fault.axis!r}')
        else:
            raise ValueError(f'not a fault: {fault!r}')
        self.faults.append(fault)

    def _apply_faults(self, t: float) -> tuple[list[float], list[float], list[float], list[int]]:
        cfg = self.config
        dry = [cfg.coulomb] * 4
        viscous = [cfg.viscous] * 4
        gyro_error = [0.0, 0.0, 0.0]
        labels = [HEALTHY] * 3
        for fault in self.faults:
            if isinstance(fault, FrictionFault):
                share = fault.fraction(t)
                i = WHEEL_IDS.index(fault.wheel)
                dry[i] += share * fault.delta_dry
                viscous[i] += share * fault.delta_viscous
            else:
                error, label = fault.error(t)
                gyro_error[fault.axis] += error
                labels[fault.axis] = max(labels[fault.axis], label)
        for i, wheel in enumerate(self._wheels):
            wheel.fCoulomb = max(dry[i], 0.0)
            # keep the Stribeck excess (static - Coulomb) as configured
            wheel.fStatic = max(dry[i], 0.0) + (cfg.static - cfg.coulomb)
            wheel.cViscous = max(viscous[i], 0.0)
        return dry, viscous, gyro_error, labels

    # -------------------------------------------------------------------------- steps
    def step(self) -> Sample:
        """Advance one sample period; return the telemetry at its end."""
        cfg = self.config
        t = (self.steps + 1) * self.dt
        dry, viscous, gyro_error, labels = self._apply_faults(t)
        walk_step = cfg.gyro_rate_walk * math.sqrt(self.dt)
        bound = cfg.gyro_walk_bound
        for i in range(3):
            w = self._walk[i] + walk_step * float(self._walk_rng.standard_normal())
            self._walk[i] = min(bound, max(-bound, w))
        phase = 2.0 * math.pi * t / cfg.gyro_thermal_period
        nominal = [self._bias0[i] + self._walk[i] + cfg.gyro_thermal_amplitude
                   * math.sin(phase + 2.0 * math.pi * i / 3.0) for i in range(3)]
        self._imu.senRotBias = [[nominal[i] + gyro_error[i]] for i in range(3)]
        self._guidance.advance(t)
        self._guidance.write(self._ref, t)
        now_ns = self._sim.TotalSim.CurrentNanos
        self._ref_msg.write(self._ref, now_ns)
        self._sim.ConfigureStopTime((self.steps + 1) * self._dt_ns)
        self._sim.ExecuteSimulation()
        self.steps += 1
        return self._read(t, dry, viscous, gyro_error, labels, nominal)

    def _read(self, t, dry, viscous, gyro_error, labels, nominal) -> Sample:
        cfg = self.config
        speed = list(self._rwa.rwSpeedOutMsg.read().wheelSpeeds[:4])
        outs = [msg.read() for msg in self._rwa.rwOutMsgs]
        clean = [FRICTION_SIGN * o.frictionTorque for o in outs]
        noise = self._noise.normal(0.0, cfg.friction_noise_std, 4) \
            if cfg.friction_noise_std > 0 else np.zeros(4)
        friction = [clean[i] + float(noise[i]) for i in range(4)]
        # u_current read now is the torque of the coming step: report the one just applied
        motor, self._applied = self._applied, [o.u_current for o in outs]
        gyro = list(self._imu.sensorOutMsg.read().AngVelPlatform)
        b = self._tracker.sensorOutMsg.read().qInrtl2Case      # scalar first
        sign = 1.0 if b[0] >= 0 else -1.0
        attitude = [sign * b[1], sign * b[2], sign * b[3], sign * b[0]]
        reference = list(self._track.attGuidOutMsg.read().omega_RN_B)
        state = self._hub.scStateOutMsg.read()
        rate = list(state.omega_BN_B)
        q_true = _mrp_to_quaternion(state.sigma_BN)
        truth: dict[str, float] = {}
        for i, wheel_id in enumerate(WHEEL_IDS):
            truth[f'{wheel_id}_dry'] = dry[i]
            truth[f'{wheel_id}_viscous'] = viscous[i]
            truth[f'{wheel_id}_noise_std'] = cfg.friction_noise_std
            truth[f'{wheel_id}_friction_true'] = clean[i]
        for i, axis in enumerate(AXES):
            truth[f'gyro_{axis}'] = float(labels[i])
            truth[f'gyro_error_{axis}'] = gyro_error[i]
            truth[f'gyro_nominal_bias_{axis}'] = nominal[i]
            truth[f'rate_{axis}'] = rate[i]
        for name, value in zip(('q_x', 'q_y', 'q_z', 'q_w'), q_true):
            truth[name] = value
        return Sample(t, speed, friction, motor, gyro, attitude, reference, truth)

    def run(self, duration_s: float,
            progress: Callable[[float], None] | None = None) -> Telemetry:
        """Step for ``duration_s`` seconds; return the telemetry record (with truth).

        Columns: ``<id>_speed``, ``<id>_friction``, auxiliary ``<id>_motor_torque``, gyro,
        star-tracker quaternion (scalar last), reference rate and ``truth_*``.
        """
        n = int(round(duration_s / self.dt))
        if n < 1:
            raise ValueError(f'duration_s must be at least one sample period ({self.dt} s), '
                             f'got {duration_s!r}')
        time = np.empty(n)
        arrays = {name: np.empty((n, width)) for name, width in (
            ('speed', 4), ('friction', 4), ('motor', 4), ('gyro', 3), ('attitude', 4),
            ('reference', 3))}
        truth: dict[str, np.ndarray] = {}
        for k in range(n):
            s = self.step()
            time[k] = s.time
            arrays['speed'][k] = s.speed
            arrays['friction'][k] = s.friction
            arrays['motor'][k] = s.motor_torque
            arrays['gyro'][k] = s.gyro
            arrays['attitude'][k] = s.attitude
            arrays['reference'][k] = s.reference_rate
            for name, value in s.truth.items():
                if name not in truth:
                    truth[name] = np.empty(n)
                truth[name][k] = value
            if progress is not None and (k + 1) % 1000 == 0:
                progress((k + 1) / n)
        wheels = {w: Wheel(arrays['speed'][:, i].copy(), arrays['friction'][:, i].copy())
                  for i, w in enumerate(WHEEL_IDS)}
        aux = {f'{w}_motor_torque': arrays['motor'][:, i].copy()
               for i, w in enumerate(WHEEL_IDS)}
        return Telemetry(time=time, wheels=wheels, gyro=arrays['gyro'],
                         attitude=arrays['attitude'], reference_rate=arrays['reference'],
                         aux=aux, truth=truth)
