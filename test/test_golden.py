"""Before/after: the events of `detect` and `diagnose` on the stored golden files do not move.

The expected JSON was written by test/golden_cases.py before the parameter schema and the
detector protocol were introduced; wall-clock timings and the input path are left out of
the comparison (golden_cases.VOLATILE_KEYS). Events must be identical; the summary must
keep every stored value, and may gain keys added on purpose later (e.g. which detectors ran
and which components were not examined).
"""

import json

import golden_cases
import pytest


def test_golden_files_are_small():
    for name in golden_cases.FILES:
        assert golden_cases.data_file(name).stat().st_size < 200_000


@pytest.mark.parametrize('command,name,args', golden_cases.RUNS,
                         ids=[f'{c}-{n}-{"config" if a else "defaults"}'
                              for c, n, a in golden_cases.RUNS])
def test_events_identical(tmp_path, command, name, args):
    expected = json.loads(golden_cases.expected_file(command, name, args).read_text())
    got = golden_cases.run(command, name, args, tmp_path / 'out.json')
    assert got['events' if command == 'detect' else 'wheels'] == \
        expected['events' if command == 'detect' else 'wheels']
    assert _missing_or_changed(expected, got) == []


def _missing_or_changed(expected, got, path=''):
    """Return the paths whose stored value is absent from ``got`` or different."""
    if isinstance(expected, dict) and isinstance(got, dict):
        return [p for key, value in expected.items()
                for p in (_missing_or_changed(value, got[key], f'{path}/{key}')
                          if key in got else [f'{path}/{key} (missing)'])]
    return [] if expected == got else [path]


def test_summary_comparison_names_what_moved():
    assert _missing_or_changed({'a': {'b': 1, 'c': 2}}, {'a': {'b': 1, 'c': 3, 'd': 4}}) == \
        ['/a/c']
    assert _missing_or_changed({'a': 1}, {}) == ['/a (missing)']


def test_volatile_keys_are_dropped():
    document = {'runtime_s': 1.0, 'a': [{'timings_s': {}, 'source': 'x', 'b': 2}]}
    assert golden_cases.stable(document) == {'a': [{'b': 2}]}
