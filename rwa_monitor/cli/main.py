"""Entry point of the ``rwa-monitor`` command: finds and runs its sub-commands."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from typing import Sequence

import rwa_monitor
from rwa_monitor import cli
from rwa_monitor.cli.output import quiet_broken_pipe
from rwa_monitor.exceptions import RwaMonitorError


def submodules(prefix: str) -> list[str]:
    """Return the names of the modules of rwa_monitor.cli that start with ``prefix``."""
    names = [m.name for m in pkgutil.iter_modules(cli.__path__) if m.name.startswith(prefix)]
    return sorted(names)


def build_parser() -> argparse.ArgumentParser:
    """Return the parser with every sub-command module registered."""
    parser = argparse.ArgumentParser(
        prog='rwa-monitor',
        description='Reaction-wheel and gyro anomaly detection on telemetry files.')
    parser.add_argument('--version', action='version',
                        version=f'rwa-monitor {rwa_monitor.__version__}')
    commands = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name in submodules('cmd_'):
        importlib.import_module(f'rwa_monitor.cli.{name}').register(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with quiet_broken_pipe():        # every command: ``rwa-monitor ... | head`` is quiet
            return int(args.func(args) or 0)
        return 0                         # the reader went away
    except RwaMonitorError as err:
        print(f'rwa-monitor {args.command}: error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
