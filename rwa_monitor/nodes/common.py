"""What every rwa_monitor node shares: QoS profiles, parameters, diagnostics, ``main``.

The API (documented in docs/nodes.md):

- QoS: :func:`telemetry_qos`, :data:`EVENTS_QOS`, :data:`DIAGNOSTICS_QOS`,
  :data:`CLOCK_QOS`; :func:`qos_event_callbacks` logs incompatible-QoS peers once.
- Parameters: the core schema's :class:`~rwa_monitor.core.schema.Param` (alias
  :data:`ParamSpec`), :func:`descriptor` (its ParameterDescriptor),
  :func:`refuse_unknown_overrides`, and :func:`declare_parameters`, which declares each
  with its ParameterDescriptor, validates
  the start-up values (ConfigError naming the parameter) and rejects bad values at run time
  with a reason naming the parameter. The returned :class:`Parameters` mapping always holds
  the current values.
- Diagnostics: :class:`DiagnosticsPublisher` publishes one DiagnosticStatus per component
  on ``/diagnostics`` every period (1 s) of wall time, named ``"<node>: <check>"``,
  ``hardware_id`` = component, KeyValues with units in the key, STALE when the component's
  input stops.
- :func:`run_node`: the body of every console script's ``main``.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import textwrap
import threading
import time
from typing import Any, Callable, Iterator, Mapping, NamedTuple, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterException)
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
import yaml

from rwa_monitor.core.params import AUTO
from rwa_monitor.core.schema import Param, Schema, SCHEMAS, SHARED_NAMES
from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.telemetry.codecs import format_value, key_values  # noqa: F401

# --------------------------------------------------------------------------------- QoS

# History depth of the telemetry topics when kept KEEP_LAST.
TELEMETRY_DEPTH = 1000


def telemetry_qos(depth: int = TELEMETRY_DEPTH, keep_all: bool = True,
                  reliable: bool = True) -> QoSProfile:
    """Return the telemetry QoS: RELIABLE, VOLATILE, KEEP_ALL (or KEEP_LAST ``depth``).

    Reliable and keep-all so that no sample is lost: a subscriber that lags keeps every
    sample until its history is full, then the publisher's ``publish`` fails and the replay
    offers the sample again later (docs/nodes.md). A reliable publisher also serves
    best-effort (sensor-data) subscribers; history does not affect compatibility.
    ``reliable=False`` gives the best-effort, keep-last profile a subscriber needs to hear
    a best-effort (sensor-data) publisher.
    """
    if not reliable:
        return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
    return QoSProfile(depth=depth,
                      history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


# Anomaly events: reliable, and the last 100 kept for subscribers that join late.
EVENTS_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)

# /diagnostics: reliable, volatile (a periodic state; the next one comes in 1 s).
DIAGNOSTICS_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)

# /clock publisher: reliable, so it matches the best-effort clock subscribers too.
CLOCK_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


def qos_event_callbacks(node: Node, topic: str, publisher: bool = False
                        ) -> PublisherEventCallbacks | SubscriptionEventCallbacks:
    """Return event callbacks that log an incompatible-QoS peer on ``topic`` (once)."""
    warned: set[str] = set()

    def incompatible(event: Any) -> None:
        policy = getattr(event, 'last_policy_kind', '?')
        if str(policy) not in warned:
            warned.add(str(policy))
            node.get_logger().warning(
                f'incompatible QoS with a peer on {topic}: policy {policy} '
                f'(total {event.total_count}); the peer gets no messages')

    if publisher:
        return PublisherEventCallbacks(incompatible_qos=incompatible)
    return SubscriptionEventCallbacks(incompatible_qos=incompatible)


# -------------------------------------------------------------------------- parameters

_BIG = sys.float_info.max

# A node parameter is a core schema parameter (core/schema.py): one definition for the
# node, the file commands, the docs and the shipped YAML.
ParamSpec = Param


def descriptor(spec: Param) -> ParameterDescriptor:
    """Return the ParameterDescriptor of a schema parameter: description, range, read-only.

    Typed by :meth:`Param.check`, not by ROS (``dynamic_typing``), so that a value of the
    wrong type is refused with a reason naming the parameter, an integer written for a
    float parameter (rate: 40) is accepted as 40.0, a float written without a dot (1e-5,
    read as a string) is accepted, and ``auto`` is accepted where the schema allows it.
    """
    text = spec.description
    if spec.unit:
        text += f' Unit: {spec.unit}.'
    if spec.choices:
        text += f' One of: {", ".join(spec.choices)}.'
    if spec.auto:
        text += f' Or {AUTO}.'
    desc = ParameterDescriptor(name=spec.name, description=text, read_only=spec.read_only,
                               dynamic_typing=True)
    kind = spec.type
    if kind is float and (spec.low is not None or spec.high is not None):
        desc.floating_point_range = [FloatingPointRange(
            from_value=-_BIG if spec.low is None else float(spec.low),
            to_value=_BIG if spec.high is None else float(spec.high), step=0.0)]
    elif kind is int and (spec.low is not None or spec.high is not None):
        desc.integer_range = [IntegerRange(
            from_value=-2 ** 63 if spec.low is None else int(spec.low),
            to_value=2 ** 63 - 1 if spec.high is None else int(spec.high), step=1)]
    if spec.choices:
        desc.additional_constraints = 'one of: ' + ', '.join(spec.choices)
    elif spec.allowed():
        desc.additional_constraints = spec.allowed()
    return desc


_ROS_TYPES = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER,
              float: Parameter.Type.DOUBLE, str: Parameter.Type.STRING,
              list: Parameter.Type.STRING_ARRAY}


def refuse_unknown_overrides(node: Node, schema: Schema) -> None:
    """Raise ConfigError for a parameter given to ``node`` that no schema knows.

    ROS ignores such a parameter silently; the file commands refuse it, so the node does
    too, naming the nearest valid name. A name of another node's schema may come from a
    ``/**`` block and is left alone, as the file commands do.
    """
    given = getattr(node, '_parameter_overrides', {})
    known = set(SHARED_NAMES).union(*(s.names() for s in SCHEMAS.values()))
    for name in given:
        if name in known or name.startswith('qos_overrides.'):
            continue
        raise ConfigError(f'{node.get_name()}: unknown parameter {name!r}'
                          f'{schema.nearest(name)}')


class Parameters(Mapping[str, Any]):
    """The current, validated values of a node's parameters (updated on every set)."""

    def __init__(self, values: dict[str, Any]) -> None:
        self._values = values

    def __getitem__(self, name: str) -> Any:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)


def declare_parameters(node: Node, specs: Sequence[Param],
                       on_change: Callable[[str, Any], None] | None = None,
                       check_all: Callable[[dict[str, Any]], None] | None = None
                       ) -> Parameters:
    """Declare ``specs`` on ``node``, validate them, and guard every later change.

    Start-up values (defaults, ``--params-file``, ``-p``) that break a spec raise
    :class:`ConfigError` naming the parameter; a ``required`` spec has no default (it is
    declared typed but unset, and its value is None until given). At run time a set
    request with a bad value is rejected with that reason; accepted values update the
    returned mapping, then ``on_change(name, value)`` is called for each.
    ``check_all(values)`` checks rules between parameters (raise ValueError naming one),
    at start-up and on every change.
    """
    by_name = {spec.name: spec for spec in specs}
    values: dict[str, Any] = {}
    for spec in specs:
        try:
            if spec.required:  # statically typed, so that it may stay unset
                desc = descriptor(spec)
                desc.dynamic_typing = False
                param = node.declare_parameter(spec.name, _ROS_TYPES[spec.type], desc)
            else:
                param = node.declare_parameter(spec.name, spec.default, descriptor(spec))
        except (InvalidParameterValueException, InvalidParameterTypeException,
                ParameterException) as err:
            raise ConfigError(f'parameter {spec.name}: {err}') from None
        if spec.required and param.type_ == Parameter.Type.NOT_SET:
            values[spec.name] = None
            continue
        try:
            values[spec.name] = spec.check(param.value)
        except ValueError as err:
            raise ConfigError(f'parameter {err}') from None
    if check_all is not None:
        try:
            check_all(dict(values))
        except ValueError as err:
            raise ConfigError(f'parameter {err}') from None

    def on_set(params: list[Parameter]) -> SetParametersResult:
        proposed = dict(values)
        for param in params:
            spec = by_name.get(param.name)
            if spec is None:
                continue
            try:
                proposed[param.name] = spec.check(param.value)
            except ValueError as err:
                return SetParametersResult(successful=False, reason=str(err))
        if check_all is not None:
            try:
                check_all(proposed)
            except ValueError as err:
                return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def post_set(params: list[Parameter]) -> None:
        for param in params:
            if param.name in by_name:
                values[param.name] = by_name[param.name].check(param.value)
                if on_change is not None:
                    on_change(param.name, values[param.name])

    node.add_on_set_parameters_callback(on_set)
    node.add_post_set_parameters_callback(post_set)
    return Parameters(values)


# ------------------------------------------------------------------------- diagnostics

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}


def publish_calibration_change(node: Node, publisher: Any, calibration: Any,
                               detector: str) -> None:
    """Publish the calibration now in force on ``anomalies`` (kind calibration_changed).

    ``calibration`` is the node's :class:`rwa_monitor.nodes.calibration.CalibrationInForce`.
    Not journalled with the alarms: it is a setting, not an anomaly (level OK).
    """
    out = DiagnosticArray()
    now = node.get_clock().now()
    out.header.stamp = now.to_msg()
    out.status = [calibration.change_status(detector, now.nanoseconds * 1e-9,
                                            node.get_name())]
    publisher.publish(out)


def wheel_names(text: str) -> set[str] | None:
    """Return the wheel ids of a comma-separated ``wheels`` parameter (None = any wheel)."""
    names = {n.strip() for n in text.split(',') if n.strip()}
    return names or None


class Refusal(NamedTuple):
    """Why a wheel is ignored: the input counter to increment and the log message."""

    counter: str
    message: str


def wheel_refusal(wheel_id: str, allowed: set[str] | None, known: int,
                  max_wheels: int) -> Refusal | None:
    """Return the refusal if a new wheel must be ignored, else None."""
    if allowed is not None and wheel_id not in allowed:
        return Refusal('unknown_wheel', f'ignoring wheel {wheel_id!r}: not in parameter wheels')
    if known >= max_wheels:
        return Refusal('too_many_wheels', f'ignoring wheel {wheel_id!r}: max_wheels reached')
    return None


class ComponentHealth:
    """The health of one component: level, message, KeyValues, time of the last input."""

    def __init__(self, hardware_id: str, check: str) -> None:
        self.hardware_id = hardware_id
        self.check = check
        self.level = OK
        self.message = 'waiting for input'
        self.values: dict[str, Any] = {}
        self.last_input: float | None = None
        self.provider: Callable[[], tuple[bytes, str, dict[str, Any]]] | None = None
        self.stale_timeout: float | None = None  # None: the publisher's


class DiagnosticsPublisher:
    """Publish component health on ``/diagnostics`` the way diagnostic_updater does.

    Every ``period`` seconds of wall (steady) time, whatever the replay rate, one
    DiagnosticArray holds a status per component, named ``"<node>: <check>"`` (``"<ns>/<node>:
    <check>"`` when the node runs in a namespace); its
    stamp is the node clock (sim time under a replay). A component whose input has not
    arrived for ``stale_timeout`` seconds (its own, if set) is reported STALE (its last
    level is kept in the KeyValue ``last_level``). Staleness is measured on the steady
    clock too, because a stopped replay stops the sim clock. Only level constants are
    assigned to ``level``.
    """

    def __init__(self, node: Node, *, period: float = 1.0, stale_timeout: float = 3.0,
                 topic: str = '/diagnostics') -> None:
        self._node = node
        self.period = period
        self.stale_timeout = stale_timeout
        self.components: dict[str, ComponentHealth] = {}
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.steady_clock = self._steady  # for the node's own wall-time timers
        # "<node>" in the root namespace, "sat1/<node>" under /sat1 (the dashboard and
        # diagnostic aggregators tell spacecraft apart by it).
        self.prefix = node.get_fully_qualified_name().lstrip('/')
        self._started = self.now()
        self._last_publish = self._started
        self._pub = node.create_publisher(DiagnosticArray, topic, DIAGNOSTICS_QOS)
        self._timer = node.create_timer(period, self.publish, clock=self._steady)
        self.published = 0

    @staticmethod
    def now() -> float:
        """Return the steady-clock time (s) used for staleness.

        ``time.monotonic`` reads the same CLOCK_MONOTONIC as rclpy's STEADY_TIME clock,
        at a fraction of the cost (it is called once per message).
        """
        return time.monotonic()

    def component(self, hardware_id: str, check: str) -> ComponentHealth:
        """Return the health record of ``hardware_id`` (created on first use)."""
        health = self.components.get(hardware_id)
        if health is None:
            health = self.components[hardware_id] = ComponentHealth(hardware_id, check)
        return health

    def set(self, hardware_id: str, check: str, level: bytes, message: str,
            **values: Any) -> None:
        """Set a component's level and message; merge ``values`` into its KeyValues."""
        health = self.component(hardware_id, check)
        health.level, health.message = level, message
        health.values.update(values)

    def provide(self, hardware_id: str, check: str,
                provider: Callable[[], tuple[bytes, str, dict[str, Any]]]) -> None:
        """Compute a component's ``(level, message, values)`` by calling ``provider``.

        The provider is called only when a status is published (once a period), so a node
        need not update its health on every message.
        """
        self.component(hardware_id, check).provider = provider

    def mark_input(self, hardware_id: str, check: str, now: float | None = None) -> None:
        """Record that input for ``hardware_id`` arrived (at steady time ``now``)."""
        self.component(hardware_id, check).last_input = self.now() if now is None else now

    def remove(self, hardware_id: str) -> None:
        """Stop reporting a component."""
        self.components.pop(hardware_id, None)

    def status(self, health: ComponentHealth, now: float | None = None) -> DiagnosticStatus:
        """Return the DiagnosticStatus of one component, STALE if its input stopped."""
        now = self.now() if now is None else now
        since = now - (self._started if health.last_input is None else health.last_input)
        if health.provider is not None:
            try:
                health.level, health.message, health.values = health.provider()
            except Exception as err:  # noqa: BLE001 - a health bug must not stop the node
                health.level, health.message = ERROR, f'health check failed: {err!r}'
        values = dict(health.values)
        level, message = health.level, health.message
        timeout = self.stale_timeout if health.stale_timeout is None else health.stale_timeout
        if since > timeout:
            values['last_level'] = LEVEL_NAMES[health.level]
            level, message = STALE, f'no input for {since:.1f} s; last: {health.message}'
        values['since_input_s'] = round(since, 3)
        return DiagnosticStatus(level=level, name=f'{self.prefix}: {health.check}',
                                message=message, hardware_id=health.hardware_id,
                                values=key_values(values))

    def publish(self) -> None:
        """Publish the statuses of every component now."""
        now = self.now()
        self._last_publish = now
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = [self.status(h, now) for h in list(self.components.values())]
        self._pub.publish(msg)
        self.published += 1

    def destroy(self) -> None:
        """Destroy the timer and the publisher."""
        self._node.destroy_timer(self._timer)
        self._node.destroy_publisher(self._pub)


# -------------------------------------------------------------------------------- main

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
    """Return a SIGINT handler that records the signal, then interrupts as Python does."""
    def handler(signum: int, frame: Any) -> None:
        flag.set()
        raise KeyboardInterrupt
    return handler


def spin(node: Node, executor: str = 'events') -> None:
    """Spin ``node`` until its context shuts down.

    ``'events'`` (the default): rclpy.experimental.EventsExecutor, turned by
    ``spin_once`` with a bounded timeout until it raises ExternalShutdownException. Its
    ``spin()`` is not used: in the Jazzy wheels
    it never returns to Python, so neither SIGINT nor a shutdown from a callback ends it,
    and this package saw its timers stay silent under it. ``spin_once`` releases the GIL
    while waiting (the FSS worker thread keeps running) and raises
    ExternalShutdownException once the context is shut down. ``'single'``: the
    SingleThreadedExecutor (it rebuilds its wait set on every turn: about 4x the CPU per
    message, docs/nodes.md "Where the time goes").
    """
    if executor == 'events':
        from rclpy.experimental import EventsExecutor
        runner = EventsExecutor(context=node.context)
        runner.add_node(node)
        while True:   # ends with ExternalShutdownException (checking ok() per turn costs)
            runner.spin_once(timeout_sec=0.1)
    runner = rclpy.executors.SingleThreadedExecutor(context=node.context)
    runner.add_node(node)
    runner.spin()


RCLError = rclpy_implementation.RCLError


def _ros_args(argv: Sequence[str]) -> list[str]:
    """Return the arguments inside ``--ros-args`` sections of ``argv``."""
    out, inside = [], False
    for arg in argv[1:]:
        if arg == '--ros-args':
            inside = True
        elif arg == '--':
            inside = False
        elif inside:
            out.append(arg)
    return out


def _same(given: Any, value: Any) -> bool:
    if given == value or str(given) == str(value):
        return True
    try:
        return float(given) == float(value)
    except (TypeError, ValueError):
        return False


def beaten_overrides(node: Node, argv: Sequence[str]) -> list[str]:
    """Return a warning for each ``-p`` of ``argv`` whose value ``node`` does not hold.

    rcl applies ``-p`` and ``--params-file`` in the order given, the later winning: a
    ``-p`` (with or without a ``NODE:`` prefix) placed before a ``--params-file`` whose
    block for the node sets the same name is silently beaten (measured with rclpy on
    Jazzy; docs/nodes.md "Parameters files and -p").
    """
    args = _ros_args(argv)
    if '--params-file' not in args:
        return []
    out = []
    for flag, item in zip(args, args[1:]):
        if flag not in ('-p', '--param') or ':=' not in item:
            continue
        target, text = item.split(':=', 1)
        prefix, _, name = target.rpartition(':')
        if prefix and prefix.lstrip('/') not in (node.get_name(),
                                                 node.get_fully_qualified_name().lstrip('/')):
            continue
        if not node.has_parameter(name):
            continue
        try:
            given = yaml.safe_load(text)
        except yaml.YAMLError:
            given = text
        value = node.get_parameter(name).value
        if not _same(given, value):
            out.append(f'-p {item} was beaten by a later --params-file block (value in force: '
                       f'{value!r}): put -p {node.get_name()}:{name}:={text} after '
                       '--params-file')
    return out


def warn_beaten_overrides(node: Node, argv: Sequence[str]) -> None:
    """Log a warning for each ``-p`` of ``argv`` that a parameters file beat."""
    for text in beaten_overrides(node, argv):
        node.get_logger().warning(text)


def rcl_error_line(err: Exception) -> str:
    """Return rcl's refusal of the arguments in one line, without its source locations."""
    text = ' '.join(str(err).split())
    text = text.removeprefix('failed to initialize rcl: ')
    return text.split(', at /')[0]


def run_node(factory: Callable[[], Node], args: Sequence[str] | None = None,
             executor: str = 'events', *, help_text: str | Callable[[], str] | None = None
             ) -> int:
    """Initialise rclpy with ``args``, create the node, spin it; return an exit code.

    ``args`` (default ``sys.argv``) get ``use_sim_time`` true as a default (see
    :func:`with_sim_time`). ``-h``/``--help`` before ``--ros-args`` prints ``help_text``
    (default: :func:`node_help` of the docstring and ``PARAMETERS`` of the module that
    defines ``factory``) and returns 0 without starting ROS.

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
    if wants_help(argv):
        text = help_text() if callable(help_text) else help_text
        if text is None:   # the docstring and PARAMETERS of the module defining ``factory``
            module = sys.modules.get(getattr(factory, '__module__', ''))
            text = node_help(str(argv[0]).rsplit('/', 1)[-1], getattr(module, '__doc__', None),
                             getattr(module, 'PARAMETERS', ()))
        print(text)
        return 0
    interrupted = threading.Event()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _interrupt_handler(interrupted))
    try:
        rclpy.init(args=with_sim_time(argv))
    except RCLError as err:   # rcl refused the arguments (a parameters file it cannot parse)
        print(f'error: {rcl_error_line(err)}', file=sys.stderr)
        return 2
    node = None
    try:
        node = factory()
        warn_beaten_overrides(node, argv)
        spin(node, executor)
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
        if node is not None:
            with contextlib.suppress(Exception):
                node.destroy_node()
        rclpy.try_shutdown()
    return getattr(node, 'exit_code', 0)
