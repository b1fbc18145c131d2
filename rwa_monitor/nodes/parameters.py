"""Node parameters from the core schema: descriptors, validation, ``-p`` beaten by a file.

:func:`declare_parameters` declares each schema parameter with its ParameterDescriptor,
validates the start-up values (ConfigError naming the parameter) and rejects bad values
at run time with a reason naming the parameter; the returned :class:`Parameters` mapping
always holds the current values. :func:`refuse_unknown_overrides` refuses a name no schema
knows; :func:`beaten_overrides` finds the ``-p`` values a later ``--params-file`` beat.
"""

from __future__ import annotations

import sys
from typing import Any, Callable, Iterator, Mapping, Sequence

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterException)
from rclpy.node import Node
from rclpy.parameter import Parameter
import yaml

from rwa_monitor.core.params import AUTO
from rwa_monitor.core.schema import Param, Schema, SCHEMAS, SHARED_NAMES
from rwa_monitor.exceptions import ConfigError

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
