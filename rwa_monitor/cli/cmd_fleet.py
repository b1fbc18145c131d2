"""``rwa-monitor fleet ARCHIVE -o OUT``: a constellation's archive on Dask distributed.

ARCHIVE/<spacecraft>/ holds passes (CSV, Parquet, rosbag2, .mcap, .db3) and optionally
calibration.yaml; ARCHIVE/archive.yaml may give the archive's epoch (``epoch_utc``).
Each spacecraft's passes run in time order through runners that carry their state from
pass to pass: its events are those of ``rwa-monitor detect`` on its passes joined into
one file (rwa_monitor/fleet). With ``--state``, a run continues from the last one: daily
runs add up to one run over the whole archive. Exit codes as ``detect``, for what this run
found: 0 all examined, nothing found (also: no new passes); 1 anomaly found by this run;
3 nothing found but something (a pass, a component) not examined; 2 error (bad
parameters, a refused state, an unwritable output).
"""

from __future__ import annotations

import argparse
import contextlib
import pathlib
import sys

from rwa_monitor.cli.main import EXIT_ANOMALY, EXIT_NOT_EXAMINED, EXIT_NOTHING_FOUND
from rwa_monitor.exceptions import OutputError

MEANING = {EXIT_NOTHING_FOUND: 'everything examined, no new anomaly',
           EXIT_ANOMALY: 'this run found anomalies',
           EXIT_NOT_EXAMINED: 'no anomaly, but not everything could be examined'}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fleet`` sub-command."""
    parser = subparsers.add_parser(
        'fleet', help='run the detectors over a fleet archive on Dask (events, trend)',
        description='Run every spacecraft of ARCHIVE (one folder each: passes and an '
                    'optional calibration.yaml) through detectors that carry their state '
                    'across passes; write events.json/.parquet, summary.json, '
                    'trend.parquet and report.html into OUT.',
        epilog='exit codes, for what this run found: 0 examined, nothing found (or no new '
               'passes); 1 anomaly found; 3 nothing found but not everything could be '
               'examined; 2 error')
    parser.add_argument('archive', type=pathlib.Path, metavar='ARCHIVE',
                        help='folder of spacecraft folders')
    parser.add_argument('-o', '--output', type=pathlib.Path, required=True, metavar='OUT',
                        help='output folder (created; an earlier fleet output folder is '
                             'replaced as a whole, anything else refused)')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('--workers', type=int, default=2, metavar='N',
                       help='worker processes of the local Dask cluster (default 2)')
    where.add_argument('--scheduler', metavar='tcp://HOST:PORT',
                       help='an existing Dask scheduler (dask scheduler / dask worker)')
    parser.add_argument('--config', type=pathlib.Path, metavar='YAML',
                        help='parameters file in the node format (default: the installed '
                             "config/fleet.yaml, the fleet's operating point; a value absent "
                             "from the file is the schema's default)")
    parser.add_argument('--state', type=pathlib.Path, metavar='DIR',
                        help='state folder: continue from the last run and move it on (a '
                             'state of another version or configuration is refused)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the fleet and write OUT; return the exit code."""
    from rwa_monitor.fleet.cluster import ClusterStart, start_fork_server
    if not args.scheduler and args.workers >= 1:
        start_fork_server()    # first: it loads the workers' modules while this one loads
    from rwa_monitor.fleet import outputs, state
    archive = args.archive.resolve()
    for name, path in (('output', args.output), ('state', args.state)):
        if path is not None and archive in (path.resolve(), *path.resolve().parents):
            raise OutputError(f'{path}: the {name} folder must be outside the archive '
                              f'{args.archive} (it would be read as a spacecraft)')
    state.check_folders(args.state, args.output)
    outputs.check_output(args.output)
    # The cluster starts while the engine is imported and the state read, and closes
    # while the outputs are written (fleet/cluster.py).
    with state.locked(args.state) if args.state else contextlib.nullcontext(), \
            ClusterStart(args.workers, args.scheduler) as cluster:
        from rwa_monitor.fleet.engine import run_archive
        result = run_archive(args.archive, client=cluster, config=args.config,
                             state_dir=args.state, log=sys.stderr)
        outputs.write_outputs(args.output, result)
        result.commit()      # the state moves on only once this run's outputs are written
    return report(args.output, result)


def report(out: pathlib.Path, result) -> int:
    """Print what the run did and found; return the exit code."""
    crafts = result.summary['spacecraft']
    if result.new_passes == 0:
        print(f'no new passes; {result.already_processed} already processed')
    else:
        print(f'wrote {out}: {result.summary["new_events"]} new events from '
              f'{result.new_passes} new passes of {len(crafts)} spacecraft in '
              f'{result.timings["wall_s"]:.1f} s ({_history(result.summary)})')
    point = result.summary['operating_point']
    print(f'changes tested at false-alarm rate r = {point["false_alarm_rate"]:g} per test '
          f'(parameters: {result.summary["config"]})')
    bare = [craft for craft, entry in crafts.items() if not entry['calibration']]
    if bare:
        print('not calibrated (no calibration.yaml: friction tested without a nominal '
              f'model, trends in absolute levels): {", ".join(bare)}')
    for craft, entry in crafts.items():
        for what, why in entry['not_examined'].items():
            print(f'not examined: {craft} {what}: {why}')
        for name, why in entry['overlapping'].items():
            print(f'rows dropped: {craft} pass {name}: {why}')
    flagged = [f'{craft} {name} ({block["health"]})' for craft, entry in crafts.items()
               for name, block in entry['components'].items()
               if any(kind != 'healthy' for kind in block['by_kind'])]
    if result.anomaly:
        code = EXIT_ANOMALY
    elif result.incomplete:
        code = EXIT_NOT_EXAMINED
    else:
        code = EXIT_NOTHING_FOUND
    print(f'components with events: {", ".join(flagged) or "none"}; exit {code}: '
          f'{MEANING[code]}')
    return code


def _history(summary: dict) -> str:
    """Return what the cumulative history holds: current events, and superseded ones."""
    text = f'{summary["events"]} current events in the history'
    if summary.get('superseded'):
        text += f', {summary["superseded"]} superseded by later revisions'
    return text
