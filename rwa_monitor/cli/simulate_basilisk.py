"""``rwa-monitor simulate basilisk``: telemetry of the Basilisk spacecraft bus with faults."""

from __future__ import annotations

import argparse
import sys

from rwa_monitor.cli.options import add_format, OUTPUT_HELP, write_output_telemetry
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.sim.basilisk_config import (BusConfig, describe, parse_fault, require,
                                             WHEEL_IDS)

EPILOG = f'''\
faults (repeatable --fault; TIME_S in seconds of simulation time):
  friction:WHEEL:TIME_S:dry=NM[,viscous=NMS][,ramp=S]   WHEEL one of {", ".join(WHEEL_IDS)};
      a step (or a linear ramp over S seconds) of the Coulomb level (N m) and/or the
      viscous coefficient (N m s/rad)
  gyro:AXIS:TIME_S:bias=RAD_S                            a gyro bias step on x, y or z
  gyro:AXIS:TIME_S:drift=RAD_S2[,level=RAD_S]            a drift ramp (slope rad/s per s),
      held at level (signed) once reached
columns: <wheel>_speed (rad/s), <wheel>_friction (N m, f = -f_c sign(w) - f_v w + noise),
<wheel>_motor_torque (N m, auxiliary), gyro_* (rad/s), q_* (scalar last), ref_* (rad/s),
truth_* (friction levels, friction without noise, gyro labels 0/1/2 and errors, true rate).
needs the optional extra bsk: pip install -e '.[bsk]' (make demo-bus uses .venv-bsk).
example: rwa-monitor simulate basilisk --hours 2 --fault friction:rw2:3600:dry=3e-4 \\
  --fault gyro:x:5400:drift=1e-6,level=2e-4 --seed 1 -o bus.csv
'''


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``simulate basilisk`` (registering never imports the simulator)."""
    parser = subparsers.add_parser(
        'basilisk', help='high-fidelity spacecraft bus (optional extra bsk) with faults',
        description='Write telemetry of a simulated spacecraft (hub, 4 wheels in a pyramid '
                    'with Coulomb, viscous and Stribeck friction, attitude control, IMU, '
                    'star tracker) with injected faults and truth_* columns.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    length = parser.add_mutually_exclusive_group()
    length.add_argument('--hours', type=float, help='duration in hours (default 1)')
    length.add_argument('--seconds', type=float, help='duration in seconds')
    parser.add_argument('--fault', action='append', default=[], metavar='SPEC',
                        help='fault to inject (repeatable; see below)')
    parser.add_argument('--rate', type=float, default=BusConfig.rate_hz, metavar='HZ',
                        help=f'sample rate in Hz (default {BusConfig.rate_hz:g})')
    parser.add_argument('--null-speed', type=float, metavar='RAD_S',
                        help='wheel speed bias along the null space (default '
                             f'{BusConfig.null_speed:g}; 40 keeps the wheels off zero speed)')
    parser.add_argument('--guidance-scale', type=float, default=1.0, metavar='X',
                        help='factor on the guidance rate amplitudes (default 1; 0 = '
                             'inertial hold)')
    parser.add_argument('--friction-noise', type=float, metavar='NM',
                        help='std of the friction telemetry noise (default '
                             f'{BusConfig.friction_noise_std:g} N m)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('-o', '--output', required=True, metavar='PATH', help=OUTPUT_HELP)
    add_format(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Validate the arguments, simulate and write the file."""
    duration = (args.seconds if args.seconds is not None
                else 3600.0 * (args.hours if args.hours is not None else 1.0))
    faults = [parse_fault(spec) for spec in args.fault]
    options = {'rate_hz': args.rate}
    if args.friction_noise is not None:
        options['friction_noise_std'] = args.friction_noise
    if args.null_speed is not None:
        options['null_speed'] = args.null_speed
    options['ref_amplitude'] = tuple(args.guidance_scale * a for a in BusConfig.ref_amplitude)
    try:
        config = BusConfig(**options).validated()
        if not duration >= 1.0 / config.rate_hz:
            raise ValueError(f'duration must be at least one sample ({1.0 / config.rate_hz:g} '
                             f's), got {duration!r} s')
        if not 0 <= args.seed < 2 ** 32:
            raise ValueError(f'seed must be an integer in [0, 4294967295], got {args.seed}')
    except ValueError as err:
        raise ConfigError(str(err)) from None
    require()
    from rwa_monitor.sim.basilisk import BasiliskBus
    bus = BasiliskBus(config, faults, seed=args.seed)

    def progress(fraction: float) -> None:
        print(f'\r  {100 * fraction:5.1f} %', end='', file=sys.stderr, flush=True)

    tele = bus.run(duration, progress if sys.stderr.isatty() else None)
    written = write_output_telemetry(args, tele)
    print(f'wrote {written}: {len(tele)} samples at {config.rate_hz:g} Hz '
          f'({duration:g} s)')
    for fault in faults:
        print(f'  {describe(fault)}')
    return 0
