"""``rwa-monitor simulate friction``: seeded wheel friction telemetry with truth columns."""

from __future__ import annotations

import argparse

from rwa_monitor.cli.options import add_format, add_topics, OUTPUT_HELP, write_output_telemetry
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.sim.friction import parse_anomaly, REGIMES, simulate_friction_with_truth
from rwa_monitor.sim.profiles import PROFILES

_SI = REGIMES['si']
_DRY, _VISC, _NOISE = _SI['dry_nm'], _SI['viscous_nms'], _SI['noise_std_nm']
EPILOG = f'''\
units: time in seconds from the first sample, speed in rad/s, friction torque in N m
(--units si: nominal dry {_DRY:g} N m, viscous {_VISC:g} N m s/rad, noise std {_NOISE:g} N m)
or in noise units (--units scaled: the paper's scaling, noise std 1).

anomalies: WHEEL:KIND:TIME_S:SIZE, KIND dry (SIZE in N m) or viscous (SIZE in N m s/rad),
or WHEEL:both:TIME_S:DRY:VISCOUS. A step starts at the first sample at or after TIME_S.
example: rwa-monitor simulate friction --wheels 4 --hours 3 --rate 10 --anomaly \\
  rw2:dry:3600:+2e-4 --anomaly rw3:viscous:7200:+3e-7 --seed 0 -o wheels.csv
'''


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``simulate friction``."""
    parser = subparsers.add_parser(
        'friction', help='wheel spin rate and friction torque, model (1) with steps',
        description='Write seeded reaction-wheel telemetry (speed, friction torque) with '
                    'truth_* columns of the dry and viscous friction per sample.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--wheels', type=int, default=4, metavar='N',
                        help='number of wheels rw1..rwN (default 4)')
    length = parser.add_mutually_exclusive_group()
    length.add_argument('--hours', type=float, help='duration in hours (default 1)')
    length.add_argument('--seconds', type=float, help='duration in seconds')
    parser.add_argument('--rate', type=float, default=10.0, metavar='HZ',
                        help='sample rate in Hz (default 10)')
    parser.add_argument('--profile', choices=PROFILES, default='realistic',
                        help='spin-rate profile (default realistic; fig3..fig6: the paper '
                             'formulas, in sample index)')
    parser.add_argument('--units', choices=tuple(REGIMES), default='si',
                        help='parameter regime (default si)')
    parser.add_argument('--dry', type=float, metavar='NM', help='nominal dry friction')
    parser.add_argument('--viscous', type=float, metavar='NMS',
                        help='nominal viscous coefficient')
    parser.add_argument('--noise', type=float, metavar='NM', help='noise standard deviation')
    parser.add_argument('--anomaly', action='append', default=[], metavar='SPEC',
                        help='step anomaly WHEEL:KIND:TIME_S:SIZE[:SIZE] (repeatable)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('-o', '--output', required=True, metavar='PATH', help=OUTPUT_HELP)
    add_format(parser)
    add_topics(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Simulate and write the file; print the injected changes."""
    anomalies = [parse_anomaly(spec) for spec in args.anomaly]
    duration = (args.seconds if args.seconds is not None
                else 3600.0 * (1.0 if args.hours is None else args.hours))
    try:
        tele, changes = simulate_friction_with_truth(
            n_wheels=args.wheels, duration_s=duration, rate_hz=args.rate,
            profile=args.profile, units=args.units, dry_nm=args.dry,
            viscous_nms=args.viscous, noise_std_nm=args.noise, anomalies=anomalies,
            seed=args.seed)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    written = write_output_telemetry(args, tele)
    print(f'wrote {written}: {len(tele)} samples, wheels {", ".join(tele.wheels)}')
    for c in changes:
        print(f'  {c.wheel} {c.kind} at t = {c.time_s:g} s (row {c.index}): '
              f'dry {c.delta_dry:+g}, viscous {c.delta_viscous:+g}')
    return 0
