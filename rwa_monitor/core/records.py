"""Typed state records as data: a JSON tree plus named numpy arrays, checked by type.

A detector family keeps its state in frozen dataclasses (its *records*); this module turns
one into ``(tree, arrays)`` and back. The tree and the arrays are read by the record's
declared field types only: nothing in them names a class, a module or a function, so
reading a state never imports or runs anything it names, and a tree that does not match
the declared types exactly (a missing or unknown field, a wrong type, an array of another
dtype or number of dimensions, an array that is not used) is refused with
:class:`RecordError` naming the field. A renamed private attribute of a detector cannot
change the format: only the records can, and each family's record has its own version.

Field types understood: ``bool``, ``int``, ``float`` (non-finite values as the strings
``nan``, ``inf``, ``-inf``), ``str``, ``X | None``, :data:`Scalar` (any of bool, int,
float, str or None, kept as JSON keeps them; a non-finite float as ``{"float": "nan"}``),
``tuple[X, ...]``, ``tuple[X, Y]``, ``dict[str, X]`` or ``Mapping[str, X]``, numpy
arrays (``numpy.ndarray``, as a record's own field; the dtype and number of dimensions
given by ``array_field(dtype, ndim)``), and nested record dataclasses. Written here
rather than taken from a serialisation library: the general ones rebuild classes named in
the data, or do not restore numpy arrays with a fixed dtype, and this check is the point.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import functools
import math
import types
import typing
from typing import Any, TypeVar, Union

import numpy as np

from rwa_monitor.exceptions import RwaMonitorError

R = TypeVar('R')
Scalar = Union[bool, int, float, str, None]
_SCALAR_ARGS = set(typing.get_args(Scalar))
_NON_FINITE = {'nan': math.nan, 'inf': math.inf, '-inf': -math.inf}
_ARRAY = 'array'
_MAPPINGS = (dict, collections.abc.Mapping)
_EXACT = (bool, int, str)


class RecordError(RwaMonitorError, ValueError):
    """A state that does not match its record's declared types (names the field)."""


def array_field(dtype: str, ndim: int, **kwargs: Any) -> Any:
    """Return a dataclass field holding a numpy array of ``dtype`` with ``ndim`` dimensions."""
    metadata = {_ARRAY: (np.dtype(dtype), ndim)}
    return dataclasses.field(metadata=metadata, **kwargs)


def evolve(record: R, **changes: Any) -> R:
    """Return ``dataclasses.replace(record, **changes)`` for a record, without its ``__init__``.

    A frozen record's ``__init__`` sets each field through ``object.__setattr__``:
    ``replace`` of a DeclaredChange (21 fields) took 15 us, and the LLR replaces it every
    ``window`` samples for as long as a declared change lasts. Here the copy takes the
    record's attributes with ``changes`` over them (3 us). Only for records without
    ``__post_init__`` (nothing derived or checked at construction, so both give equal
    records); an unknown field is a TypeError, as with ``replace``.
    """
    cls = type(record)
    unknown = changes.keys() - _field_names(cls)
    if unknown:
        raise TypeError(f'{cls.__name__} has no field(s) {", ".join(sorted(unknown))}')
    copy = object.__new__(cls)
    attributes = copy.__dict__
    attributes.update(record.__dict__)
    attributes.update(changes)
    return copy


@functools.lru_cache(maxsize=None)
def _field_names(cls: type) -> frozenset[str]:
    if hasattr(cls, '__post_init__') or not dataclasses.is_dataclass(cls):
        raise TypeError(f'{cls.__name__}: evolve is for records without __post_init__')
    return frozenset(f.name for f in dataclasses.fields(cls) if f.init)


