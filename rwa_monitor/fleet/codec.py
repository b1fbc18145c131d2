"""A detector's state as data: a JSON tree plus named numpy arrays, never pickle.

:func:`encode` walks an object's instance attributes and returns a JSON-ready tree in
which every numpy array is replaced by a reference into a dict of arrays (saved as
``.npz``). Only the classes of :data:`DATA_CLASSES` are walked and only those of
:data:`CONFIG_CLASSES` are passed over (a detector's configuration objects, rebuilt from
its parameters); anything else is refused with :class:`StateError` naming the class, so
a detector that gains a new kind of attribute fails loudly rather than being half saved.
To let a new class be saved, add it to the registry below (one place). Written here
rather than taken from a library: pickle runs code on load (never on disk here), and the
general serialisers neither restrict the classes they rebuild nor restore into views of
a detector's shared state arrays.

:func:`restore` puts a tree back into a freshly constructed detector with the same
parameters, in place: an array whose shape and dtype match the fresh one is copied into
it with ``numpy.copyto`` (some attributes are views of one shared state array and must
stay so), dicts and lists of the same length are restored item by item, registered
objects attribute by attribute; everything else is rebuilt from the tree.

Tree tags (docs/contracts.md "Fleet state"): ``$array`` (key into the arrays),
``$float`` (a non-finite float by its repr), ``$scalar`` (a numpy scalar: dtype and
value), ``$tuple``, ``$set``, ``$deque`` (items, maxlen), ``$dict`` (key/value pairs),
``$object`` (registered class name and attributes), ``$config`` (configuration object,
not saved). Plain lists, str, int, bool, None and finite floats are themselves.
"""

from __future__ import annotations

from collections import deque
import importlib
import math
from typing import Any

import numpy as np

from rwa_monitor.exceptions import RwaMonitorError

# The registry: module -> class names (the tree names a class by its own module). A name
# a module does not have is skipped, so the list may name the classes of the detector's
# past and next layouts (a typed record of the last change, ring views) side by side.
DATA_CLASSES: dict[str, tuple[str, ...]] = {
    'rwa_monitor.core.llr_detector': ('LLRDetector',),
    'rwa_monitor.core.llr_noise': ('NoiseModel',),
    'rwa_monitor.core.llr_changes': ('DeclaredChange',),
    'rwa_monitor.core.events': ('AnomalyEvent',),
    'rwa_monitor.core.vsadc': ('VsadcDetector', 'VsadcAxis', '_Window', '_SlidingMax',
                               'Transition'),
    'rwa_monitor.core.gyro_diagnosis': ('GyroDiagnosis',),
    'rwa_monitor.core.gyro_residual': ('ResidualAxis',),
    'rwa_monitor.core.gyro_rows': ('GyroRows',),
    'rwa_monitor.core.attitude': ('StarTrackerRate',),
}
CONFIG_CLASSES: dict[str, tuple[str, ...]] = {
    'rwa_monitor.core.friction': ('RegressorSet',),
}


class StateError(RwaMonitorError, ValueError):
    """A state that cannot be saved or restored (names the class or the attribute)."""


def _name(cls: type) -> str:
    return f'{cls.__module__}.{cls.__qualname__}'


def _classes(registry: dict[str, tuple[str, ...]]) -> dict[str, type]:
    found = {}
    for module, names in registry.items():
        loaded = importlib.import_module(module)
        for name in names:
            cls = getattr(loaded, name, None)
            if not isinstance(cls, type) or cls.__module__ != module:
                raise StateError(f'state registry: {module}.{name} is not a class defined '
                                 f'there (moved or renamed? update DATA_CLASSES)')
            found[_name(cls)] = cls
    return found


_DATA: dict[str, type] = {}
_CONFIG: dict[str, type] = {}


def _registered() -> tuple[dict[str, type], dict[str, type]]:
    if not _DATA:
        _DATA.update(_classes(DATA_CLASSES))
        _CONFIG.update(_classes(CONFIG_CLASSES))
    return _DATA, _CONFIG


def _attributes(obj: Any) -> dict[str, Any]:
    """Return an object's instance attributes: its ``__dict__`` and filled ``__slots__``."""
    attrs = dict(getattr(obj, '__dict__', {}))
    for cls in type(obj).__mro__:
        for slot in getattr(cls, '__slots__', ()):
            if slot != '__dict__' and hasattr(obj, slot):
                attrs[slot] = getattr(obj, slot)
    return attrs


