"""``rwa-monitor simulate fss``: wheels with friction switching systems, one status each."""

from __future__ import annotations

import argparse

from rwa_monitor.cli.options import add_format, OUTPUT_HELP, write_output_telemetry
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.sim.fss import (RATE_HZ, simulate_fss, SPEED_SCALE_RAD_S, STATUSES,
                                 TORQUE_SCALE_NM, WINDOW_SAMPLES)

EPILOG = f'''\
units: time in s, speed in rad/s, friction torque in N m (friction = -f_d sign(w) - f_v w
+ noise). One normalised unit is {TORQUE_SCALE_NM:g} N m of torque and
{SPEED_SCALE_RAD_S:g} rad/s of speed; nominal base dry friction ~1 unit, viscous ~1 unit.
statuses: {", ".join(STATUSES)} (docs/simulators.md, section FSS).
example: rwa-monitor simulate fss --status nominal,dry,fss1,fss2 --seed 0 -o fss.csv
'''


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``simulate fss``."""
    parser = subparsers.add_parser(
        'fss', help='wheel friction with switching systems (FSS paper, eq. 4-8)',
        description='Write seeded wheel telemetry whose dry friction jumps with two friction '
                    'switching systems, one status per wheel, with truth_* columns.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--status', default='nominal,nominal,nominal,nominal',
                        help='comma-separated status per wheel rw1, rw2, ... '
                             '(default four nominal wheels)')
    parser.add_argument('--samples', type=int, default=WINDOW_SAMPLES,
                        help=f'samples per wheel (default {WINDOW_SAMPLES})')
    parser.add_argument('--rate', type=float, default=RATE_HZ, metavar='HZ',
                        help=f'sample rate in Hz (default {RATE_HZ:g})')
    parser.add_argument('--profile', choices=('realistic', 'biased', 'constant'),
                        default='realistic', help='spin-rate profile (default realistic)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('-o', '--output', required=True, metavar='PATH', help=OUTPUT_HELP)
    add_format(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Simulate and write the file."""
    statuses = [s.strip() for s in args.status.split(',') if s.strip()]
    try:
        tele = simulate_fss(statuses=statuses, n_samples=args.samples, rate_hz=args.rate,
                            profile=args.profile, seed=args.seed)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    written = write_output_telemetry(args, tele)
    print(f'{len(tele)} samples of {", ".join(f"{w}={s}" for w, s in zip(tele.wheels, statuses))}'
          f' written to {written}')
    return 0
