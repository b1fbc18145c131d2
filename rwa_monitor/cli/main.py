"""Entry point of the ``rwa-monitor`` command: finds and runs its sub-commands."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import traceback
from typing import Sequence

import rwa_monitor
from rwa_monitor import cli
from rwa_monitor.cli.output import quiet_broken_pipe
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


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Return the parser with every sub-command module registered, or only ``command``'s.

    ``command``: the sub-command the arguments name (:func:`named_command`); only its
    module ``cmd_<command>`` is imported, so that a command starts without the imports of
    the others (a name that is no command registers them all, for argparse's error).
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
        importlib.import_module(f'rwa_monitor.cli.{name}').register(commands)
    return parser


def named_command(argv: Sequence[str]) -> str | None:
    """Return the first argument that is not an option: the sub-command, if any.

    The options before it (``--debug``, ``--version``, ``-h``) take no value.
    """
    return next((a for a in argv if not a.startswith('-')), None)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the process exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(named_command(argv)).parse_args(argv)
    from rwa_monitor.progress import KernelNotice
    from rwa_monitor.core import jit
    jit.set_reporter(KernelNotice())     # a first run says it compiles, and how far
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


def _first_line(err: BaseException, limit: int = 300) -> str:
    """Return the first line of an exception's message, at most ``limit`` characters."""
    lines = str(err).strip().splitlines()
    text = lines[0] if lines else ''
    return text if len(text) <= limit else text[:limit] + '...'


if __name__ == '__main__':
    sys.exit(main())
