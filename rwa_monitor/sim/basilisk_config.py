"""Parameters and fault specifications of the Basilisk bus (no Basilisk import here).

Everything here is plain Python so that the command line and the node can validate their
arguments and say what is wrong even where the optional simulator is not installed.
Defaults and the reasons for them are in docs/basilisk.md.

Fault specifications (command line ``--fault``, node parameters ``faults``/``inject``)::

    friction:WHEEL:TIME_S:dry=NM[,viscous=NMS][,ramp=S]
    gyro:AXIS:TIME_S:bias=RAD_S
    gyro:AXIS:TIME_S:drift=RAD_S2[,level=RAD_S]

``TIME_S`` is seconds of simulation time, or ``now`` (the current simulation time when
the fault is scheduled). A friction fault adds ``dry`` (N m) to the Coulomb level and
``viscous`` (N m s/rad) to the viscous coefficient of one wheel, as a step or, with
``ramp`` > 0, linearly over ``ramp`` seconds. A gyro ``bias`` is a step of the gyro error
on one axis; a ``drift`` ramps it with a constant slope (rad/s per s), up to ``level``
(then held: a bias after the drift) or without end when ``level`` is absent.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import importlib.util
import math

from rwa_monitor.core.params import check_int, check_real
from rwa_monitor.exceptions import ConfigError, RwaMonitorError

INSTALL_HINT = ('the spacecraft simulation bus needs the optional extra: '
                "pip install -e '.[bsk]' (or make test-bsk / make demo-bus, which use .venv-bsk)")

WHEEL_IDS = ('rw1', 'rw2', 'rw3', 'rw4')
AXES = ('x', 'y', 'z')
HEALTHY, DRIFT, BIAS = 0, 1, 2   # gyro truth labels (vsadc paper: 0 healthy, 1 drift, 2 bias)


@dataclass(frozen=True)
class BusConfig:
    """Spacecraft, wheels, controller, guidance and sensors (SI units)."""

    rate_hz: float = 4.0                 # telemetry and flight-software rate (vsadc Table 2)
    inertia: float = 14.5                # kg m^2, hub, diagonal (vsadc Table 2)
    kp: float = 0.2                      # N m/rad, attitude gain (vsadc Table 2)
    kd: float = 0.7                      # N m s/rad, rate gain (vsadc Table 2)
    elevation_deg: float = 30.0          # pyramid: wheel axes 30 deg above the x-y plane
    wheel_inertia: float = 0.02          # kg m^2 about the spin axis
    coulomb: float = 5.0e-4              # N m, Coulomb (dry) friction
    static: float = 8.0e-4               # N m, breakaway (Stribeck peak) friction
    stribeck_speed: float = 1.0          # rad/s, Stribeck velocity (> 0: Stribeck on)
    viscous: float = 2.0e-6              # N m s/rad
    omega_limit_cycle: float = 0.1       # rad/s, the simulator's friction band around 0
    torque_max: float = 0.05             # N m per wheel
    null_speed: float = 10.0             # rad/s, wheel speed bias along the null space
    null_gain: float = 0.002             # N m s/rad, null-space speed servo gain
    ref_amplitude: tuple[float, float, float] = (0.02, 0.015, 0.025)   # rad/s
    ref_period: tuple[float, float, float] = (700.0, 1100.0, 1500.0)   # s
    friction_noise_std: float = 5.0e-5   # N m, white noise of the friction telemetry
    gyro_noise_std: float = 1.0e-5       # rad/s per sample (white, the IMU's own process)
    gyro_bias_std: float = 1.0e-5        # rad/s, constant bias per axis ~ N(0, std^2)
    gyro_rate_walk: float = 2.0e-8       # rad/s/sqrt(s), nominal bias drift (random walk)
    gyro_walk_bound: float = 5.0e-5      # rad/s, bound of that nominal drift
    st_noise_arcsec: float = 5.0         # 1-sigma per axis, white, clipped at 3 sigma
    slew_rate: float = 0.0               # rad/s, rest-to-rest slews added to guidance (0: none)
    slew_period: float = 1200.0          # s between slew starts (about x, y, z in turn)
    slew_duration: float = 120.0         # s per slew, its acceleration ramps included
    slew_ramp: float = 20.0              # s of each acceleration / deceleration ramp
    gyro_thermal_amplitude: float = 0.0  # rad/s, orbital thermal wander of the gyro bias
    gyro_thermal_period: float = 5400.0  # s (one orbit); axis phases 0, 120, 240 deg

    def validated(self) -> 'BusConfig':
        """Return self after checking every value; ValueError names the bad one."""
        positive = ('rate_hz', 'inertia', 'kp', 'kd', 'wheel_inertia', 'torque_max',
                    'omega_limit_cycle', 'stribeck_speed', 'slew_period', 'slew_ramp',
                    'gyro_thermal_period')
        non_negative = ('coulomb', 'viscous', 'null_speed', 'null_gain',
                        'friction_noise_std', 'gyro_noise_std', 'gyro_bias_std',
                        'gyro_rate_walk', 'gyro_walk_bound', 'st_noise_arcsec',
                        'slew_rate', 'gyro_thermal_amplitude')
        for name in positive:
            check_real(name, getattr(self, name), 0.0, low_open=True)
        for name in non_negative:
            check_real(name, getattr(self, name), 0.0)
        check_real('static', self.static, self.coulomb)
        check_real('slew_duration', self.slew_duration, 2.0 * self.slew_ramp, self.slew_period)
        check_real('elevation_deg', self.elevation_deg, 0.0, 90.0, True, True)
        for name in ('ref_amplitude', 'ref_period'):
            values = getattr(self, name)
            if len(values) != 3:
                raise ValueError(f'{name} must have 3 values (x, y, z), got {values!r}')
            for axis, value in zip(AXES, values):
                check_real(f'{name}[{axis}]', value, 0.0, low_open=name == 'ref_period')
        return self


def config_fields() -> tuple[str, ...]:
    """Return the names of the BusConfig fields."""
    return tuple(f.name for f in fields(BusConfig))


@dataclass(frozen=True)
class FrictionFault:
    """A friction change on ``wheel`` from ``time_s``: a step, or a ramp over ``ramp_s``."""

    wheel: str
    time_s: float
    delta_dry: float = 0.0
    delta_viscous: float = 0.0
    ramp_s: float = 0.0

    def fraction(self, t: float) -> float:
        """Return how much of the change applies at time ``t`` (0 before, 1 when done)."""
        if t < self.time_s:
            return 0.0
        if self.ramp_s <= 0.0:
            return 1.0
        return min(1.0, (t - self.time_s) / self.ramp_s)


@dataclass(frozen=True)
class GyroFault:
    """A gyro error on ``axis`` (0..2) from ``time_s``: bias step or drift ramp.

    ``slope`` (rad/s per s) > 0 is a drift that ramps towards ``level`` (rad/s, signed;
    NaN: no end); ``slope`` = 0 is a bias step of ``level``.
    """

    axis: int
    time_s: float
    level: float = math.nan
    slope: float = 0.0

    def error(self, t: float) -> tuple[float, int]:
        """Return the gyro error in rad/s and the truth label at ``t`` seconds."""
        if t < self.time_s:
            return 0.0, HEALTHY
        if self.slope <= 0.0:
            return self.level, BIAS
        sign = -1.0 if self.level < 0 else 1.0
        ramp = sign * self.slope * (t - self.time_s)
        if math.isnan(self.level) or abs(ramp) < abs(self.level):
            return ramp, DRIFT
        return self.level, BIAS


Fault = FrictionFault | GyroFault


def _parse_options(spec: str, text: str, allowed: tuple[str, ...]) -> dict[str, float]:
    options: dict[str, float] = {}
    for item in filter(None, text.split(',')):
        key, sep, value = item.partition('=')
        key = key.strip()
        if not sep or key not in allowed:
            raise ConfigError(f'bad fault {spec!r}: expected KEY=VALUE with KEY one of '
                              f'{", ".join(allowed)}, got {item!r}')
        if key in options:
            raise ConfigError(f'bad fault {spec!r}: {key} given twice')
        try:
            number = float(value)
        except ValueError:
            raise ConfigError(f'bad fault {spec!r}: {key} must be a number, '
                              f'got {value!r}') from None
        if not math.isfinite(number):
            raise ConfigError(f'bad fault {spec!r}: {key} must be finite')
        options[key] = number
    return options


def parse_fault(spec: str, now: float = 0.0) -> Fault:
    """Parse a fault specification (module docstring); ConfigError says what is wrong.

    ``now`` is the simulation time that the time ``now`` stands for.
    """
    usage = ('expected friction:WHEEL:TIME_S:dry=NM[,viscous=NMS][,ramp=S] or '
             'gyro:AXIS:TIME_S:bias=RAD_S or gyro:AXIS:TIME_S:drift=RAD_S2[,level=RAD_S]')
    parts = spec.strip().split(':')
    if len(parts) != 4:
        raise ConfigError(f'bad fault {spec!r}: {usage}')
    kind, target, time_text, options = parts
    if time_text.strip() == 'now':
        time_s = now
    else:
        try:
            time_s = float(time_text)
        except ValueError:
            raise ConfigError(f'bad fault {spec!r}: TIME_S must be a number of seconds or '
                              f'"now", got {time_text!r}') from None
        if not (math.isfinite(time_s) and time_s >= 0.0):
            raise ConfigError(f'bad fault {spec!r}: TIME_S must be >= 0')
    if kind == 'friction':
        if target not in WHEEL_IDS:
            raise ConfigError(f'bad fault {spec!r}: WHEEL must be one of '
                              f'{", ".join(WHEEL_IDS)}, got {target!r}')
        opts = _parse_options(spec, options, ('dry', 'viscous', 'ramp'))
        if not {'dry', 'viscous'} & set(opts):
            raise ConfigError(f'bad fault {spec!r}: give dry=NM and/or viscous=NMS')
        if opts.get('ramp', 0.0) < 0.0:
            raise ConfigError(f'bad fault {spec!r}: ramp must be >= 0 s')
        return FrictionFault(target, time_s, opts.get('dry', 0.0), opts.get('viscous', 0.0),
                             opts.get('ramp', 0.0))
    if kind == 'gyro':
        if target not in AXES:
            raise ConfigError(f'bad fault {spec!r}: AXIS must be one of {", ".join(AXES)}, '
                              f'got {target!r}')
        opts = _parse_options(spec, options, ('bias', 'drift', 'level'))
        if ('bias' in opts) == ('drift' in opts):
            raise ConfigError(f'bad fault {spec!r}: give exactly one of bias= or drift=')
        if 'bias' in opts:
            if 'level' in opts:
                raise ConfigError(f'bad fault {spec!r}: level goes with drift, not bias')
            return GyroFault(AXES.index(target), time_s, opts['bias'], 0.0)
        slope = opts['drift']
        if slope <= 0.0:
            raise ConfigError(f'bad fault {spec!r}: drift slope must be > 0 '
                              f'(the sign of level gives the direction)')
        return GyroFault(AXES.index(target), time_s, opts.get('level', math.nan), slope)
    raise ConfigError(f'bad fault {spec!r}: kind must be friction or gyro; {usage}')


def describe(fault: Fault) -> str:
    """Return a one-line human description of a fault."""
    if isinstance(fault, FrictionFault):
        how = 'step' if fault.ramp_s <= 0 else f'ramp over {fault.ramp_s:g} s'
        return (f'{fault.wheel}: friction {how} at t = {fault.time_s:g} s, dry '
                f'{fault.delta_dry:+g} N m, viscous {fault.delta_viscous:+g} N m s/rad')
    axis = AXES[fault.axis]
    if fault.slope <= 0:
        return f'gyro_{axis}: bias step {fault.level:+g} rad/s at t = {fault.time_s:g} s'
    end = 'without end' if math.isnan(fault.level) else f'to {fault.level:+g} rad/s'
    return (f'gyro_{axis}: drift {fault.slope:g} rad/s per s {end} from '
            f't = {fault.time_s:g} s')


def check_seed(seed: int) -> int:
    """Return ``seed`` if it is an integer in [0, 2**32 - 1], else ValueError."""
    return check_int('seed', seed, 0, 2 ** 32 - 1)


def available() -> bool:
    """Return True if the simulator package is installed (without importing it)."""
    return importlib.util.find_spec('Basilisk') is not None


def require() -> None:
    """Raise RwaMonitorError with the install hint if the simulator is not installed."""
    if not available():
        raise RwaMonitorError(INSTALL_HINT)
