"""The audit's cases of issue 36 (main 91ca172), each failing there, and their causes.

Each case of bench/faults_audit.py runs the real command and raises AssertionError on a
wrong behaviour; the tests below pin the causes in the code that had them.
"""

import json
import math

import numpy as np
import pytest

from bench.faults_audit import CASES
from rwa_monitor.cli.output import json_text
from rwa_monitor.core.fss.assign import assign_changepoints
from rwa_monitor.core.fss.model import DEFAULT_SYSTEMS
from rwa_monitor.core.fss.pipeline import diagnose, FssConfig, plausible
from rwa_monitor.core.schema import FSS, LLR


@pytest.mark.parametrize('case', [c for _, c in CASES], ids=[n for n, _ in CASES])
def test_fault_case(case, tmp_path):
    outcome = case(tmp_path)
    assert isinstance(outcome, str) and '\n' not in outcome


def test_the_diagnoser_has_the_detectors_plausibility_limits():
    for name in ('max_abs_speed', 'max_abs_friction'):
        assert FSS[name] is LLR[name]           # one definition (core/schema.py)
        assert getattr(FssConfig(), name) == LLR[name].default
    speed = np.array([1.0, 1e5, -1e5 + 1, np.nan, 2.0])
    friction = np.array([1e-4, 1e-4, 1e-4, 1e-4, -1e3])
    w, f, counts = plausible(speed, friction, FssConfig())
    assert counts == {'non_finite': 1, 'out_of_range': 2}
    assert np.isfinite(w).tolist() == [True, False, True, False, False]
    assert np.array_equal(np.isfinite(w), np.isfinite(f))


def test_a_window_with_values_no_wheel_has_is_diagnosed_on_the_rest():
    rng = np.random.default_rng(361)
    t = np.arange(4000) * 0.1
    speed = 200.0 + 150.0 * np.sin(t / 20.0)
    friction = -2e-4 - 5e-7 * speed + rng.normal(0, 5e-5, t.size)
    bad = rng.choice(t.size, 40, replace=False)
    friction[bad] = -1e300
    from rwa_monitor import load_fss_model
    result = diagnose(speed, friction, t, load_fss_model())
    assert result['rejected'] == {'non_finite': 0, 'out_of_range': 40}
    assert 3e-5 < result['estimates']['noise_std_nm'] < 8e-5


def test_the_assignment_refuses_a_non_finite_rejection_cost():
    """An infinite cost dropped every state of a stage: IndexError at assign.py 132."""
    with pytest.raises(ValueError, match='reject_cost must be finite'):
        assign_changepoints(np.array([10, 20]), np.array([1, -1]),
                            np.array([1.0, math.inf]), 100, DEFAULT_SYSTEMS)


def test_json_text_is_strict():
    text = json_text({'a': math.nan, 'b': [math.inf, -math.inf, 1.5], 'c': np.float64('nan')})
    assert json.loads(text) == {'a': None, 'b': [None, None, 1.5], 'c': None}
    for word in ('NaN', 'Infinity'):
        assert word not in text