def encode(record: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Return ``(tree, arrays)`` of a record (arrays keyed by the field's path)."""
    arrays: dict[str, np.ndarray] = {}
    tree = _encode_record(record, type(record), arrays, type(record).__name__)
    return tree, arrays


def decode(cls: type[R], tree: Any, arrays: typing.Mapping[str, np.ndarray]) -> R:
    """Return the record of type ``cls`` in ``(tree, arrays)``; RecordError if it differs.

    Every array must be used exactly once: an array no field names is refused too.
    """
    used: set[str] = set()
    record = _decode_record(cls, tree, arrays, cls.__name__, used)
    extra = sorted(set(arrays) - used)
    if extra:
        raise RecordError(f'{cls.__name__}: arrays no field names: {", ".join(extra[:5])}')
    return record


def _hints(cls: type) -> typing.Mapping[str, Any]:
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise RecordError(f'{cls!r} is not a record dataclass')
    return _type_hints(cls)


@functools.lru_cache(maxsize=256)
def _type_hints(cls: type) -> typing.Mapping[str, Any]:
    """Return the class's resolved field types, once per class (read only).

    Resolving them is the cost of decoding a record: a fleet state's history of 3,650
    events took 1.6 s in ``get_type_hints`` alone, called for every record decoded.
    """
    return types.MappingProxyType(typing.get_type_hints(cls))


@functools.lru_cache(maxsize=256)
def _fields(cls: type) -> tuple[tuple[str, Any, dataclasses.Field], ...]:
    """Return each field's name, resolved type and field object, once per class.

    With :func:`_shape`, what a record costs apart from its values: a year of a fleet's
    daily runs holds 219,000 pass records, each decoded and encoded at every run.
    """
    hints = _hints(cls)
    return tuple((f.name, hints[f.name], f) for f in dataclasses.fields(cls))


@functools.lru_cache(maxsize=1024)
def _shape(hint: Any) -> tuple[Any, tuple]:
    """Return ``(typing.get_origin(hint), typing.get_args(hint))``, once per type."""
    return typing.get_origin(hint), typing.get_args(hint)


def _encode_record(record: Any, cls: type, arrays: dict[str, np.ndarray], path: str) -> dict:
    if type(record) is not cls:
        raise RecordError(f'{path}: expected a {cls.__name__}, got {type(record).__name__}')
    out = {}
    for name, hint, field in _fields(cls):
        value = getattr(record, name)
        # The common scalars as _encode gives them, without its call (same checks).
        if (type(value) is hint and hint in _EXACT) or (
                hint is float and type(value) is float and math.isfinite(value)):
            out[name] = value
        else:
            out[name] = _encode(value, hint, field, arrays, f'{path}.{name}')
    return out


def _encode(value: Any, hint: Any, field: Any, arrays: dict[str, np.ndarray],
            path: str) -> Any:
    if hint is float:
        value = float(value)
        return value if math.isfinite(value) else repr(value)
    origin, args = _shape(hint)
    if origin in (Union, types.UnionType) and set(args) == _SCALAR_ARGS:
        return _encode_scalar(value, path)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) != 1:
            raise RecordError(f'{path}: only X | None unions are records')
        return _encode(value, inner[0], field, arrays, path)
    if hint is np.ndarray:
        dtype, ndim = _array_spec(field, path)
        array = np.asarray(value)
        if array.dtype != dtype or array.ndim != ndim:
            raise RecordError(f'{path}: expected a {ndim}-D {dtype} array, got a '
                              f'{array.ndim}-D {array.dtype} one')
        arrays[path] = np.ascontiguousarray(array)
        return {_ARRAY: path}
    if hint in (bool, int, str):
        if hint is int and isinstance(value, np.integer):
            value = int(value)
        if hint is bool and isinstance(value, np.bool_):
            value = bool(value)
        _check_scalar(value, hint, path)
        return value
    if origin is tuple:
        if _exact_items(value, args):
            return list(value)
        items = _tuple_hints(args, len(value), path)
        if value and args[-1] is Ellipsis and dataclasses.is_dataclass(args[0]):
            return [_encode_record(v, args[0], arrays, f'{path}[{i}]')
                    for i, v in enumerate(value)]
        return [_encode(v, h, None, arrays, f'{path}[{i}]')
                for i, (v, h) in enumerate(zip(value, items))]
    if origin in _MAPPINGS:
        if args[0] is not str:
            raise RecordError(f'{path}: dict keys must be str')
        return {str(k): _encode(v, args[1], None, arrays, f'{path}[{k}]')
                for k, v in value.items()}
    if dataclasses.is_dataclass(hint):
        return _encode_record(value, hint, arrays, path)
    raise RecordError(f'{path}: type {hint!r} is not a record type')


def _decode_record(cls: type, tree: Any, arrays: typing.Mapping[str, np.ndarray],
                   path: str, used: set[str]) -> Any:
    fields = _fields(cls)
    if not isinstance(tree, dict):
        raise RecordError(f'{path}: expected an object, got {type(tree).__name__}')
    if len(tree) != len(fields) or any(name not in tree for name, _, _ in fields):
        names = [name for name, _, _ in fields]
        missing = [n for n in names if n not in tree]
        unknown = [k for k in tree if k not in names]
        raise RecordError(f'{path}: ' + '; '.join(
            part for part in (missing and f'missing {", ".join(missing)}',
                              unknown and f'unknown {", ".join(map(str, unknown))}') if part))
    values = {}
    for name, hint, field in fields:
        value = tree[name]
        # The common scalars as _decode takes them, without its call (same checks).
        if (type(value) is hint and hint in _EXACT) or (
                hint is float and type(value) is float and math.isfinite(value)):
            values[name] = value
        else:
            values[name] = _decode(value, hint, field, arrays, f'{path}.{name}', used)
    return cls(**values)


def _decode(tree: Any, hint: Any, field: Any, arrays: typing.Mapping[str, np.ndarray],
            path: str, used: set[str]) -> Any:
    if hint is float:
        if isinstance(tree, str) and tree in _NON_FINITE:
            return _NON_FINITE[tree]
        if type(tree) not in (int, float) or (type(tree) is float and not math.isfinite(tree)):
            raise RecordError(f'{path}: expected a number, got {tree!r:.40}')
        return float(tree)
    origin, args = _shape(hint)
    if origin in (Union, types.UnionType) and set(args) == _SCALAR_ARGS:
        return _decode_scalar(tree, path)
    if origin in (Union, types.UnionType):
        if tree is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _decode(tree, inner[0], field, arrays, path, used)
    if hint is np.ndarray:
        dtype, ndim = _array_spec(field, path)
        if not isinstance(tree, dict) or set(tree) != {_ARRAY} or tree[_ARRAY] != path:
            raise RecordError(f'{path}: expected the array reference {path!r}')
        if path not in arrays:
            raise RecordError(f'{path}: its array is missing')
        array = arrays[path]
        if not isinstance(array, np.ndarray) or array.dtype != dtype or array.ndim != ndim:
            raise RecordError(f'{path}: expected a {ndim}-D {dtype} array, got '
                              f'{getattr(array, "ndim", "?")}-D '
                              f'{getattr(array, "dtype", type(array).__name__)}')
        used.add(path)
        return np.array(array)
    if hint in (bool, int, str):
        _check_scalar(tree, hint, path)
        return tree
    if origin is tuple:
        if not isinstance(tree, list):
            raise RecordError(f'{path}: expected a list, got {type(tree).__name__}')
        if _exact_items(tree, args):
            return tuple(tree)
        items = _tuple_hints(args, len(tree), path)
        if tree and args[-1] is Ellipsis and dataclasses.is_dataclass(args[0]):
            return tuple(_decode_record(args[0], v, arrays, f'{path}[{i}]', used)
                         for i, v in enumerate(tree))
        return tuple(_decode(v, h, None, arrays, f'{path}[{i}]', used)
                     for i, (v, h) in enumerate(zip(tree, items)))
    if origin in _MAPPINGS:
        if not isinstance(tree, dict):
            raise RecordError(f'{path}: expected an object, got {type(tree).__name__}')
        return {k: _decode(v, args[1], None, arrays, f'{path}[{k}]', used)
                for k, v in tree.items()}
    if dataclasses.is_dataclass(hint):
        return _decode_record(hint, tree, arrays, path, used)
    raise RecordError(f'{path}: type {hint!r} is not a record type')


def _encode_scalar(value: Any, path: str) -> Any:
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or type(value) in (bool, int, str):
        return value
    if type(value) is float:
        return value if math.isfinite(value) else {'float': repr(value)}
    raise RecordError(f'{path}: expected a bool, int, float, str or None, got '
                      f'{type(value).__name__}')


def _decode_scalar(tree: Any, path: str) -> Any:
    if tree is None or type(tree) in (bool, int, str):
        return tree
    if type(tree) is float and math.isfinite(tree):
        return tree
    if isinstance(tree, dict) and set(tree) == {'float'} and tree['float'] in _NON_FINITE:
        return _NON_FINITE[tree['float']]
    raise RecordError(f'{path}: expected a bool, int, float, str or null, got {tree!r:.40}')


def _check_scalar(value: Any, hint: type, path: str) -> None:
    # bool is an int in Python: a declared int takes no bool, a declared bool only bools.
    if type(value) is not hint:
        raise RecordError(f'{path}: expected {hint.__name__}, got {value!r:.40}')


def _exact_items(values: Any, args: tuple) -> bool:
    """Return True for a ``tuple[X, ...]`` of bool, int or str whose items are all exactly X.

    Such a tuple is its own tree, item for item (the checks of :func:`_check_scalar`, in
    one pass): a fleet state's pass log holds a name for each of a year's passes.
    """
    if len(args) != 2 or args[1] is not Ellipsis or args[0] not in _EXACT:
        return False
    kind = args[0]
    return all(type(v) is kind for v in values)


def _tuple_hints(args: tuple, size: int, path: str) -> tuple:
    if len(args) == 2 and args[1] is Ellipsis:
        return (args[0],) * size
    if len(args) != size:
        raise RecordError(f'{path}: expected {len(args)} items, got {size}')
    return args


def _array_spec(field: Any, path: str) -> tuple[np.dtype, int]:
    spec = field.metadata.get(_ARRAY) if field is not None else None
    if spec is None:
        raise RecordError(f'{path}: an array field needs array_field(dtype, ndim)')
    return spec
