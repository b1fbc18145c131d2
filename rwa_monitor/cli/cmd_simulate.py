"""``rwa-monitor simulate KIND``: one module ``simulate_<kind>`` per simulator."""

from __future__ import annotations

import argparse
import importlib

from rwa_monitor.cli.main import submodules


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``simulate`` and, under it, one KIND per ``simulate_<kind>`` module."""
    parser = subparsers.add_parser('simulate', help='write seeded telemetry with truth',
                                   description='Write seeded telemetry with truth columns.')
    kinds = parser.add_subparsers(dest='kind', metavar='KIND', required=True)
    for name in submodules('simulate_'):
        importlib.import_module(f'rwa_monitor.cli.{name}').register(kinds)
