"""``rwa-monitor openmct``: the operator's view, Open MCT with the rwa_monitor plugin.

Serves the page on ``--host``:``--port`` (127.0.0.1:8090) until Ctrl-C: history from a
fleet's output folder (``--fleet OUT``) and from recordings (``--recording FILE``, with
their events: ``--events`` or detected on the spot as ``rwa-monitor detect`` would), live
data with ``--live`` (the ROS topics of every namespace, through a bridge node inside the
command). The Open MCT bundle is the npm package pinned by the project's lock file
(``make openmct`` in a clone; ``rwa-monitor openmct --install`` after a pip install).
docs/usage.md, "The operator's view", walks through it.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
from typing import Any


def register(subparsers: Any) -> None:
    """Add the ``openmct`` sub-command."""
    parser = subparsers.add_parser(
        'openmct', help='the view for operators: Open MCT with fleet history, recordings '
        'and live wheels', description=__doc__.split('\n\n')[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='examples:\n  rwa-monitor openmct --fleet fleet-out\n'
               '  rwa-monitor openmct --recording run.mcap --calibration cal/calibration.yaml\n'
               '  rwa-monitor openmct --live            # then open http://127.0.0.1:8090/')
    parser.add_argument('--fleet', type=pathlib.Path, action='append', default=[],
                        metavar='OUT', help='a fleet output folder (rwa-monitor fleet -o OUT); '
                        'repeatable')
    parser.add_argument('--recording', type=pathlib.Path, action='append', default=[],
                        metavar='FILE', help='a telemetry file or recording (CSV, MCAP, '
                        'rosbag2 folder, Parquet); repeatable')
    parser.add_argument('--events', type=pathlib.Path, action='append', default=[],
                        metavar='JSON', help='events of the n-th --recording (rwa-monitor '
                        'detect -o); default: detect them at start')
    parser.add_argument('--calibration', type=pathlib.Path, metavar='YAML',
                        help='commissioning calibration of the recordings and the live '
                        'wheels: the residual is taken against its nominal models')
    parser.add_argument('--config', type=pathlib.Path, metavar='YAML',
                        help='parameters file for detecting the events of a '
                        'recording (default: the installed config/rwa_monitor.yaml)')
    parser.add_argument('--epoch', metavar='TIME',
                        help='UTC time of telemetry time 0 (ISO 8601, e.g. '
                        '2026-03-01T00:00:00Z, or Unix seconds; "unix": stamps are Unix '
                        'time); default: the epoch in the fleet summary, else none (times '
                        'shown as T+ from the start)')
    parser.add_argument('--live', action='store_true',
                        help='subscribe to the ROS topics (telemetry/wheels, telemetry/gyro, '
                        'anomalies of every namespace, /diagnostics) and push them live')
    parser.add_argument('--domain-id', type=int,
                        default=int(os.environ.get('ROS_DOMAIN_ID', '0') or 0),
                        help='ROS domain id for --live (default: $ROS_DOMAIN_ID or 0)')
    parser.add_argument('--host', default='127.0.0.1',
                        help='address to serve on (default 127.0.0.1: this machine only)')
    parser.add_argument('--port', type=int, default=8090,
                        help='TCP port (default 8090; 0: any free port)')
    parser.add_argument('--allow-origin', action='append', default=[], metavar='ORIGIN',
                        help='another page origin (scheme://host:port) allowed to open the '
                        'live WebSocket; default: only the origin of the page itself')
    parser.add_argument('--install', action='store_true',
                        help='install the pinned Open MCT bundle with npm (for a pip '
                        'install) and exit')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve the operator's view until Ctrl-C (or install the bundle with --install)."""
    from rwa_monitor.openmct import bundle
    if args.install:
        dist = bundle.install()
        print(f'installed Open MCT {bundle.pinned_version()} in {dist}')
        return 0
    from rwa_monitor.exceptions import ConfigError
    if not (args.fleet or args.recording or args.live):
        raise ConfigError('nothing to show: give --fleet OUT, --recording FILE or --live')
    if len(args.events) > len(args.recording):
        raise ConfigError('--events: one per --recording at most')
    dist = bundle.find_bundle()
    store = build_store(args)
    return serve(store, dist, args)


def build_store(args: argparse.Namespace) -> Any:
    """Return the GroundStore filled from the fleet outputs and recordings of ``args``."""
    from rwa_monitor.openmct import history
    from rwa_monitor.openmct.store import GroundStore
    epoch = 0.0 if args.epoch == 'unix' else history.parse_epoch(args.epoch)
    store = GroundStore(epoch_unix_s=epoch, live=args.live)
    for out in args.fleet:
        summary = history.load_fleet(store, out)
        found = history.fleet_epoch(summary)
        if store.epoch_unix_s is None and found is not None:
            store.epoch_unix_s = found
        print(f'fleet {out}: {len(summary.get("spacecraft") or {})} spacecraft', flush=True)
    calibration = None
    if args.calibration is not None:
        from rwa_monitor.telemetry.calibration_file import load
        calibration = load(args.calibration)
    for i, path in enumerate(args.recording):
        load_recording(store, path, args.events[i] if i < len(args.events) else None,
                       calibration, args)
    return store


def load_recording(store: Any, path: pathlib.Path, events_path: pathlib.Path | None,
                   calibration: Any, args: argparse.Namespace) -> None:
    """Add one recording and its events (read from ``events_path`` or detected)."""
    import json

    from rwa_monitor.openmct import history
    from rwa_monitor.telemetry import read_telemetry
    tele = read_telemetry(path)
    if events_path is not None:
        events = json.loads(events_path.read_text()).get('events', [])
    else:
        from rwa_monitor.cli.cmd_detect import load_config
        from rwa_monitor.pipelines import detect
        config = load_config(args.config)
        if args.calibration is not None:
            for node in ('llr_detector', 'vsadc_detector'):
                block = config.setdefault(node, {}).setdefault('ros__parameters', {})
                block['calibration_file'] = str(args.calibration)
        print(f'{path}: detecting anomalies as rwa-monitor detect does ...', flush=True)
        found, _ = detect(tele, config, args.config or 'installed parameters')
        events = [e.to_json() for e in found]
    name = path.stem if path.suffix else path.name
    history.load_recording(store, tele, name, events, calibration)
    print(f'recording {path}: {len(tele)} rows, {len(events)} events', flush=True)


def serve(store: Any, dist: pathlib.Path, args: argparse.Namespace) -> int:
    """Serve until Ctrl-C or SIGTERM; with --live run the ROS bridge beside the server."""
    import asyncio
    import signal

    from rwa_monitor.openmct.server import GroundServer

    async def main() -> None:
        try:
            server = GroundServer(store, dist, args.host, args.port, args.allow_origin)
        except OSError as err:
            from rwa_monitor.exceptions import ConfigError
            raise ConfigError(f'--host/--port: cannot serve on {args.host}:{args.port}: '
                              f'{err}') from None
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        bridge = None
        if args.live:
            from rwa_monitor.nodes.openmct_bridge import BridgeThread
            bridge = BridgeThread(store, args.domain_id, args.calibration)
            bridge.start()
        print(f"operator's view on {server.url} (Ctrl-C to stop)", flush=True)
        try:
            await stop.wait()
        finally:
            server.stop()
            if bridge is not None:
                bridge.stop()
    asyncio.run(main())
    print('stopped', file=sys.stderr)
    return 0
