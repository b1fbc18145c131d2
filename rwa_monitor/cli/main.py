"""Entry point of the ``rwa-monitor`` command: finds and runs its sub-commands."""

from __future__ import annotations

import argparse
import ast
import importlib
import pathlib
import pkgutil
import sys
import traceback
from typing import Sequence

import rwa_monitor
from rwa_monitor import cli
from rwa_monitor.exceptions import NotExaminedError, RwaMonitorError

# Exit codes of every command (docs/usage.md, "Exit codes and verdicts").
EXIT_NOTHING_FOUND = 0    # examined, nothing found
EXIT_ANOMALY = 1          # an anomaly was found
EXIT_ERROR = 2            # bad input, bad configuration, or an unexpected failure
EXIT_NOT_EXAMINED = 3     # nothing found, but not everything could be examined


def submodules(prefix: str) -> list[str]:
    """Return the names of the modules of rwa_monitor.cli that start with ``prefix``."""
    names = [m.name for m in pkgutil.iter_modules(cli.__path__) if m.name.startswith(prefix)]
    return sorted(names)


def build_parser(command: str | None = None, listing: bool = False
                 ) -> argparse.ArgumentParser:
    """Return the parser with every sub-command module registered, or only ``command``'s.

    ``command``: the sub-command the arguments name (:func:`named_command`); only its
    module ``cmd_<command>`` is imported, so that a command starts without the imports of
    the others. ``listing``: when no command is named, list the commands without importing
    them (:func:`listed_help`): what ``rwa-monitor --help`` and argparse's error print;
    such a parser runs no command.
    """
    parser = argparse.ArgumentParser(
        prog='rwa-monitor',
        description='Reaction-wheel and gyro anomaly detection on telemetry files.')
    parser.add_argument('--version', action='version',
                        version=f'rwa-monitor {rwa_monitor.__version__}')
    parser.add_argument('--debug', action='store_true',
                        help='on an unexpected error print its traceback (default: one line)')
    commands = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    names = submodules('cmd_')
    if f'cmd_{command}' in names:
        names = [f'cmd_{command}']
    for name in names:
        text = listed_help(name) if listing and len(names) > 1 else None
        if text is not None:
            commands.add_parser(name.removeprefix('cmd_'), help=text)
        else:
            importlib.import_module(f'rwa_monitor.cli.{name}').register(commands)
    return parser


def listed_help(module: str) -> str | None:
    """Return the help line ``rwa_monitor/cli/<module>.py`` registers, read from its source.

    The literal ``help=`` of its ``add_parser('<command>', ...)`` call, or None where
    there is none to read (the caller then imports the module): the list of commands
    without the imports of every command (a few milliseconds against about 0.3 s).
    """
    command = module.removeprefix('cmd_')
    try:
        tree = ast.parse(pathlib.Path(cli.__path__[0], f'{module}.py').read_text('utf-8'))
    except (OSError, SyntaxError, UnicodeDecodeError):
        return None
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == 'add_parser' and node.args
                and isinstance(node.args[0], ast.Constant) and node.args[0].value == command):
            for keyword in node.keywords:
                if keyword.arg == 'help' and isinstance(keyword.value, ast.Constant):
                    return str(keyword.value.value)
    return None


def named_command(argv: Sequence[str]) -> str | None:
    """Return the first argument that is not an option: the sub-command, if any.

    The options before it (``--debug``, ``--version``, ``-h``) take no value; after
    ``-h`` or ``--help`` there is none (``rwa-monitor -h detect`` lists every command).
    """
    for arg in argv:
        if arg in ('-h', '--help'):
            return None
        if not arg.startswith('-'):
            return arg
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the process exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(named_command(argv), listing=True).parse_args(argv)
    from rwa_monitor.cli.output import quiet_broken_pipe
    from rwa_monitor.progress import KernelNotice
    from rwa_monitor.core import jit
    # A first run says it compiles, and how far; the reporter before it is back once the
    # command returns (a caller in the same process keeps its own stderr).
    previous = jit.set_reporter(KernelNotice())
    try:
        with quiet_broken_pipe():        # every command: ``rwa-monitor ... | head`` is quiet
            return int(args.func(args) or 0)
        return 0                         # the reader went away
    except NotExaminedError as err:      # too few usable samples: docs/usage.md
        print(f'rwa-monitor {args.command}: not examined: {err}', file=sys.stderr)
        return EXIT_NOT_EXAMINED
    except RwaMonitorError as err:
        print(f'rwa-monitor {args.command}: error: {err}', file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        return 130
    except Exception as err:             # any other failure: exit 2, one line
        kind = type(err).__qualname__
        if type(err).__module__ != 'builtins':
            kind = f'{type(err).__module__}.{kind}'
        hint = '' if args.debug else f' (rwa-monitor --debug {args.command} ... for details)'
        if args.debug:
            traceback.print_exc()
        print(f'rwa-monitor {args.command}: unexpected error: {kind}: {_first_line(err)}'
              + hint, file=sys.stderr)
        return EXIT_ERROR
    finally:
        jit.set_reporter(previous)


def _first_line(err: BaseException, limit: int = 300) -> str:
    """Return the first line of an exception's message, at most ``limit`` characters."""
    lines = str(err).strip().splitlines()
    text = lines[0] if lines else ''
    return text if len(text) <= limit else text[:limit] + '...'


if __name__ == '__main__':
    sys.exit(main())
