"""``rwa-monitor detect FILE``: run every detector whose input columns the file has.

Each module of :mod:`rwa_monitor.pipelines` whose ``applies(tele)`` is true runs with the
parameters of its node (its ``SCHEMA``): the ``/**`` block of the YAML file overlaid with
the node's block, read and checked by :mod:`rwa_monitor.telemetry.parameters_file`, so
one file configures the nodes and the command line alike. A pipeline with
``run_with_summary`` also reports per-component facts (samples, rejected-sample counters,
run time); events are sorted by estimated change time. A bad parameter value is a
ConfigError naming the pipeline and the parameter (exit code 2).

Exit codes (docs/usage.md): 0 every component of the file was examined and nothing was
found; 1 an anomaly was found; 3 nothing found, but not everything could be examined (no
detector could run, a wheel has no friction column, or a component had too few usable
samples or never became ready, or most of its samples were rejected or untested: the
summary's ``not_examined`` says which and why); 2 error. The
summary's ``detectors`` lists each detector as ``ran`` or the reason it could not.
Outputs never destroy data (:mod:`rwa_monitor.cli.output`).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Any

from rwa_monitor import pipelines
from rwa_monitor.cli.main import EXIT_ANOMALY, EXIT_NOT_EXAMINED, EXIT_NOTHING_FOUND
from rwa_monitor.cli.options import add_topics, INPUT_HELP, read_input
from rwa_monitor.cli.output import (check_output, json_text, quiet_broken_pipe, STDOUT,
                                    write_output)
from rwa_monitor.cli.readable import number_text, p_value_text
from rwa_monitor.core.coverage import EXAMINED, UNKNOWN
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import help_text, LLR, SCHEMAS, VSADC
from rwa_monitor.pipelines import detect
from rwa_monitor.telemetry.parameters_file import block_values, read_parameters_file


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``detect`` sub-command."""
    parser = subparsers.add_parser(
        'detect', help='detect anomalies in a telemetry file (events JSON)',
        description='Run every detector whose input columns the telemetry file has; '
                    'write the events JSON ({"events": [...], "summary": {...}}) or print '
                    'a table. Times are seconds of the file, torques N m.',
        epilog=f'{help_text(LLR)}\n{help_text(VSADC)}',
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('file', type=pathlib.Path, help=INPUT_HELP)
    add_topics(parser)
    parser.add_argument('--config', type=pathlib.Path, metavar='YAML',
                        help='parameters file in the node format (node blocks with '
                             'ros__parameters; default: the installed config/rwa_monitor.yaml)')
    parser.add_argument('-o', '--output', type=pathlib.Path, metavar='FILE',
                        help='write the events JSON here, atomically (- = standard output; '
                             'an input file is refused; default: print a table)')
    parser.add_argument('--calibration', type=pathlib.Path, metavar='YAML',
                        help='commissioning calibration (rwa-monitor calibrate '
                             'DIR/calibration.yaml): detectors test changes against the '
                             'nominal models it holds')
    parser.add_argument('--friction-model', type=pathlib.Path, metavar='YAML',
                        help='refined friction model for the LLR detector, as written by '
                             'rwa-monitor identify (DIR/friction_model.yaml)')
    parser.epilog = ('exit codes: 0 examined, nothing found; 1 anomaly found; 3 nothing '
                     'found but not everything could be examined; 2 error')
    parser.set_defaults(func=run)


def load_config(path: pathlib.Path | None) -> dict[str, Any]:
    """Return the node blocks of a parameters YAML file (the installed one by default)."""
    return read_parameters_file(path)


def node_parameters(config: dict[str, Any], node: str) -> dict[str, Any]:
    """Return the checked parameters of ``node``: its block over ``/**``, defaults filled."""
    return block_values(config, SCHEMAS[node])


DETECTOR_NEEDS = {'llr': 'needs <wheel>_speed and <wheel>_friction columns',
                  'vsadc': 'needs gyro_x/y/z and q_x/y/z/w columns'}


def coverage(tele: Any, summary: dict[str, Any]) -> dict[str, Any]:
    """Add to ``summary`` which detectors ran and which components were not examined.

    ``detectors``: name -> ``ran`` or why it could not; ``not_examined``: component ->
    reason (its ``verdict`` is ``not_examined``: too few usable samples for a first
    verdict, or ``unknown``: most of its samples rejected or untested; or the detector
    never became ready). Returns the summary.
    """
    detectors: dict[str, str] = {}
    not_examined: dict[str, str] = {}
    for name in sorted(pipelines.available()):
        if name in summary['pipelines']:
            detectors[name] = 'ran'
        else:
            detectors[name] = 'not run: ' + DETECTOR_NEEDS.get(
                name, 'the file lacks its input columns')
    for wheel_id, wheel in tele.wheels.items():
        if wheel.friction is None:
            not_examined[wheel_id] = 'no friction column (the friction detectors need one)'
    for name, info in summary['pipelines'].items():
        for component, entry in info.get('components', {}).items():
            if not isinstance(entry, dict):
                continue
            if entry.get('verdict', EXAMINED) != EXAMINED:   # core/coverage.py
                not_examined[component] = f'{name}: {verdict_text(entry)}'
            elif entry.get('ready') is False:
                not_examined[component] = f'{name}: never ready (learning the nominal class)'
    summary['detectors'] = detectors
    summary['not_examined'] = not_examined
    return summary


def verdict_text(fields: dict[str, Any]) -> str:
    """Return the reason of a verdict's fields (core/coverage.py), ``unknown: `` first."""
    prefix = 'unknown: ' if fields.get('verdict') == UNKNOWN else ''
    return prefix + str(fields.get('verdict_reason', fields.get('verdict')))


def exit_code(events: list[AnomalyEvent], summary: dict[str, Any]) -> int:
    """Return 1 if an anomaly was found, else 3 if something was not examined, else 0."""
    if any(e.kind != 'healthy' for e in events):
        return EXIT_ANOMALY
    if summary.get('not_examined') or not summary['pipelines']:
        return EXIT_NOT_EXAMINED
    return EXIT_NOTHING_FOUND


def run(args: argparse.Namespace) -> int:
    """Read the file, detect, and write the JSON or print the table."""
    check_output(args.output, args.file, args.config, args.friction_model, args.xtce,
                 args.telemetry_map)
    tele = read_input(args.file, args)
    config = load_config(args.config)
    if args.calibration is not None:
        for node in ('llr_detector', 'vsadc_detector'):
            block = config.setdefault(node, {}).setdefault('ros__parameters', {})
            block['calibration_file'] = str(args.calibration)
    if args.friction_model is not None:
        block = config.setdefault('llr_detector', {}).setdefault('ros__parameters', {})
        block['friction_model_file'] = str(args.friction_model)
    events, summary = detect(tele, config, args.config or 'installed parameters')
    coverage(tele, summary)
    code = exit_code(events, summary)
    with quiet_broken_pipe():
        if args.output is not None:
            document = {'events': [e.to_json() for e in events], 'summary': summary}
            write_output(args.output, json_text(document))
            if str(args.output) != STDOUT:
                print(f'wrote {args.output}: {len(events)} events')
        else:
            print_table(events, summary, sys.stdout)
    return code


def print_table(events: list[AnomalyEvent], summary: dict[str, Any], out) -> None:
    """Print the events one per line, then each component's verdict and counts.

    Numbers as a person reads them (cli/readable.py): p-values ``< 1e-300`` or ``n/a``,
    three significant digits; the JSON of ``-o`` keeps the exact values.
    """
    header = (f'{"time_s":>10} {"component":<9} {"detector":<8} {"kind":<9} {"rev":>3} '
              f'{"p_value":>9} {"declared_s":>10}  details')
    print(header, file=out)
    for e in events:
        details = ' '.join(f'{k}={number_text(v)}' for k, v in e.details.items())
        print(f'{e.time:>10.1f} {e.component:<9} {e.detector:<8} {e.kind:<9} '
              f'{e.revision:>3} {p_value_text(e.p_value):>9} {e.declared_time:>10.1f}  '
              f'{details}', file=out)
    if not events:
        print('(no anomaly declared)', file=out)
    print(f'{summary["samples"]} samples', file=out)
    for name, state in summary.get('detectors', {}).items():
        print(f'detector {name}: {state}', file=out)
    for component, why in summary.get('not_examined', {}).items():
        print(f'not examined: {component}: {why}', file=out)
    for name, info in summary['pipelines'].items():
        print(f'{name}: {info["events"]} events in {info["runtime_s"]:.2f} s', file=out)
        for component, entry in info['components'].items():
            print(f'  {component}: {component_text(entry)}', file=out)


def component_text(entry: Any) -> str:
    """Return one component's summary entry as a sentence (verdict, samples, rejections)."""
    if not isinstance(entry, dict):
        return _plain(entry)
    parts = [str(entry['verdict']).replace('_', ' ')] if 'verdict' in entry else []
    if 'samples' in entry:
        usable = entry.get('usable_samples')
        parts.append(f'{entry["samples"]} samples'
                     + (f' ({usable} usable)' if usable is not None else ''))
    if 'events' in entry:
        parts.append(f'{entry["events"]} events')
    rejected = {k: v for k, v in (entry.get('rejected') or {}).items() if v}
    if rejected:
        parts.append('not tested: ' + ', '.join(f'{k} {v}' for k, v in rejected.items()))
    shown = {'verdict', 'samples', 'usable_samples', 'events', 'rejected', 'runtime_s',
             'verdict_reason', 'needed_samples'}
    parts += [f'{k} {_plain(v)}' for k, v in entry.items() if k not in shown]
    return '; '.join(parts)


def _plain(value: Any) -> str:
    if isinstance(value, dict):
        return ', '.join(f'{k} {_plain(v)}' for k, v in value.items()) or 'none'
    if isinstance(value, (list, tuple)):
        return ', '.join(_plain(v) for v in value) or 'none'
    return number_text(value)
