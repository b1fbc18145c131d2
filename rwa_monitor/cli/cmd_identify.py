"""``rwa-monitor identify FILE -o DIR``: find what the friction model lacks, add it, report.

Writes DIR/report.json (DESIGN.md contract), DIR/selection.json (every step and test),
DIR/report.md, DIR/residuals_before.png, DIR/residuals_after.png and
DIR/friction_model.yaml (the refined model as a configuration snippet for the detectors).

``--format coastdown`` reads the measured coast-down folder's per-revolution file
(``derived/coast_per_rev.csv``: run, body, direction, t_s, omega_rad_s) in place, one run
and body at a time, into an in-memory record with only a speed column; friction is then
J dw/dt (no drive torque during a coast), with J from the folder's pendulum swings
(:func:`pendulum_inertia`) unless ``--inertia`` is given. Nothing is copied or written
outside DIR.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import pathlib

import numpy as np

from rwa_monitor.cli.options import add_topics, INPUT_HELP
from rwa_monitor.core.identify import report as rep
from rwa_monitor.core.identify.data import prepare
from rwa_monitor.core.identify.model import snippet
from rwa_monitor.core.identify.select import identify, Selection
from rwa_monitor.exceptions import RwaMonitorError, TelemetrySchemaError
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel

GRAVITY = 9.81
# Body -> (wheelInfo.csv name, pendulum file) of the coast-down folder.
PENDULUM = {'drum': ('Drum', 'inertia/Drum_I1.csv'),
            'wheel': ('Vittoria Corsa Open', 'inertia/Vittoria_Corsa_Open_I1.csv')}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``identify`` sub-command."""
    p = subparsers.add_parser(
        'identify', help='identify friction effects the model lacks; report before/after',
        description='Fit the Coulomb + viscous friction model (jumps segmented), diagnose '
                    'the residual, add named effects by forward selection validated on '
                    'held-out data, and write DIR/report.json, plots, a markdown report '
                    'and the refined model as a config snippet (friction_model.yaml).')
    p.add_argument('file', type=pathlib.Path, help=INPUT_HELP + ', or the '
                   'coast-down per-revolution CSV with --format coastdown')
    add_topics(p)
    p.add_argument('-o', '--out', type=pathlib.Path, required=True, help='output directory')
    p.add_argument('--wheel', help='wheel id (default: the first wheel); with --format '
                   'coastdown the body: drum (default) or wheel')
    p.add_argument('--inertia', type=float, help='wheel inertia J (kg m^2): estimate '
                   'friction from speed when the file has no friction column')
    p.add_argument('--torque-constant', type=float,
                   help='motor torque constant K_T (N m/A) for f = J dw/dt - K_T I')
    p.add_argument('--format', choices=('telemetry', 'coastdown'), default='telemetry')
    p.add_argument('--run', help='coast-down run name (--format coastdown); "list" lists')
    p.add_argument('--half-width', type=int, default=5,
                   help='differentiator half window in samples (default 5)')
    p.add_argument('--alpha', type=float, default=1e-3,
                   help='family-wise level of the effect and jump tests (default 1e-3)')
    p.add_argument('--no-jumps', action='store_true', help='do not segment friction jumps')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the identification on one file and write the outputs."""
    if args.format == 'coastdown':
        if not args.run or args.run == 'list':
            for name, body, n in coastdown_runs(args.file):
                print(f'{name}\t{body}\t{n}')
            return 0 if args.run == 'list' else _fail('--run NAME is needed (or --run list)')
        body = args.wheel or 'drum'
        tele = read_coastdown(args.file, args.run, body)
        inertia = args.inertia if args.inertia is not None else pendulum_inertia(
            coastdown_folder(args.file), body)
        wheel = body
    else:
        tele = read_telemetry(args.file, args.topics).only('wheels')
        inertia, wheel = args.inertia, args.wheel
    try:
        data = prepare(tele, wheel, inertia, args.torque_constant, args.half_width)
        selection = identify(data, alpha=args.alpha, jumps=not args.no_jumps)
    except ValueError as err:
        if isinstance(err, RwaMonitorError):
            raise
        raise RwaMonitorError(str(err)) from None
    result = write_outputs(selection, args.out, title=str(args.file) + (
        f' [{args.run}]' if args.run else ''))
    print(f'{data.wheel}: RMSE held out {result["rmse_before"]["held_out"]:.4g} -> '
          f'{result["rmse_after"]["held_out"]:.4g} N m (noise floor '
          f'{result["noise_floor"]:.4g}); effects: '
          f'{", ".join(e["name"] for e in result["effects"]) or "none"}; '
          f'report in {args.out}')
    return 0


def _fail(message: str) -> int:
    raise RwaMonitorError(message)


def write_outputs(selection: Selection, out: pathlib.Path, title: str = '') -> dict:
    """Write report.json, selection.json, report.md, the plots and the snippet."""
    import yaml
    out.mkdir(parents=True, exist_ok=True)
    result = rep.report(selection)
    (out / 'report.json').write_text(json.dumps(result, indent=2) + '\n')
    (out / 'selection.json').write_text(json.dumps(rep.details(selection), indent=1) + '\n')
    (out / 'report.md').write_text(rep.markdown(selection, result, title or 'telemetry'))
    (out / 'friction_model.yaml').write_text(
        '# Refined friction model from rwa-monitor identify (docs/identify.md).\n'
        + yaml.safe_dump(snippet(selection), sort_keys=False))
    rep.plot_residuals(selection, out / 'residuals_before.png', 'before')
    rep.plot_residuals(selection, out / 'residuals_after.png', 'after')
    return result


def coastdown_folder(path: os.PathLike) -> pathlib.Path:
    """Return the coast-down data folder of ``path`` (the folder or its per-rev CSV)."""
    path = pathlib.Path(path)
    folder = path if path.is_dir() else path.parent.parent
    if not (folder / 'derived' / 'coast_per_rev.csv').exists():
        raise TelemetrySchemaError(str(path), 'not a coast-down folder or its '
                                   'derived/coast_per_rev.csv')
    return folder


def _rows(path: os.PathLike) -> list[dict]:
    csv_path = coastdown_folder(path) / 'derived' / 'coast_per_rev.csv'
    with open(csv_path, newline='') as handle:
        return list(csv.DictReader(handle))


def coastdown_runs(path: os.PathLike) -> list[tuple[str, str, int]]:
    """Return (run, body, samples) of every coast in the per-revolution file."""
    counts: dict[tuple[str, str], int] = {}
    for row in _rows(path):
        key = (row['run'], row['body'])
        counts[key] = counts.get(key, 0) + 1
    return [(r, b, n) for (r, b), n in counts.items()]


def read_coastdown(path: os.PathLike, run: str, body: str = 'drum') -> Telemetry:
    """Return one coast (run, body) as an in-memory record: time and <body>_speed only."""
    rows = [r for r in _rows(path) if r['run'] == run and r['body'] == body]
    if not rows:
        raise TelemetrySchemaError(str(path), f'no coast for run {run!r} and body {body!r} '
                                   f'(see --run list)')
    time = np.array([float(r['t_s']) for r in rows])
    speed = np.array([float(r['omega_rad_s']) for r in rows])
    order = np.argsort(time)
    return Telemetry(time=time[order], wheels={body: Wheel(speed=speed[order])},
                     source=f'{path}:{run}:{body}')


def pendulum_inertia(folder: os.PathLike, body: str = 'drum') -> float:
    """Return the body's moment of inertia (kg m^2) from the folder's pendulum swings.

    A coin of mass m fixed at distance d from the axle turns the body into a physical
    pendulum of period T0 = 2 pi sqrt(I / (m g d)) at small amplitude, with
    I = J + m d^2, so J = m g d T0^2 / (4 pi^2) - m d^2. T is the median interval between
    successive passes in the pendulum file; the swing amplitude (theta_1 to theta_2 of
    wheelInfo.csv, their mean theta) lengthens the period by (1 + theta^2/16 +
    11 theta^4/3072), which is divided out.
    """
    folder = pathlib.Path(folder)
    name, swings = PENDULUM[body]
    with open(folder / 'wheelInfo.csv', newline='') as handle:
        info = next(r for r in csv.DictReader(handle) if r['name'] == name)
    with open(folder / swings, newline='') as handle:
        passes = np.array([float(r[0]) for r in csv.reader(handle) if r and r[0].strip()])
    period = float(np.median(np.diff(passes))) * 1e-6
    theta = math.radians(0.5 * (float(info['theta_1']) + float(info['theta_2'])))
    period0 = period / (1.0 + theta ** 2 / 16.0 + 11.0 * theta ** 4 / 3072.0)
    mass, dist = float(info['m_coin']), float(info['d_coin'])
    return mass * GRAVITY * dist * period0 ** 2 / (4.0 * math.pi ** 2) - mass * dist ** 2