def encode(value: Any) -> tuple[Any, dict[str, np.ndarray]]:
    """Return ``(tree, arrays)`` of a registered object (module doc); raise StateError."""
    arrays: dict[str, np.ndarray] = {}
    return _encode(value, arrays, 'state'), arrays


def _encode(value: Any, arrays: dict[str, np.ndarray], where: str) -> Any:
    kind = type(value)
    if value is None or kind in (bool, str, int):
        return value
    if kind is float:
        return value if math.isfinite(value) else {'$float': repr(value)}
    if kind is np.ndarray:
        key = f'a{len(arrays)}'
        arrays[key] = value
        return {'$array': key}
    if isinstance(value, np.generic):
        return {'$scalar': value.dtype.str, 'value': _encode(value.item(), arrays, where)}
    if kind is list:
        return [_encode(v, arrays, f'{where}[{i}]') for i, v in enumerate(value)]
    if kind is tuple:
        return {'$tuple': [_encode(v, arrays, f'{where}[{i}]') for i, v in enumerate(value)]}
    if kind in (set, frozenset):
        items = sorted(value, key=repr)
        return {'$set': [_encode(v, arrays, where) for v in items]}
    if kind is deque:
        return {'$deque': [_encode(v, arrays, where) for v in value], 'maxlen': value.maxlen}
    if kind is dict:
        return {'$dict': [[_encode(k, arrays, where), _encode(v, arrays, f'{where}[{k!r}]')]
                          for k, v in value.items()]}
    data, config = _registered()
    name = _name(kind)
    if name in config:
        return {'$config': name}
    if name not in data:
        raise StateError(f'{where}: cannot save a {name} (not in the allowlist of '
                         'rwa_monitor/fleet/codec.py)')
    if isinstance(value, tuple):     # a NamedTuple
        return {'$object': name, 'items': [_encode(v, arrays, f'{where}.{f}')
                                           for f, v in zip(kind._fields, value)]}
    return {'$object': name, 'attrs': {k: _encode(v, arrays, f'{where}.{k}')
                                       for k, v in _attributes(value).items()}}


def restore(into: Any, tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    """Return the value of ``tree``, restored in place into ``into`` where it fits."""
    if type(tree) is list:
        if type(into) is list and len(into) == len(tree):
            for i, item in enumerate(tree):
                into[i] = restore(into[i], item, arrays)
            return into
        return [restore(None, item, arrays) for item in tree]
    if type(tree) is not dict:
        return tree
    if '$array' in tree:
        saved = arrays[tree['$array']]
        if type(into) is np.ndarray and into.shape == saved.shape and \
                into.dtype == saved.dtype:
            np.copyto(into, saved)
            return into
        return np.array(saved)
    if '$float' in tree:
        return float(tree['$float'])
    if '$scalar' in tree:
        return np.dtype(tree['$scalar']).type(tree['value'])
    if '$tuple' in tree:
        return tuple(restore(None, v, arrays) for v in tree['$tuple'])
    if '$set' in tree:
        return {restore(None, v, arrays) for v in tree['$set']}
    if '$deque' in tree:
        return deque((restore(None, v, arrays) for v in tree['$deque']), tree['maxlen'])
    if '$dict' in tree:
        return _restore_dict(into, tree['$dict'], arrays)
    if '$config' in tree:
        if into is None or _name(type(into)) != tree['$config']:
            raise StateError(f'a {tree["$config"]} is rebuilt from the parameters, but the '
                             f'new detector holds {_name(type(into))} there')
        return into
    return _restore_object(into, tree, arrays)


def _restore_dict(into: Any, pairs: list, arrays: dict[str, np.ndarray]) -> dict:
    keys = [restore(None, k, arrays) for k, _ in pairs]
    target = into if type(into) is dict else {}
    for key in [k for k in target if k not in keys]:
        del target[key]
    for key, (_, value) in zip(keys, pairs):
        target[key] = restore(target.get(key), value, arrays)
    return target


def _restore_object(into: Any, tree: dict, arrays: dict[str, np.ndarray]) -> Any:
    data, _ = _registered()
    name = tree.get('$object')
    if name not in data:
        raise StateError(f'a state holds a {name}, which is not in the allowlist')
    cls = data[name]
    if 'items' in tree:
        return cls._make(restore(None, v, arrays) for v in tree['items'])
    target = into if type(into) is cls else cls.__new__(cls)
    fresh = _attributes(target) if target is into else {}
    for key, value in tree['attrs'].items():
        # object.__setattr__ also sets the fields of a frozen dataclass.
        object.__setattr__(target, key, restore(fresh.get(key), value, arrays))
    return target
