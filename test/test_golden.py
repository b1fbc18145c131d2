"""Before/after: the events of `detect` and `diagnose` on the stored golden files do not move.

The expected JSON was written by test/golden_cases.py before the parameter schema and the
detector protocol were introduced; wall-clock timings and the input path are left out of
the comparison (golden_cases.VOLATILE_KEYS), everything else must be identical.
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
    assert got == expected


def test_volatile_keys_are_dropped():
    document = {'runtime_s': 1.0, 'a': [{'timings_s': {}, 'source': 'x', 'b': 2}]}
    assert golden_cases.stable(document) == {'a': [{'b': 2}]}
