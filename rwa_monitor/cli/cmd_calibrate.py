"""``rwa-monitor calibrate FILE... -o DIR``: commissioning from fault-free telemetry.

Writes ``DIR/calibration.yaml`` (docs/contracts.md, section Calibration) and
``DIR/report.md`` with one plot per wheel. A friction change found in the data is a
warning naming the wheel and the time (``--strict``: an error, nothing written). A
low-speed band holding more than MOSTLY_UNTESTED_SHARE of a wheel's data (core/coverage.py)
is refused with a units hint (``--allow-untested``: a loud warning). Exit 3 when a wheel
had too few usable samples to be calibrated (``not_examined`` in calibration.yaml).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from rwa_monitor.cli.main import EXIT_NOT_EXAMINED
from rwa_monitor.cli.options import add_topics, read_input
from rwa_monitor.exceptions import ConfigError, NotExaminedError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` sub-command."""
    parser = subparsers.add_parser(
        'calibrate', help='commissioning: nominal models per wheel from fault-free telemetry',
        description=('Identify the nominal friction model of each wheel, its noise (with '
                     'its low-speed band) and speed range from fault-free telemetry of one '
                     'spacecraft; write DIR/calibration.yaml and DIR/report.md.'))
    parser.add_argument('files', nargs='+', type=pathlib.Path, metavar='FILE',
                        help='fault-free telemetry files of one spacecraft (CSV, Parquet, '
                             'recordings, or CCSDS space packets with --xtce and '
                             '--telemetry-map)')
    add_topics(parser)
    parser.add_argument('-o', '--output', required=True, type=pathlib.Path, metavar='DIR',
                        help='output directory')
    parser.add_argument('--strict', action='store_true',
                        help='refuse data in which a friction change is found')
    parser.add_argument('--allow-untested', action='store_true',
                        help='write a calibration whose low-speed band leaves most of the '
                             'data untested (default: refuse it, exit 2)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Read the files, calibrate, write the outputs."""
    from rwa_monitor.pipelines import calibrated
    records = [read_input(path, args) for path in args.files]
    document, warnings, arrays = calibrated.commission(records)
    for message in warnings:
        print(f'rwa-monitor calibrate: warning: {message}', file=sys.stderr)
    if args.strict and any('friction change' in m for m in warnings):
        raise ConfigError('friction changes in the calibration data (--strict): '
                          + '; '.join(warnings))
    not_examined = document['calibration'].get('not_examined', {})
    if not document['calibration']['wheels']:
        if not_examined:
            raise NotExaminedError('; '.join(f'{w}: {r}' for w, r in not_examined.items()))
        raise ConfigError('no wheel with speed and friction columns to calibrate')
    swallowed = calibrated.untested_shares(document)
    if swallowed and not args.allow_untested:
        raise ConfigError('; '.join(swallowed) + ' (--allow-untested writes it anyway)')
    for message in swallowed:
        print(f'rwa-monitor calibrate: WARNING: {message}', file=sys.stderr)
        document['calibration']['warnings'].append(message)
    for path in calibrated.write(document, arrays, args.output):
        print(f'wrote {path}')
    for wheel, reason in not_examined.items():
        print(f'not examined: {wheel}: {reason}', file=sys.stderr)
    return EXIT_NOT_EXAMINED if not_examined else 0
