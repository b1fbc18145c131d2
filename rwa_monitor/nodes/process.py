"""The body of every node's console script: arguments, help, executor, exit codes."""

from __future__ import annotations

import contextlib
import faulthandler
import signal
import sys
import textwrap
import threading
from typing import Any, Callable, Iterator, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation
import rclpy.logging
from rclpy.node import Node

from rwa_monitor.exceptions import RwaMonitorError
from rwa_monitor.nodes.parameters import warn_beaten_overrides


def with_sim_time(argv: list[str]) -> list[str]:
    """Return ``argv`` with ``use_sim_time`` true by default (the nodes run on /clock).

    Placed before the user's own arguments, so a later ``-p use_sim_time:=false`` or a
    parameter file's node block still decides. (The shipped parameter file is not loaded
    by default: its node blocks would beat the user's ``-p`` values.)
    """
    return [*argv[:1], '--ros-args', '-p', 'use_sim_time:=true', '--', *argv[1:]]


def wants_help(argv: Sequence[str]) -> bool:
    """Return True if ``-h``/``--help`` comes before any ``--ros-args`` in ``argv[1:]``."""
    user = list(argv[1:])
    if '--ros-args' in user:
        user = user[:user.index('--ros-args')]
    return '-h' in user or '--help' in user


def node_help(prog: str, description: str | None, specs: Sequence[Any] = ()) -> str:
    """Return the ``--help`` text of a node's console script: usage, summary, parameters."""
    lines = [f'usage: {prog} [-h] [--ros-args [-p NAME:=VALUE ...] [--params-file YAML] '
             '[-r FROM:=TO ...]]', '']
    summary = (description or '').strip().split('\n\n')[0]
    if summary:
        lines += [' '.join(summary.split()), '']
    if specs:
        lines.append('parameters (set with -p NAME:=VALUE or a --params-file):')
        for spec in specs:
            default = getattr(spec, 'default', '')
            flags = ' (read-only)' if getattr(spec, 'read_only', False) else ''
            lines.append(f'  {spec.name} (default {default!r}){flags}')
            lines += textwrap.wrap(str(getattr(spec, 'description', '')), 86,
                                   initial_indent='      ', subsequent_indent='      ')
    lines += ['', 'Stops cleanly on Ctrl-C (SIGINT) and SIGTERM. docs/nodes.md has the topics, '
              'diagnostics and alarms.']
    return '\n'.join(lines)


def _interrupt_handler(flag: threading.Event) -> Callable[[int, Any], None]:
    """Return a SIGINT handler that records the signal; the spin loop ends on it.

    It does not raise: a KeyboardInterrupt raised inside a callback (the replay's timer
    in the middle of a publish) is caught and logged by the executor after rclpy's own
    handler has shut the context down, and the node then logs into a dead context.
    """
    def handler(signum: int, frame: Any) -> None:
        flag.set()
    return handler


def spin(nodes: Node | Sequence[Node], executor: str = 'events',
         stop: threading.Event | None = None) -> None:
    """Spin ``nodes`` (one executor, one thread) until their context shuts down or ``stop``.

    ``'events'`` (the default): rclpy.experimental.EventsExecutor, turned by
    ``spin_once`` with a bounded timeout until it raises ExternalShutdownException. Its
    ``spin()`` is not used: in the Jazzy wheels it never returns to Python, so neither
    SIGINT nor a shutdown from a callback ends it, and this package saw its timers stay
    silent under it. ``spin_once`` releases the GIL while waiting (the FSS worker thread
    keeps running). ``'single'``: the SingleThreadedExecutor (it rebuilds its wait set on
    every turn: several times the CPU per message, docs/nodes.md "Where the time goes").
    """
    nodes = [nodes] if isinstance(nodes, Node) else list(nodes)
    context = nodes[0].context
    if executor == 'events':
        from rclpy.experimental import EventsExecutor
        runner = EventsExecutor(context=context)
        for node in nodes:
            runner.add_node(node)
        while stop is None or not stop.is_set():   # or ExternalShutdownException
            runner.spin_once(timeout_sec=0.1)
        return
    runner = rclpy.executors.SingleThreadedExecutor(context=context)
    for node in nodes:
        runner.add_node(node)
    runner.spin()


RCLError = rclpy_implementation.RCLError


def rcl_error_line(err: Exception) -> str:
    """Return rcl's refusal of the arguments in one line, without its source locations."""
    text = ' '.join(str(err).split())
    text = text.removeprefix('failed to initialize rcl: ')
    return text.split(', at /')[0]


def run_node(factory: Callable[[], Node], args: Sequence[str] | None = None,
             executor: str = 'events', *, help_text: str | Callable[[], str] | None = None
             ) -> int:
    """Run one node: :func:`run_nodes` with one factory."""
    return run_nodes([factory], args, executor, help_text=help_text)


