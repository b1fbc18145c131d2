"""The public API's docstrings: numpydoc sections and a runnable example each, run here.

Every name of ``rwa_monitor.__all__`` is either checked or listed below with its reason:
nothing is skipped silently. A function needs Parameters, Returns and Examples; a class
Parameters (every constructor argument named) and Examples; a protocol Examples (its
``update`` documents the parameters). The examples run as doctests on the object's own
docstring.
"""

import doctest
import inspect
import re

import pytest

import rwa_monitor

# Data, not callables: they have no docstring of their own (the str and dict types'); the
# package docstring and docs/parameters.md say what they are.
DATA = {'AUTO': 'the str spelling of an automatic value',
        'SCHEMAS': 'the dict of parameter schemas (docs/parameters.md)'}

NAMES = sorted(set(rwa_monitor.__all__) - set(DATA))


def _param(name):
    return pytest.param(name, id=name)


def _sections(doc):
    """Return section title -> body of a numpydoc docstring."""
    doc = inspect.cleandoc(doc)
    parts = re.split(r'^(\w[\w ]*)\n-{3,}\n', doc, flags=re.M)
    return {title: body for title, body in zip(parts[1::2], parts[2::2])}


def _documented_names(body):
    """Return the names a Parameters section documents (``a, b : type`` lines)."""
    names = set()
    for line in body.splitlines():
        if line and not line[0].isspace():
            names.update(n.strip().lstrip('*') for n in line.split(':')[0].split(','))
    return names


def _is_protocol(obj):
    return getattr(obj, '_is_protocol', False)


def test_every_public_name_is_checked_or_listed():
    assert set(NAMES) | set(DATA) == set(rwa_monitor.__all__)
    for name in DATA:
        assert not callable(getattr(rwa_monitor, name))


@pytest.mark.parametrize('name', [_param(n) for n in NAMES])
def test_docstring_has_the_numpydoc_sections(name):
    obj = getattr(rwa_monitor, name)
    sections = _sections(obj.__doc__ or '')
    if inspect.isfunction(obj):
        needed = {'Parameters', 'Returns', 'Examples'}
    elif _is_protocol(obj):
        needed = {'Examples'}
    else:
        needed = {'Parameters', 'Examples'}
    assert needed <= set(sections), f'{name}: missing {needed - set(sections)}'
    if 'Parameters' in needed:
        arguments = set(inspect.signature(obj).parameters) - {'self'}
        assert arguments <= _documented_names(sections['Parameters']), name


@pytest.mark.parametrize('name', [_param(n) for n in NAMES])
def test_examples_run(name):
    obj = getattr(rwa_monitor, name)
    module = inspect.getmodule(obj)
    tests = doctest.DocTestFinder(recurse=False).find(obj, name, module=module,
                                                      globs=vars(module).copy())
    examples = sum(len(t.examples) for t in tests)
    assert examples >= 1, f'{name}: no example'
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    for test in tests:
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted == examples
