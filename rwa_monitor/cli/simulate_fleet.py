"""``rwa-monitor simulate fleet``: a seeded fleet archive with truth (docs/fleet.md)."""

from __future__ import annotations

import argparse
import datetime as dt
import pathlib
import sys
import time

from rwa_monitor.cli.options import FORMATS
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.progress import Progress
from rwa_monitor.sim.fleet import pass_telemetry, plan_fleet, write_fleet
from rwa_monitor.telemetry.atomic import write_text_atomic

EPOCH = '2026-01-01T00:00:00Z'
EPILOG = '''\
layout: DIR/<spacecraft>/<pass id>.csv (telemetry schema, random pass ids: names do not sort
in time), DIR/truth.json (per spacecraft and wheel: base levels, wear rate, faults), and with
--calibrate DIR/<spacecraft>/calibration.yaml from the spacecraft's commissioning passes (the
first two days', fault-free); DIR/archive.yaml gives time 0 as a calendar time (--epoch).
--format ccsds: passes DIR/<spacecraft>/<pass id>.bin of CCSDS space packets, with
telemetry.xml (XTCE) and telemetry_map.yaml beside them.
example: rwa-monitor simulate fleet -o archive --spacecraft 20 --days 7 --rate 10 --seed 0
'''


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``simulate fleet``."""
    parser = subparsers.add_parser(
        'fleet', help='a fleet archive: spacecraft folders of passes, wear, faults, truth',
        description='Write a seeded archive of downlink passes of several spacecraft (model '
                    '(1) friction, realistic spin profile) with per-wheel differences, slow '
                    'dry-friction wear and step faults, and truth.json.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('-o', '--output', required=True, type=pathlib.Path, metavar='DIR',
                        help='archive folder (must not exist or be empty)')
    parser.add_argument('--spacecraft', type=int, default=4, metavar='N',
                        help='number of spacecraft (default 4)')
    parser.add_argument('--days', type=float, default=7.0, metavar='D',
                        help='archive length in days (default 7)')
    parser.add_argument('--rate', type=float, default=10.0, metavar='HZ',
                        help='sample rate in Hz (default 10)')
    parser.add_argument('--passes-per-day', type=int, default=6, metavar='P',
                        help='downlink passes per day (default 6)')
    parser.add_argument('--pass-minutes', type=float, default=10.0, metavar='M',
                        help='length of a pass in minutes (default 10)')
    parser.add_argument('--wheels', type=int, default=4, metavar='W',
                        help='wheels per spacecraft (default 4)')
    parser.add_argument('--wear-fraction', type=float, default=0.25, metavar='F',
                        help='fraction of wheels whose dry friction wears (default 0.25)')
    parser.add_argument('--faults', type=int, metavar='K',
                        help='step faults in the fleet (default one per 5 spacecraft)')
    parser.add_argument('--calibrate', action='store_true',
                        help='commission each spacecraft on its commissioning passes: '
                             'write calibration.yaml into its folder')
    parser.add_argument('--commissioning-passes', type=int, metavar='C',
                        help='first passes kept fault-free and used by --calibrate '
                             '(default: two days of passes)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--epoch', default=EPOCH, metavar='UTC',
                        help=f'calendar time of time 0, written to DIR/archive.yaml '
                             f'(epoch_utc; default {EPOCH})')
    parser.add_argument('--format', choices=FORMATS, default='auto',
                        help='passes as CSV (auto, default) or as CCSDS space packets (ccsds)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Plan, write the passes and truth.json, optionally calibrate; print a summary."""
    out = args.output
    epoch = _epoch(args.epoch)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ConfigError(f'{out}: exists and is not an empty folder')
    try:
        plan = plan_fleet(spacecraft=args.spacecraft, days=args.days, rate_hz=args.rate,
                          passes_per_day=args.passes_per_day,
                          pass_s=60.0 * args.pass_minutes, wheels=args.wheels,
                          wear_fraction=args.wear_fraction, faults=args.faults,
                          commissioning_passes=args.commissioning_passes, seed=args.seed)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    start = time.perf_counter()
    n_pass = sum(len(c.passes) for c in plan.spacecraft)
    progress = Progress(f'rwa-monitor simulate fleet: passes written to {out}', n_pass)
    suffix = '.bin' if args.format == 'ccsds' else '.csv'
    files = write_fleet(out, plan, suffix, _write_packet_pass if suffix == '.bin' else None,
                        progress.update)
    progress.finish()
    write_text_atomic(out / 'archive.yaml', f'# rwa-monitor simulate fleet, seed {args.seed}\n'
                      f'epoch_utc: {epoch}\n')
    if args.calibrate:
        progress = Progress('rwa-monitor simulate fleet: spacecraft commissioned',
                            len(plan.spacecraft))
        for done, craft in enumerate(plan.spacecraft):
            folder = out / craft.name
            records = []
            for i in range(plan.commissioning_passes):
                records.append(pass_telemetry(plan, craft, i))
                records[-1].source = str(folder / f'{craft.passes[i].pass_id}{suffix}')
            write_calibration(folder / 'calibration.yaml', records)
            progress.update(done + 1, craft.name)
        progress.finish()
    samples = n_pass * int(plan.pass_s * plan.rate_hz + 1e-9)
    faults = sum(len(c.faults) for c in plan.spacecraft)
    wearing = sum(r > 0 for c in plan.spacecraft for r in c.wear_per_day.values())
    print(f'wrote {out}: {len(plan.spacecraft)} spacecraft, {n_pass} passes, {samples} '
          f'samples per wheel, {wearing} wearing wheels, {faults} faults, '
          f'{len(files) - 1} files in {time.perf_counter() - start:.1f} s; truth in '
          f'{out / "truth.json"}')
    return 0


def _epoch(text: str) -> str:
    """Return the epoch as ISO 8601 UTC (ConfigError if it is not one)."""
    try:
        moment = dt.datetime.fromisoformat(text.replace('Z', '+00:00'))
    except ValueError:
        raise ConfigError(f'--epoch {text!r}: not an ISO 8601 time such as {EPOCH}') from None
    if moment.tzinfo is None:
        raise ConfigError(f'--epoch {text!r}: give the time zone (Z for UTC)')
    return moment.astimezone(dt.timezone.utc).isoformat().replace('+00:00', 'Z')


def _write_packet_pass(path: pathlib.Path, tele) -> None:
    """Write one pass as packets; the folder's telemetry.xml and map describe every pass."""
    from rwa_monitor.telemetry import ARCHIVE_MAP, ARCHIVE_XTCE
    from rwa_monitor.telemetry.ccsds_write import write_packets
    write_packets(path, tele, path.parent / ARCHIVE_XTCE, path.parent / ARCHIVE_MAP)


def write_calibration(path: pathlib.Path, records: list) -> None:
    """Commission one spacecraft on ``records`` and write only its calibration.yaml."""
    import yaml
    from rwa_monitor.core.identify.model import plain
    from rwa_monitor.pipelines import calibrated
    document, warnings, _ = calibrated.commission(records)
    for message in warnings:
        print(f'rwa-monitor simulate fleet: {path.parent.name}: warning: {message}',
              file=sys.stderr)
    write_text_atomic(path, yaml.safe_dump(plain(document), sort_keys=False))
