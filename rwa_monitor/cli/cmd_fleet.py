"""``rwa-monitor fleet ARCHIVE -o OUT``: a constellation's archive on Dask distributed.

ARCHIVE/<spacecraft>/ holds passes (CSV, Parquet, rosbag2, .mcap, .db3) and optionally
calibration.yaml. Each spacecraft's passes run in time order through detectors that
carry their state from pass to pass: its events are those of ``rwa-monitor detect`` on
its passes joined into one file (rwa_monitor/fleet). Exit codes as ``detect``: 0 all
examined, nothing found; 1 anomaly; 3 nothing found but something (a pass, a component)
not examined; 2 error (bad parameters, a refused state, an unwritable output).
"""

from __future__ import annotations

import argparse
import pathlib

from rwa_monitor.cli.cmd_detect import EXIT_ANOMALY, EXIT_NOT_EXAMINED, EXIT_NOTHING_FOUND
from rwa_monitor.exceptions import OutputError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fleet`` sub-command."""
    parser = subparsers.add_parser(
        'fleet', help='run the detectors over a fleet archive on Dask (events, trend)',
        description='Run every spacecraft of ARCHIVE (one folder each: passes and an '
                    'optional calibration.yaml) through detectors that carry their state '
                    'across passes; write events.json/.parquet, summary.json, '
                    'trend.parquet and report.html into OUT.',
        epilog='exit codes: 0 examined, nothing found; 1 anomaly found; 3 nothing found '
               'but not everything could be examined; 2 error')
    parser.add_argument('archive', type=pathlib.Path, metavar='ARCHIVE',
                        help='folder of spacecraft folders')
    parser.add_argument('-o', '--output', type=pathlib.Path, required=True, metavar='OUT',
                        help='output folder (created; its five files are replaced)')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('--workers', type=int, default=2, metavar='N',
                       help='worker processes of the local Dask cluster (default 2)')
    where.add_argument('--scheduler', metavar='tcp://HOST:PORT',
                       help='an existing Dask scheduler (dask scheduler / dask worker)')
    parser.add_argument('--config', type=pathlib.Path, metavar='YAML',
                        help='parameters file in the node format (default: the installed '
                             'config/rwa_monitor.yaml)')
    parser.add_argument('--state', type=pathlib.Path, metavar='DIR',
                        help='detector state folder: continue from it and update it (a '
                             'state of another version or configuration is refused)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the fleet and write OUT; return the exit code."""
    from rwa_monitor.fleet.engine import run_archive
    from rwa_monitor.fleet.outputs import write_outputs
    archive = args.archive.resolve()
    for name, path in (('output', args.output), ('state', args.state)):
        if path is not None and archive in (path.resolve(), *path.resolve().parents):
            raise OutputError(f'{path}: the {name} folder must be outside the archive '
                              f'{args.archive} (it would be read as a spacecraft)')
    result = run_archive(args.archive, workers=args.workers, scheduler=args.scheduler,
                         config=args.config, state_dir=args.state, progress=True,
                         commit=False)
    write_outputs(args.output, result)
    result.commit()          # the state moves on only once this run's outputs are written
    crafts = result.summary['spacecraft']
    print(f'wrote {args.output}: {len(result.events)} events from {len(crafts)} spacecraft '
          f'in {result.timings["wall_s"]:.1f} s')
    for craft, entry in crafts.items():
        for what, why in entry['not_examined'].items():
            print(f'not examined: {craft} {what}: {why}')
    if result.anomaly:
        return EXIT_ANOMALY
    return EXIT_NOT_EXAMINED if result.incomplete else EXIT_NOTHING_FOUND
