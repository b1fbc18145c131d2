"""``rwa-monitor diagnose FILE -o OUT.json``: FSS window diagnosis of every wheel."""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np

from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.telemetry import read_telemetry

NODE_BLOCK = 'fss_diagnoser'


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``diagnose``."""
    parser = subparsers.add_parser(
        'diagnose', help='window diagnosis of every wheel (FSS paper: dry, viscous, fss1, '
                         'fss2)',
        description='Run the four-stage FSS window diagnoser on the whole file, per wheel, '
                    'and write the JSON of DESIGN.md (docs/fss.md).')
    parser.add_argument('file', help='telemetry file (.csv or .mcap)')
    parser.add_argument('-o', '--output', required=True, help='output JSON file')
    parser.add_argument('--model', default=None,
                        help='classifier model (default: the shipped one)')
    parser.add_argument('--params-file', default=None,
                        help='YAML with a fss_diagnoser block (default config/rwa_monitor.yaml)')
    parser.add_argument('--calibration', default=None, metavar='YAML',
                        help='commissioning calibration (rwa-monitor calibrate): judge each '
                             'wheel relative to its nominal; a window the nominal and the '
                             'known anomalies cannot explain is reported "unknown"')
    parser.add_argument('--last', type=int, default=None, metavar='N',
                        help='diagnose only the last N samples of each wheel')
    parser.set_defaults(func=run)


def load_params(path: str | None) -> dict:
    """Return the fss_diagnoser parameters of a YAML params file (empty if none)."""
    import yaml

    from rwa_monitor.paths import config_file
    try:
        file = pathlib.Path(path) if path else config_file()
    except FileNotFoundError:
        return {}
    try:
        data = yaml.safe_load(file.read_text()) or {}
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'{file}: {err}') from None
    block = data.get(NODE_BLOCK, {}) if isinstance(data, dict) else {}
    params = dict((block or {}).get('ros__parameters', {}))
    if 'wglr_window' in params:  # the node's name for the wGLR half-window
        params['window'] = params.pop('wglr_window')
    return params


def run(args: argparse.Namespace) -> int:
    """Diagnose each wheel and write the JSON."""
    from rwa_monitor.core.fss.pipeline import diagnose, FssConfig, load_model
    try:
        params = load_params(args.params_file)
        config = FssConfig.from_dict(params)
        model = load_model(args.model or params.get('model') or None)
    except (ValueError, OSError) as err:
        raise ConfigError(str(err)) from None
    tele = read_telemetry(args.file)
    cal = None
    if args.calibration:
        from rwa_monitor.core.calibrate import check_wheels
        from rwa_monitor.pipelines import calibrated
        cal = calibrated.load(args.calibration)
        check_wheels(cal, [w for w, ch in tele.wheels.items() if ch.friction is not None],
                     args.calibration)
    wheels = {}
    for wheel_id, wheel in tele.wheels.items():
        if wheel.friction is None:
            continue
        sl = slice(-args.last, None) if args.last else slice(None)
        speed, friction, time = wheel.speed[sl], wheel.friction[sl], tele.time[sl]
        if np.count_nonzero(np.isfinite(speed) & np.isfinite(friction)) < 4 * config.window:
            wheels[wheel_id] = {'error': 'too few finite samples for a diagnosis'}
            continue
        if cal is not None:
            wheels[wheel_id] = calibrated.diagnose_wheel(cal['wheels'][wheel_id], time, speed,
                                                         friction, model, config)
        else:
            wheels[wheel_id] = diagnose(speed, friction, time, model, config)
    if not wheels:
        raise RwaMonitorError(f'{args.file}: no wheel with both speed and friction columns')
    with open(args.output, 'w') as handle:
        json.dump({'wheels': wheels}, handle, indent=1)
        handle.write('\n')
    for wheel_id, result in wheels.items():
        flags = result.get('anomalies', {})
        found = [k for k, v in flags.items() if v] or ['none']
        status = f' ({result["status"]})' if 'status' in result else ''
        print(f'{wheel_id}: anomalies {", ".join(found)}{status}')
    return 0
