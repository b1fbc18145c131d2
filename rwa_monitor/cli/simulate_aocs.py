"""``rwa-monitor simulate aocs``: seeded gyro / star-tracker / reference-rate telemetry."""

from __future__ import annotations

import argparse
from dataclasses import replace

from rwa_monitor.cli.options import add_format, add_topics, OUTPUT_HELP, write_output_telemetry
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.sim.aocs import (AocsConfig, AXES, DEFAULT_LEVEL, DRIFT_SLOPES, FAULT_NAMES,
                                  GyroFault, named_fault, simulate_aocs)

_SLOPES = ', '.join(f'{k} {v:g}' for k, v in DRIFT_SLOPES.items())
EPILOG = f'''\
faults (on one gyro axis, from --fault-time on): drifts of slope {_SLOPES} rad/s
per s, ramping to --level (default {DEFAULT_LEVEL:g} rad/s) and then holding it;
bias: a step of --level. --slope overrides the named drift slope.
truth columns: truth_gyro_x/y/z = 0 healthy, 1 drift, 2 bias; truth_gyro_error_*,
truth_rate_* (rad/s), truth_st_valid. Star-tracker dropouts are rows of NaN in q_*.
example: rwa-monitor simulate aocs --seconds 2400 --fault slow --fault-axis x \\
  --fault-time 600 --seed 3 -o gyro.csv
'''


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``simulate aocs``."""
    parser = subparsers.add_parser(
        'aocs', help='gyro, star tracker and reference rate of a closed AOCS loop',
        description='Write seeded AOCS telemetry (gyro_*, q_*, ref_*) of a rigid '
                    'spacecraft (vsadc paper, Table 2) with an injected gyro fault and '
                    'truth_* columns.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--seconds', type=float, default=3600.0, help='duration (default 3600)')
    parser.add_argument('--fault', choices=('none', *FAULT_NAMES), default='none',
                        help='injected gyro fault (default none)')
    parser.add_argument('--fault-axis', choices=AXES, default='x', help='gyro axis (default x)')
    parser.add_argument('--fault-time', type=float, default=600.0, metavar='S',
                        help='fault start, s from the first sample (default 600)')
    parser.add_argument('--level', type=float, default=DEFAULT_LEVEL, metavar='RAD_S',
                        help=f'final fault level in rad/s (default {DEFAULT_LEVEL:g})')
    parser.add_argument('--slope', type=float, metavar='RAD_S2',
                        help='drift slope in rad/s per s (overrides the named speed)')
    parser.add_argument('--st-noise', type=float, metavar='ARCSEC',
                        help=f'star-tracker noise (default {AocsConfig.st_noise_arcsec:g})')
    parser.add_argument('--sign-flips', type=float, default=0.0, metavar='P',
                        help='probability that a star-tracker sample is output as -q')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('-o', '--output', required=True, metavar='PATH', help=OUTPUT_HELP)
    add_format(parser)
    add_topics(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Simulate and write the file."""
    try:
        fault = None
        if args.fault != 'none':
            fault = named_fault(args.fault, args.fault_axis, args.fault_time, args.level)
            if args.slope is not None:
                fault = GyroFault(fault.axis, fault.time_s, fault.level, args.slope)
        config = AocsConfig(st_sign_flip_probability=args.sign_flips)
        if args.st_noise is not None:
            config = replace(config, st_noise_arcsec=args.st_noise)
        tele = simulate_aocs(args.seconds, fault=fault, config=config, seed=args.seed)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    written = write_output_telemetry(args, tele)
    print(f'wrote {written}: {len(tele)} samples at {config.rate_hz:g} Hz')
    if fault is not None:
        kind = 'bias step' if fault.slope == 0 else f'drift {fault.slope:g} rad/s per s'
        print(f'  gyro_{AXES[fault.axis]}: {kind} from t = {fault.time_s:g} s to '
              f'{fault.level:g} rad/s')
    return 0
