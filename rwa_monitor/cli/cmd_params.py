"""``rwa-monitor params [BLOCK]``: the parameters of every detector and tool (core schema)."""

from __future__ import annotations

import argparse

import yaml

from rwa_monitor.core.schema import help_text, parameters_document, SCHEMAS, yaml_block


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``params``."""
    parser = subparsers.add_parser(
        'params', help='list the parameters of the detectors and tools (defaults, ranges)',
        description='Print the parameters defined in rwa_monitor/core/schema.py: a block '
                    'as text, as a parameters-file block (--yaml), or every block as the '
                    'markdown of docs/parameters.md (--markdown).')
    parser.add_argument('block', nargs='?', choices=sorted(SCHEMAS),
                        help='one block (default: every block)')
    form = parser.add_mutually_exclusive_group()
    form.add_argument('--markdown', action='store_true',
                      help='print docs/parameters.md (every block)')
    form.add_argument('--yaml', action='store_true',
                      help='print the defaults as a parameters-file block')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the requested form."""
    if args.markdown:
        print(parameters_document(), end='')
        return 0
    blocks = [SCHEMAS[args.block]] if args.block else list(SCHEMAS.values())
    for schema in blocks:
        if args.yaml:
            print(yaml.safe_dump(yaml_block(schema), sort_keys=False), end='')
        else:
            print(help_text(schema, ('all', 'node', 'file')))
    return 0
