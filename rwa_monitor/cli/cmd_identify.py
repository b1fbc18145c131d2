"""``rwa-monitor identify FILE -o DIR``: find what the friction model lacks, add it, report.

Writes DIR/report.json (DESIGN.md contract), DIR/selection.json (every step and test),
DIR/report.md, DIR/residuals_before.png, DIR/residuals_after.png and
DIR/friction_model.yaml (the refined model as a configuration snippet for the detectors);
with ``--wheel all`` one such folder per wheel and DIR/wheels.md, DIR/wheels.json (the
effects side by side, wheels whose effects differ from their siblings' flagged). The
wheels of one file are taken as identical (one design): effects are selected on their
pooled evidence (core/identify/joint.py); ``--separately`` identifies each wheel alone.

``--format coastdown`` reads the measured coast-down folder's per-revolution file
(``derived/coast_per_rev.csv``: run, body, direction, t_s, omega_rad_s) in place, one run
and body at a time, into an in-memory record with only a speed column; friction is then
J dw/dt (no drive torque during a coast), with J from the folder's pendulum swings
(telemetry/coastdown.py) unless ``--inertia`` is given. Nothing is copied or written
outside DIR. The options' defaults, bounds and help come from the ``identify`` block of
the parameter schema (core/schema.py IDENTIFY, docs/parameters.md).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from rwa_monitor.cli.main import EXIT_NOT_EXAMINED
from rwa_monitor.cli.options import add_topics, INPUT_HELP, read_input
from rwa_monitor.core.schema import AUTO, default_text, help_text, IDENTIFY, Param
from rwa_monitor.exceptions import NotExaminedError, RwaMonitorError
from rwa_monitor.telemetry.atomic import child, FolderOutput, write_text_atomic


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``identify`` sub-command."""
    p = subparsers.add_parser(
        'identify', help='identify friction effects the model lacks; report before/after',
        description='Fit the Coulomb + viscous friction model (jumps segmented), diagnose '
                    'the residual, add named effects by forward selection validated on '
                    'held-out data, and write DIR/report.json, plots, a markdown report '
                    'and the refined model as a config snippet (friction_model.yaml).',
        epilog=help_text(IDENTIFY), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', type=pathlib.Path, help=INPUT_HELP + ', or the '
                   'coast-down per-revolution CSV with --format coastdown')
    add_topics(p)
    p.add_argument('-o', '--out', type=pathlib.Path, required=True, help='output directory')
    p.add_argument('--wheel', help='wheel id (default: the first wheel; "all": every wheel, '
                   'one sub-folder each, effects side by side in DIR/wheels.md); with '
                   '--format coastdown the body: drum (default) or wheel')
    _option(p, 'inertia')
    _option(p, 'torque_constant')
    p.add_argument('--format', choices=('telemetry', 'coastdown'), default='telemetry')
    p.add_argument('--run', help='coast-down run name (--format coastdown); "list" lists')
    _option(p, 'half_width')
    _option(p, 'alpha')
    jumps = IDENTIFY['jumps']
    p.add_argument('--no-jumps', dest='jumps', action='store_false', default=jumps.default,
                   help=f'do not: {jumps.description[0].lower()}{jumps.description[1:]}')
    same = IDENTIFY['identical_wheels']
    p.add_argument('--separately', dest='identical_wheels', action='store_false',
                   default=same.default,
                   help=f'identify each wheel alone; default: {same.description}')
    p.set_defaults(func=run)


def _option(parser: argparse.ArgumentParser, name: str) -> None:
    """Add ``--<name>`` with the schema's default, bounds and meaning."""
    param = IDENTIFY[name]
    unit = f' [{param.unit}]' if param.unit else ''
    parser.add_argument('--' + name.replace('_', '-'), type=_converter(param),
                        default=param.default, metavar=name.upper(),
                        help=f'{param.description}{unit} Allowed: {param.allowed()}; default '
                             f'{default_text(param)}.')


def _converter(param: Param):
    """Return the argparse type of a schema parameter (its own check, one-line errors)."""
    def convert(text: str):
        if param.auto and text == AUTO:
            return AUTO
        try:
            return param.check(param.type(text))
        except ValueError as err:
            raise argparse.ArgumentTypeError(str(err)) from None
    return convert


def _given(value):
    """Return None for an automatic value, else the value."""
    return None if value == AUTO else value


