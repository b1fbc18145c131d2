"""``rwa-monitor diagnose FILE -o OUT.json``: FSS window diagnosis of every wheel.

Exit codes (docs/usage.md): 0 every wheel diagnosed; 3 a wheel was not examined (no
friction column, too few tested samples, or most of its window not tested: ``status``
``unknown``; the JSON's ``not_examined`` says which and why); 2 error.
"""

from __future__ import annotations

import argparse
import sys

from rwa_monitor.cli.cmd_detect import verdict_text
from rwa_monitor.cli.main import EXIT_NOT_EXAMINED
from rwa_monitor.cli.options import add_topics, INPUT_HELP, read_input
from rwa_monitor.cli.output import (check_output, json_text, quiet_broken_pipe, STDOUT,
                                    write_output)
from rwa_monitor.core.schema import FSS, fss_config, help_text
from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.telemetry.parameters_file import load_block


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``diagnose``."""
    parser = subparsers.add_parser(
        'diagnose', help='window diagnosis of every wheel (FSS paper: dry, viscous, fss1, '
                         'fss2)',
        description='Run the four-stage FSS window diagnoser on the whole file, per wheel, '
                    'and write the JSON of DESIGN.md (docs/fss.md).',
        epilog=help_text(FSS), formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('file', help=INPUT_HELP)
    add_topics(parser)
    parser.add_argument('-o', '--output', required=True,
                        help='output JSON file, written atomically (- = standard output; an '
                             'input file is refused)')
    parser.add_argument('--model', default=None,
                        help='classifier model (default: the shipped one)')
    parser.add_argument('--params-file', default=None,
                        help='parameters file with a fss_diagnoser block (default: the '
                             'installed config/rwa_monitor.yaml)')
    parser.add_argument('--calibration', default=None, metavar='YAML',
                        help='commissioning calibration (rwa-monitor calibrate): judge each '
                             'wheel relative to its nominal; a window the nominal and the '
                             'known anomalies cannot explain is reported "unknown" (default: '
                             'calibration_file of the parameters)')
    parser.add_argument('--last', type=int, default=None, metavar='N',
                        help='diagnose only the last N samples of each wheel')
    parser.set_defaults(func=run)


def load_params(path: str | None) -> dict:
    """Return the checked fss_diagnoser parameters of a parameters file (or the defaults)."""
    return load_block(path, FSS)


def run(args: argparse.Namespace) -> int:
    """Diagnose each wheel and write the JSON."""
    from rwa_monitor.core.fss.events import window_events
    from rwa_monitor.core.fss.pipeline import diagnose
    from rwa_monitor.telemetry.fss_model import load_model
    check_output(args.output, args.file, args.params_file, args.model)
    params = load_params(args.params_file)
    try:
        config = fss_config(params)
        model = load_model(args.model or params['model'] or None)
    except (ValueError, OSError) as err:
        raise ConfigError(str(err)) from None
    tele = read_input(args.file, args).only('wheels')
    cal_path = args.calibration or params.get('calibration_file') or ''
    cal = None
    if cal_path:
        from rwa_monitor.core.calibrate import check_wheels, diagnose_fss
        from rwa_monitor.telemetry.calibration_file import load
        cal = load(cal_path)
        check_wheels(cal, [w for w, ch in tele.wheels.items() if ch.friction is not None],
                     cal_path)
    wheels = {}
    events = []
    not_examined = {}
    for wheel_id, wheel in tele.wheels.items():
        if wheel.friction is None:
            not_examined[wheel_id] = 'no friction column (the diagnosis needs one)'
            continue
        sl = slice(-args.last, None) if args.last else slice(None)
        speed, friction, time = wheel.speed[sl], wheel.friction[sl], tele.time[sl]
        if cal is not None:
            wheels[wheel_id] = diagnose_fss(cal['wheels'][wheel_id], time, speed, friction,
                                            model, config)
        else:
            wheels[wheel_id] = diagnose(speed, friction, time, model, config)
        first = range(len(tele.time))[sl].start
        events.extend(e.to_json() for e in window_events(wheel_id, wheels[wheel_id], time, first))
    if not wheels:
        raise RwaMonitorError(f'{args.file}: no wheel with both speed and friction columns')
    # A window mostly not tested is unknown with its counts (core/fss/pipeline.py).
    not_examined.update({w: verdict_text(r['coverage']) for w, r in wheels.items()
                         if 'coverage' in r})
    document = {'wheels': wheels, 'events': events, 'not_examined': not_examined}
    with quiet_broken_pipe():
        write_output(args.output, json_text(document, indent=1))
        out = sys.stderr if args.output == STDOUT else sys.stdout
        for wheel_id, result in wheels.items():
            if wheel_id in not_examined:
                print(f'{wheel_id}: not examined ({not_examined[wheel_id]})', file=out)
                continue
            flags = result.get('anomalies', {})
            found = [k for k, v in flags.items() if v] or ['none']
            status = f' ({result["status"]})' if 'status' in result else ''
            print(f'{wheel_id}: anomalies {", ".join(found)}{status}', file=out)
    return EXIT_NOT_EXAMINED if not_examined else 0
