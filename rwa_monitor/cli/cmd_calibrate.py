"""``rwa-monitor calibrate FILE... -o DIR``: commissioning from fault-free telemetry.

Writes ``DIR/calibration.yaml`` (docs/contracts.md, section Calibration) and
``DIR/report.md`` with one plot per wheel. A friction change found in the data is a
warning naming the wheel and the time (``--strict``: an error, nothing written).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry import read_telemetry


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` sub-command."""
    parser = subparsers.add_parser(
        'calibrate', help='commissioning: nominal models per wheel from fault-free telemetry',
        description=('Identify the nominal friction model of each wheel, its noise (with '
                     'its low-speed band) and speed range from fault-free telemetry of one '
                     'spacecraft; write DIR/calibration.yaml and DIR/report.md.'))
    parser.add_argument('files', nargs='+', type=pathlib.Path, metavar='FILE',
                        help='fault-free telemetry files (.csv or .mcap) of one spacecraft')
    parser.add_argument('-o', '--output', required=True, type=pathlib.Path, metavar='DIR',
                        help='output directory')
    parser.add_argument('--strict', action='store_true',
                        help='refuse data in which a friction change is found')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Read the files, calibrate, write the outputs."""
    from rwa_monitor.pipelines import calibrated
    records = [read_telemetry(path) for path in args.files]
    document, warnings, arrays = calibrated.commission(records)
    for message in warnings:
        print(f'rwa-monitor calibrate: warning: {message}', file=sys.stderr)
    if args.strict and any('friction change' in m for m in warnings):
        raise ConfigError('friction changes in the calibration data (--strict): '
                          + '; '.join(warnings))
    if not document['calibration']['wheels']:
        raise ConfigError('no wheel with speed and friction columns to calibrate')
    for path in calibrated.write(document, arrays, args.output):
        print(f'wrote {path}')
    return 0