def run(args: argparse.Namespace) -> int:
    """Run the identification on one wheel (or every wheel) and write the outputs."""
    # The identification and its report load scipy's statistics (most of a second): only
    # when the command runs, so that ``rwa-monitor --help`` starts at once.
    import numpy as np
    from rwa_monitor.pipelines.identify import examinable, identify_wheel, identify_wheels
    from rwa_monitor.pipelines.identify_report import OUTPUT_FILES
    from rwa_monitor.telemetry.coastdown import (coastdown_folder, coastdown_runs,
                                                 pendulum_inertia, read_coastdown)
    if args.format == 'coastdown':
        if not args.run or args.run == 'list':
            for name, body, n in coastdown_runs(args.file):
                print(f'{name}\t{body}\t{n}')
            return 0 if args.run == 'list' else _fail('--run NAME is needed (or --run list)')
        body = args.wheel or 'drum'
        tele = read_coastdown(args.file, args.run, body)
        inertia = _given(args.inertia) or pendulum_inertia(coastdown_folder(args.file), body)
        wheels = [body]
    else:
        tele = read_input(args.file, args).only('wheels')
        inertia = _given(args.inertia)
        wheels = list(tele.wheels) if args.wheel == 'all' else [args.wheel]
        if args.wheel == 'all' and not wheels:
            _fail('the file has no <id>_speed column: nothing to identify')
    _leave_out_implausible(tele, wheels)
    many = len(wheels) > 1
    not_examined: dict[str, str] = {}
    if many:     # a wheel with too few usable samples is left out (exit 3), the rest run
        wheels, not_examined = examinable(tele, wheels)
        if not wheels:
            raise NotExaminedError('; '.join(not_examined.values()))
    title = str(args.file) + (f' [{args.run}]' if args.run else '')
    results = {}
    agreement = None
    output = FolderOutput(args.out, OUTPUT_FILES, 'identify outputs')   # refused before the work
    try:
        if len(wheels) > 1:
            found, agreement = identify_wheels(tele, wheels, args.identical_wheels, inertia,
                                               _given(args.torque_constant), args.half_width,
                                               args.alpha, args.jumps)
        else:
            selection, extra = identify_wheel(tele, wheels[0], inertia,
                                              _given(args.torque_constant), args.half_width,
                                              args.alpha, args.jumps)
            found = {selection.data.wheel: (selection, extra)}
    except ValueError as err:
        if isinstance(err, RwaMonitorError):
            raise
        if isinstance(err, np.linalg.LinAlgError):    # said only "Singular matrix"
            raise RwaMonitorError(
                f'{", ".join(wheels)}: the least-squares fit has no unique solution ({err}): '
                'the speed and friction columns do not determine the friction model; '
                'check them and their units') from None
        raise RwaMonitorError(str(err)) from None
    with output as work:
        _write(args, found, many, title, work, results, agreement, not_examined)
    for reason in not_examined.values():
        print(f'rwa-monitor identify: not examined: {reason}', file=sys.stderr)
    return EXIT_NOT_EXAMINED if not_examined else 0


def _write(args, found, many, title, work, results, agreement, not_examined) -> None:
    """Write every output into ``work`` (swapped onto ``args.out`` by the caller)."""
    from rwa_monitor.pipelines.identify_report import side_by_side, wheels_markdown
    from rwa_monitor.pipelines.identify_report import write_outputs
    for wheel, (selection, extra) in found.items():
        out, shown = ((child(work, wheel), child(args.out, wheel)) if many
                      else (work, args.out))
        result = write_outputs(selection, out, title=title, extra=extra)
        results[selection.data.wheel] = result
        speed = result.get('speed_rmse')
        print(f'{selection.data.wheel}: RMSE held out {result["rmse_before"]["held_out"]:.4g} '
              f'-> {result["rmse_after"]["held_out"]:.4g} N m (noise floor '
              f'{result["noise_floor"]:.4g}); effects: '
              f'{", ".join(e["name"] for e in result["effects"]) or "none"}'
              + (f'; speed RMSE {speed["before"]:.4g} -> {speed["after"]:.4g} rad/s'
                 if speed else '') + f'; report in {shown}')
        from rwa_monitor.core.identify.report import reversals
        note = reversals(selection)['note']
        if note:
            print(f'{selection.data.wheel}: note: {note}')
    if many:
        summary = side_by_side(results, agreement)
        if not_examined:
            summary['not_examined'] = not_examined
        write_text_atomic(work / 'wheels.json', json.dumps(summary, indent=2) + '\n')
        write_text_atomic(work / 'wheels.md', wheels_markdown(summary))
        print(wheels_markdown(summary))


def _leave_out_implausible(tele, wheels: list[str]) -> None:
    """Drop values beyond the detectors' plausibility limits; refuse a column of only those.

    The limits are the LLR detector's ``max_abs_speed`` and ``max_abs_friction``
    (core/schema.py), as in ``detect``, ``diagnose`` and ``calibrate``: a value no wheel
    can produce (1e300 N m) is left out like a NaN (counted by the identification as a
    non-finite row; a note says how many), and a column holding nothing else is refused
    naming it (it used to end in "Singular matrix" or an infinite RMSE).
    """
    import numpy as np
    from rwa_monitor.core.schema import LLR
    for wheel in (tele.wheels if wheels == [None] else wheels):   # None: the file's only one
        channels = tele.wheels.get(wheel)
        if channels is None:
            continue        # an unknown wheel: the identification names it
        for kind, unit in (('speed', 'rad/s'), ('friction', 'N m')):
            values = getattr(channels, kind, None)
            if values is None:
                continue
            limit = LLR[f'max_abs_{kind}'].default
            values = np.asarray(values, dtype=float)
            finite = np.isfinite(values)
            with np.errstate(invalid='ignore'):
                beyond = finite & ~(np.abs(values) < limit)
            count = int(np.count_nonzero(beyond))
            if not count:
                continue
            column = f'{wheel}_{kind}'
            top = float(np.max(np.abs(values[beyond])))
            if count == np.count_nonzero(finite):
                raise RwaMonitorError(
                    f'{column}: every value is at or beyond {limit:g} {unit} (up to {top:g}): '
                    f'not physical (the detectors ignore |{kind}| >= {limit:g} {unit}); '
                    'check the column and its unit')
            setattr(channels, kind, np.where(beyond, np.nan, values))
            print(f'rwa-monitor identify: {column}: {count} of {values.size} values at or '
                  f'beyond {limit:g} {unit} (up to {top:g}) left out as not physical',
                  file=sys.stderr)


def _fail(message: str) -> int:
    raise RwaMonitorError(message)