@contextlib.contextmanager
def _rcl_quiet() -> Iterator[None]:
    """Silence the ``rcl`` logger while rclpy parses the arguments, then restore it.

    A level the arguments set (``--log-level rcl:=debug``) is left as they set it.
    """
    fatal = rclpy.logging.LoggingSeverity.FATAL
    before = rclpy.logging.get_logger_level('rcl')
    rclpy.logging.set_logger_level('rcl', fatal)
    try:
        yield
    finally:
        if rclpy.logging.get_logger_level('rcl') == fatal:
            rclpy.logging.set_logger_level('rcl', before)


def run_nodes(factories: Sequence[Callable[[], Node]], args: Sequence[str] | None = None,
              executor: str = 'events', *, help_text: str | Callable[[], str] | None = None
              ) -> int:
    """Initialise rclpy with ``args``, create the nodes, spin them; return an exit code.

    Every node is made by its factory in one process, one context and one executor (the
    one-process composition of ``rwa-monitor-monitor`` when there are several).

    ``args`` (default ``sys.argv``) get ``use_sim_time`` true as a default (see
    :func:`with_sim_time`). ``-h``/``--help`` before ``--ros-args`` prints ``help_text``
    (default: :func:`node_help` of the docstring and ``PARAMETERS`` of the module that
    defines the first factory) and returns 0 without starting ROS.

    Arguments rcl refuses (a parameters file it cannot parse), a :class:`ConfigError` (a
    bad parameter) or any other package error at start-up is printed as one line and
    gives 2; a ``-p`` value that a parameters-file block beat is warned about
    (:func:`warn_beaten_overrides`). Ctrl-C,
    SIGTERM and an external shutdown end cleanly with 0 (an error raised by a call into a
    context that the signal already shut down is part of that shutdown, not a failure).
    The node may end itself by calling ``rclpy.try_shutdown(context=node.context)`` (the
    replay does when it is done). ``executor`` is ``'single'`` or ``'events'``
    (rclpy.experimental.EventsExecutor).
    """
    argv = sys.argv if args is None else list(args)
    from rwa_monitor.paths import with_installed_params_files
    argv, notes = with_installed_params_files(argv)
    for note in notes:
        print(f'{str(argv[0]).rsplit("/", 1)[-1]}: {note}', file=sys.stderr)
    from rwa_monitor.core import jit
    from rwa_monitor.progress import KernelNotice
    jit.set_reporter(KernelNotice())    # a machine's first run says it compiles, and how far
    if wants_help(argv):
        text = help_text() if callable(help_text) else help_text
        if text is None:   # the docstring and PARAMETERS of the module defining ``factory``
            module = sys.modules.get(getattr(factories[0], '__module__', ''))
            text = node_help(str(argv[0]).rsplit('/', 1)[-1], getattr(module, '__doc__', None),
                             getattr(module, 'PARAMETERS', ()))
        print(text)
        return 0
    interrupted = threading.Event()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _interrupt_handler(interrupted))
        # A node that does not stop can be asked where it is: kill -USR1 PID writes every
        # thread's Python stack to the process's stderr (docs/nodes.md); none where that
        # stream has no file descriptor (an embedding host that replaced it).
        with contextlib.suppress(AttributeError, ValueError, OSError):
            faulthandler.register(signal.SIGUSR1, file=sys.__stderr__, all_threads=True)
    try:
        with _rcl_quiet():   # our one line below says what rcl's own [ERROR] line would
            rclpy.init(args=with_sim_time(argv))
    except RCLError as err:   # rcl refused the arguments (a parameters file it cannot parse)
        print(f'error: {rcl_error_line(err)}', file=sys.stderr)
        return 2
    nodes: list[Node] = []
    try:
        for factory in factories:
            nodes.append(factory())
            warn_beaten_overrides(nodes[-1], argv)
        if not interrupted.is_set():   # Ctrl-C during start-up: stop before spinning
            spin(nodes, executor, interrupted)
    except RwaMonitorError as err:   # ConfigError and every error of the package at start
        print(f'error: {err}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: BLE001 - see below
        if rclpy.ok() and not interrupted.is_set():
            raise
        # The context was shut down (SIGINT/SIGTERM) while a callback was using it, or
        # Ctrl-C landed inside a call into rclpy's C++ layer, which turns the
        # KeyboardInterrupt into a RuntimeError (seen in take_message).
    finally:
        for node in reversed(nodes):
            with contextlib.suppress(Exception):
                node.destroy_node()
        rclpy.try_shutdown()
    return max((getattr(node, 'exit_code', 0) for node in nodes), default=0)
