"""Before/after: the events of `detect` and `diagnose` on the stored golden files do not move.

The expected JSON was written by test/golden_cases.py before the parameter schema and the
detector protocol were introduced; wall-clock timings and the input path are left out of
the comparison (golden_cases.VOLATILE_KEYS). Events must be identical; the summary must
keep every stored value, and may gain keys added on purpose later (e.g. which detectors ran
and which components were not examined). The stored floats of the detect runs were
rewritten once, on 2026-11-28, when the LLR's least-squares solves moved from numpy's pinv
to compiled Jacobi rotations (docs/llr.md "Change time refinement"): 73 floats moved, by
at most 5.2e-7 relative (a z of 0.03), and no index, kind, count or other value.

Indices, kinds, counts and every other non-float value must be equal. Floats must agree to
FLOAT_RTOL: the statistics behind z_dry, z_viscous and the deltas go through the BLAS/LAPACK
of numpy and scipy, whose kernels are chosen per CPU at run time (OpenBLAS DYNAMIC_ARCH), so
their last digits differ between machines (seen: relative 4e-11 between two x86-64 CPUs).
A real change of the algorithm moves them by far more than 1e-9. The z statistics are
differences of such numbers, which amplifies those last digits: they are compared to Z_ATOL
absolutely and Z_RTOL relatively (seen: 3e-10 on a z of 0.03; relative 1.2e-8 on a z of 91.6
between an AVX2 and an AVX-512 machine), where a decision needs a change of order 1.
"""

import json
import math

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
    key = 'events' if command == 'detect' else 'wheels'
    assert _missing_or_changed(expected[key], got[key]) == []
    assert _missing_or_changed(got[key], expected[key]) == []
    assert _missing_or_changed(expected, got) == []


FLOAT_RTOL = 1e-9
Z_ATOL = 1e-8
Z_RTOL = 1e-7


def _missing_or_changed(expected, got, path=''):
    """Return the paths whose stored value is absent from ``got`` or different."""
    if isinstance(expected, dict) and isinstance(got, dict):
        return [p for key, value in expected.items()
                for p in (_missing_or_changed(value, got[key], f'{path}/{key}')
                          if key in got else [f'{path}/{key} (missing)'])]
    if isinstance(expected, list) and isinstance(got, list):
        if len(expected) != len(got):
            return [f'{path} (length {len(got)}, stored {len(expected)})']
        return [p for i, (e, g) in enumerate(zip(expected, got))
                for p in _missing_or_changed(e, g, f'{path}/{i}')]
    if type(expected) is float and type(got) is float:
        z = path.rsplit('/', 1)[-1].startswith('z_')
        atol, rtol = (Z_ATOL, Z_RTOL) if z else (0.0, FLOAT_RTOL)
        return [] if math.isclose(expected, got, rel_tol=rtol, abs_tol=atol) else [path]
    return [] if expected == got and type(expected) is type(got) else [path]


def test_summary_comparison_names_what_moved():
    assert _missing_or_changed({'a': {'b': 1, 'c': 2}}, {'a': {'b': 1, 'c': 3, 'd': 4}}) == \
        ['/a/c']
    assert _missing_or_changed({'a': 1}, {}) == ['/a (missing)']


def test_floats_agree_to_the_tolerance_and_nothing_else_moves():
    assert _missing_or_changed([{'z': 1.2665296660817826}], [{'z': 1.2665296660798069}]) == []
    assert _missing_or_changed([{'z': 1.0}], [{'z': 1.0 + 1e-7}]) == ['/0/z']
    assert _missing_or_changed([{'z_dry': -0.0313059133}], [{'z_dry': -0.0313059130}]) == []
    assert _missing_or_changed([{'z_dry': 0.0}], [{'z_dry': 1e-7}]) == ['/0/z_dry']
    assert _missing_or_changed([{'z_viscous': 91.5957943}], [{'z_viscous': 91.5957954}]) == []
    assert _missing_or_changed([{'z_viscous': 91.59}], [{'z_viscous': 91.60}]) == \
        ['/0/z_viscous']
    assert _missing_or_changed([{'index': 999}], [{'index': 1000}]) == ['/0/index']
    assert _missing_or_changed([{'index': 999}], [{'index': 999.0}]) == ['/0/index']
    assert _missing_or_changed([1, 2], [1]) == [' (length 1, stored 2)']


def test_volatile_keys_are_dropped():
    document = {'runtime_s': 1.0, 'a': [{'timings_s': {}, 'source': 'x', 'b': 2}]}
    assert golden_cases.stable(document) == {'a': [{'b': 2}]}
