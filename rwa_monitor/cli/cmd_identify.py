"""``rwa-monitor identify FILE -o DIR``: find what the friction model lacks, add it, report.

Writes DIR/report.json (DESIGN.md contract), DIR/selection.json (every step and test),
DIR/report.md, DIR/residuals_before.png, DIR/residuals_after.png and
DIR/friction_model.yaml (the refined model as a configuration snippet for the detectors);
with ``--wheel all`` one such folder per wheel and DIR/wheels.md, DIR/wheels.json (the
effects side by side, wheels whose effects differ from their siblings' flagged).

``--format coastdown`` reads the measured coast-down folder's per-revolution file
(``derived/coast_per_rev.csv``: run, body, direction, t_s, omega_rad_s) in place, one run
and body at a time, into an in-memory record with only a speed column; friction is then
J dw/dt (no drive torque during a coast), with J from the folder's pendulum swings
(telemetry/coastdown.py) unless ``--inertia`` is given. Nothing is copied or written
outside DIR.
"""

from __future__ import annotations

import argparse
import json
import pathlib

from rwa_monitor.cli.options import add_topics, INPUT_HELP
from rwa_monitor.exceptions import RwaMonitorError
from rwa_monitor.pipelines.identify_report import identify_wheel, side_by_side
from rwa_monitor.pipelines.identify_report import wheels_markdown, write_outputs
from rwa_monitor.telemetry import read_telemetry
from rwa_monitor.telemetry.atomic import write_text_atomic
from rwa_monitor.telemetry.coastdown import coastdown_folder, coastdown_runs
from rwa_monitor.telemetry.coastdown import pendulum_inertia, read_coastdown


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
    p.add_argument('--wheel', help='wheel id (default: the first wheel; "all": every wheel, '
                   'one sub-folder each, effects side by side in DIR/wheels.md); with '
                   '--format coastdown the body: drum (default) or wheel')
    p.add_argument('--inertia', type=float, help='wheel inertia J (kg m^2): estimate '
                   'friction from speed when the file has no friction column')
    p.add_argument('--torque-constant', type=float,
                   help='motor torque constant K_T (N m/A) for f = J dw/dt - K_T I')
    p.add_argument('--format', choices=('telemetry', 'coastdown'), default='telemetry')
    p.add_argument('--run', help='coast-down run name (--format coastdown); "list" lists')
    p.add_argument('--half-width', type=int, default=None,
                   help='differentiator half window in samples (default: chosen from the '
                   'data, noise against bias, when friction is derived from speed; 5 '
                   'otherwise)')
    p.add_argument('--alpha', type=float, default=1e-3,
                   help='family-wise level of the effect and jump tests (default 1e-3)')
    p.add_argument('--no-jumps', action='store_true', help='do not segment friction jumps')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the identification on one wheel (or every wheel) and write the outputs."""
    if args.format == 'coastdown':
        if not args.run or args.run == 'list':
            for name, body, n in coastdown_runs(args.file):
                print(f'{name}\t{body}\t{n}')
            return 0 if args.run == 'list' else _fail('--run NAME is needed (or --run list)')
        body = args.wheel or 'drum'
        tele = read_coastdown(args.file, args.run, body)
        inertia = args.inertia if args.inertia is not None else pendulum_inertia(
            coastdown_folder(args.file), body)
        wheels = [body]
    else:
        tele = read_telemetry(args.file, args.topics).only('wheels')
        inertia = args.inertia
        wheels = list(tele.wheels) if args.wheel == 'all' else [args.wheel]
        if args.wheel == 'all' and not wheels:
            _fail('the file has no <id>_speed column: nothing to identify')
    half_width = 'auto' if args.half_width is None else args.half_width
    title = str(args.file) + (f' [{args.run}]' if args.run else '')
    results = {}
    for wheel in wheels:
        out = args.out / wheel if len(wheels) > 1 else args.out
        try:
            selection, extra = identify_wheel(tele, wheel, inertia, args.torque_constant,
                                              half_width, args.alpha, not args.no_jumps)
        except ValueError as err:
            if isinstance(err, RwaMonitorError):
                raise
            raise RwaMonitorError(str(err)) from None
        result = write_outputs(selection, out, title=title, extra=extra)
        results[selection.data.wheel] = result
        speed = result.get('speed_rmse')
        print(f'{selection.data.wheel}: RMSE held out {result["rmse_before"]["held_out"]:.4g} '
              f'-> {result["rmse_after"]["held_out"]:.4g} N m (noise floor '
              f'{result["noise_floor"]:.4g}); effects: '
              f'{", ".join(e["name"] for e in result["effects"]) or "none"}'
              + (f'; speed RMSE {speed["before"]:.4g} -> {speed["after"]:.4g} rad/s'
                 if speed else '') + f'; report in {out}')
    if len(wheels) > 1:
        summary = side_by_side(results)
        write_text_atomic(args.out / 'wheels.json', json.dumps(summary, indent=2) + '\n')
        write_text_atomic(args.out / 'wheels.md', wheels_markdown(summary))
        print(wheels_markdown(summary))
    return 0


def _fail(message: str) -> int:
    raise RwaMonitorError(message)
