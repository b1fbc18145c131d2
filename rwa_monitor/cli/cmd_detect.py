"""``rwa-monitor detect FILE``: run every detector whose input columns the file has.

Each module of :mod:`rwa_monitor.pipelines` whose ``applies(tele)`` is true runs with the
parameters of its node (its ``SCHEMA``): the ``/**`` block of the YAML file overlaid with
the node's block, read and checked by :mod:`rwa_monitor.telemetry.parameters_file`, so
one file configures the nodes and the command line alike. A pipeline with
``run_with_summary`` also reports per-component facts (samples, rejected-sample counters,
run time); events are sorted by estimated change time. A bad parameter value is a
ConfigError naming the pipeline and the parameter (exit code 2).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from typing import Any

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import help_text, LLR, SCHEMAS, VSADC
from rwa_monitor.pipelines import detect
from rwa_monitor.telemetry import read_telemetry
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
    parser.add_argument('file', type=pathlib.Path, help='telemetry file (.csv or .mcap)')
    parser.add_argument('--config', type=pathlib.Path, metavar='YAML',
                        help='parameters file in the node format (node blocks with '
                             'ros__parameters; default: the installed config/rwa_monitor.yaml)')
    parser.add_argument('-o', '--output', type=pathlib.Path, metavar='FILE',
                        help='write the events JSON here (default: print a table)')
    parser.add_argument('--friction-model', type=pathlib.Path, metavar='YAML',
                        help='refined friction model for the LLR detector, as written by '
                             'rwa-monitor identify (DIR/friction_model.yaml)')
    parser.set_defaults(func=run)


def load_config(path: pathlib.Path | None) -> dict[str, Any]:
    """Return the node blocks of a parameters YAML file (the installed one by default)."""
    return read_parameters_file(path)


def node_parameters(config: dict[str, Any], node: str) -> dict[str, Any]:
    """Return the checked parameters of ``node``: its block over ``/**``, defaults filled."""
    return block_values(config, SCHEMAS[node])


def run(args: argparse.Namespace) -> int:
    """Read the file, detect, and write the JSON or print the table."""
    tele = read_telemetry(args.file)
    config = load_config(args.config)
    if args.friction_model is not None:
        block = config.setdefault('llr_detector', {}).setdefault('ros__parameters', {})
        block['friction_model_file'] = str(args.friction_model)
    events, summary = detect(tele, config, args.config or 'installed parameters')
    if args.output is not None:
        document = {'events': [e.to_json() for e in events], 'summary': summary}
        args.output.write_text(json.dumps(document, indent=2) + '\n')
        print(f'wrote {args.output}: {len(events)} events')
    else:
        print_table(events, summary, sys.stdout)
    return 0


def print_table(events: list[AnomalyEvent], summary: dict[str, Any], out) -> None:
    """Print the events one per line, then the per-pipeline summary."""
    header = (f'{"time_s":>10} {"component":<9} {"detector":<8} {"kind":<8} {"rev":>3} '
              f'{"p_value":>9} {"declared_s":>10}  details')
    print(header, file=out)
    for e in events:
        details = ' '.join(f'{k}={v:.3g}' if isinstance(v, float) else f'{k}={v}'
                           for k, v in e.details.items())
        print(f'{e.time:>10.1f} {e.component:<9} {e.detector:<8} {e.kind:<8} '
              f'{e.revision:>3} {e.p_value:>9.2g} {e.declared_time:>10.1f}  {details}',
              file=out)
    if not events:
        print('(no anomaly declared)', file=out)
    print(f'{summary["samples"]} samples', file=out)
    for name, info in summary['pipelines'].items():
        print(f'{name}: {info["events"]} events in {info["runtime_s"]:.2f} s', file=out)
        for component, entry in info['components'].items():
            print(f'  {component}: {json.dumps(entry)}', file=out)
