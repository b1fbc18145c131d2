"""Typed state records (core/records.py): round trips, and every mismatch refused."""

from __future__ import annotations

import dataclasses
import json
import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from rwa_monitor.core import records
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.records import array_field, RecordError


@dataclasses.dataclass(frozen=True)
class Inner:
    """A nested record."""

    level: float
    counts: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class Outer:
    """A record with every kind of field."""

    values: np.ndarray = array_field('float64', 1)
    name: str = 'rw1'
    inner: Inner | None = None
    by_name: dict[str, Inner] = dataclasses.field(default_factory=dict)
    flag: bool = False
    event: AnomalyEvent | None = None


def _sample() -> Outer:
    event = AnomalyEvent('llr', 'rw1', 'dry', 1.0, 10, 2.0, 20, math.nan, 1,
                         {'final': True, 'z_dry': math.inf, 'kind_shape': 'step', 'n': 3})
    return Outer(np.array([1.0, math.nan, -math.inf]), 'rw2', Inner(math.nan, (1, 2)),
                 {'a': Inner(1.5, ())}, True, event)


def _same(a: Outer, b: Outer) -> bool:
    return (np.array_equal(a.values, b.values, equal_nan=True) and repr(a.inner) == repr(b.inner)
            and a.by_name == b.by_name and a.flag is b.flag and repr(a.event) == repr(b.event))


def test_round_trip_through_json_keeps_every_value():
    record = _sample()
    tree, arrays = records.encode(record)
    back = records.decode(Outer, json.loads(json.dumps(tree, allow_nan=False)), arrays)
    assert _same(record, back)
    assert back.values.dtype == np.float64


@pytest.mark.parametrize('edit, message', [
    (lambda t: t.update(flag=1), 'expected bool'),
    (lambda t: t.update(extra=1), 'unknown extra'),
    (lambda t: t.pop('name'), 'missing name'),
    (lambda t: t['inner'].update(counts=[1, True]), 'expected int'),
    (lambda t: t['inner'].update(level=None), 'expected a number'),
    (lambda t: t.update(values={'array': 'Outer.other'}), 'array reference'),
    (lambda t: t['event'].update(details={'x': [1]}), 'expected a bool, int, float'),
    (lambda t: t.update(by_name=[]), 'expected an object'),
])
def test_a_tree_that_differs_from_the_declared_types_is_refused(edit, message):
    tree, arrays = records.encode(_sample())
    tree = json.loads(json.dumps(tree))
    edit(tree)
    with pytest.raises(RecordError, match=message):
        records.decode(Outer, tree, arrays)


def test_arrays_of_another_dtype_shape_or_unused_are_refused():
    tree, arrays = records.encode(_sample())
    with pytest.raises(RecordError, match='float64'):
        records.decode(Outer, tree, {'Outer.values': np.zeros(3, dtype=np.int64)})
    with pytest.raises(RecordError, match='1-D'):
        records.decode(Outer, tree, {'Outer.values': np.zeros((3, 1))})
    with pytest.raises(RecordError, match='no field names'):
        records.decode(Outer, tree, {**arrays, 'stray': np.zeros(1)})
    with pytest.raises(RecordError, match='missing'):
        records.decode(Outer, tree, {})


def test_encoding_refuses_values_that_are_not_the_declared_types():
    with pytest.raises(RecordError, match='2-D'):
        records.encode(dataclasses.replace(_sample(), values=np.zeros((2, 2))))
    with pytest.raises(RecordError, match='expected a Inner'):
        records.encode(dataclasses.replace(_sample(), inner=(1.0, ())))


_JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False)
                     | st.text(max_size=8),
                     lambda inner: st.lists(inner, max_size=4)
                     | st.dictionaries(st.text(max_size=8), inner, max_size=4), max_leaves=20)


@settings(max_examples=300, deadline=None)
@given(path=st.lists(st.sampled_from(['values', 'name', 'inner', 'by_name', 'flag', 'event',
                                      'level', 'counts', 'details', 'kind', 'time']),
                     min_size=1, max_size=3), value=_JSON)
def test_any_edit_of_the_tree_is_decoded_exactly_or_refused(path, value):
    tree, arrays = records.encode(_sample())
    tree = json.loads(json.dumps(tree))
    node = tree
    for key in path[:-1]:
        if not isinstance(node, dict) or not isinstance(node.get(key), dict):
            break
        node = node[key]
    node[path[-1]] = value
    try:
        back = records.decode(Outer, tree, arrays)
    except RecordError:
        return
    again, _ = records.encode(back)
    assert json.loads(json.dumps(again)) == json.loads(json.dumps(tree))


def test_evolve_gives_what_replace_gives_and_leaves_the_record():
    record = _sample()
    for changes in ({}, {'name': 'rw3'}, {'flag': False, 'inner': None},
                    {'values': np.zeros(2), 'by_name': {}}):
        evolved = records.evolve(record, **changes)
        assert type(evolved) is Outer and _same(evolved, dataclasses.replace(record, **changes))
    assert _same(record, _sample())
    with pytest.raises(dataclasses.FrozenInstanceError):
        records.evolve(record, name='rw3').name = 'rw4'


def test_evolve_refuses_unknown_fields_and_records_that_check_themselves():
    with pytest.raises(TypeError, match='no field'):
        records.evolve(_sample(), nme='rw3')

    @dataclasses.dataclass(frozen=True)
    class Checked:
        level: float

        def __post_init__(self) -> None:
            assert self.level >= 0

    with pytest.raises(TypeError, match='__post_init__'):
        records.evolve(Checked(1.0), level=-1.0)
