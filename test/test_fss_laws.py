"""Switching laws from commissioning data, the least-squares baseline, relative features."""

import numpy as np
import pytest

from rwa_monitor.core.fss import baseline
from rwa_monitor.core.fss.classify import relative_features
from rwa_monitor.core.fss.laws import estimate_systems, uniform_range
from rwa_monitor.core.fss.model import DEFAULT_SYSTEMS, EXAMPLE_1
from rwa_monitor.core.fss.pipeline import FssConfig
from rwa_monitor.sim import fss


def test_uniform_range_recovers_the_law():
    # 4000 draws of U{50..150}: the 0.1 and 0.9 sample quantiles have standard errors
    # sqrt(0.09 / 4000) x 101 ~ 0.5 steps, so the range is found within a few steps.
    x = np.random.default_rng(0).integers(50, 151, 4000)
    lo, hi = uniform_range(x)
    assert abs(lo - 50) <= 3 and abs(hi - 150) <= 3
    assert uniform_range([10, 20], [35]) == (10, 35)  # a censored sojourn raises hi
    assert uniform_range([]) is None


def test_laws_estimated_from_nominal_windows():
    windows = []
    for j in range(5):
        rng = np.random.default_rng(np.random.SeedSequence(5, spawn_key=(j,)))
        sig = fss.simulate_wheel(fss.WINDOW_SAMPLES, 'nominal', rng)
        windows.append((sig['speed'], sig['friction']))
    systems, report = estimate_systems(windows, DEFAULT_SYSTEMS, FssConfig())
    fast, slow = systems
    # ~330 activations and as many inactive sojourns (Example 1: U{1..200}, U{1..2000}):
    # quantile matching errs by ~1 % of the range (sd), plus activations shorter than
    # the wGLR window that stage 1 misses; bounds 15 % of the range.
    assert fast.residence[1][1] == pytest.approx(200, abs=30)
    assert fast.residence[0][1] == pytest.approx(2000, abs=300)
    assert fast.residence[1][0] <= 30
    # The slow system (Example 2, U{10001..30000}) jumps ~3 times per window: a few tens
    # of sojourns; its lo is bounded below by the fast system's longest residence.
    assert fast.residence[0][1] < slow.residence[0][0] <= 12_000
    assert 18_000 <= slow.residence[0][1] <= 40_000
    assert report['windows'] == 5 and len(report['history']) == 3
    assert [s.name for s in systems] == [s.name for s in DEFAULT_SYSTEMS]
    assert fast.levels == EXAMPLE_1.levels  # levels are not estimated (Remark 1)


def test_baseline_is_zero_on_its_own_reference_and_flags_above_threshold():
    rng = np.random.default_rng(3)
    speed = fss.spin_profile(20_000, rng, kind='biased')
    friction = 1.2 * np.sign(speed) + 0.9 * speed + rng.normal(0.0, 0.025, speed.size)
    summary = baseline.ls_summary(speed, friction, np.array([], int))
    # One interval: the dry level is the single LS coefficient, its spread 0. Noise 0.025
    # on 20000 samples: the coefficients' standard errors are ~1e-3 or less (bound 5 %).
    assert summary['dry_range'] == 0.0
    assert summary['viscous'] == pytest.approx(0.9, rel=0.05)
    assert summary['dry'] == pytest.approx(1.2, rel=0.05)
    scores = baseline.baseline_scores(summary, summary)
    assert all(v == 0.0 for v in scores.values() if np.isfinite(v))
    nominal = [{k: float(v) for k, v in zip(baseline.KINDS, row)}
               for row in np.linspace(0.0, 1.0, 101)[:, None].repeat(4, axis=1)]
    thresholds = baseline.nominal_thresholds(nominal, 0.05)
    assert thresholds['dry'] == pytest.approx(0.95)
    flags = baseline.baseline_flags({'dry': 0.96, 'viscous': 0.5, 'fss1': np.nan,
                                     'fss2': 2.0}, thresholds)
    assert flags == {'dry': True, 'viscous': False, 'fss1': False, 'fss2': True}
    with pytest.raises(ValueError, match='false_rate'):
        baseline.nominal_thresholds(nominal, 0.0)


def test_relative_features_make_the_reference_one():
    ref = {'base_dry': 2.0, 'viscous': 0.5, 'levels': [[0.0, 0.6], [0.0]]}
    window = {'base_dry': 3.0, 'viscous': 0.75, 'levels': [[0.0, 0.8], [0.0, 1.0]]}
    rel = relative_features(window, ref)
    assert rel == {'base_dry': 1.5, 'viscous': 1.5, 'levels': [[0.0, 0.4], [0.0, 0.5]]}
    assert relative_features(ref, ref)['base_dry'] == 1.0
    with pytest.raises(ValueError, match='positive'):
        relative_features(window, {**ref, 'viscous': 0.0})


def test_size_table_helpers():
    from bench.fss_sizes import _roc, smallest_found, verdicts
    assert smallest_found({1.1: 0.5, 1.5: 0.95, 2.0: 0.9, 3.0: 1.0}) == 1.5
    assert smallest_found({1.1: 0.95, 1.5: 0.8, 3.0: 1.0}) == 3.0
    assert smallest_found({1.1: 0.1, 3.0: 0.5}) is None
    separated = _roc(np.array([2.0, 3.0]), np.array([0.0, 1.0]))
    assert separated['auc'] == 1.0 and separated['detection_at_5pct_false'] == 1.0
    # Scores of one law for both classes: the AUC estimates P(X > Y) = 1/2; with 2000
    # draws each its standard error is ~0.009 (bound 5 sd).
    rng = np.random.default_rng(0)
    same = _roc(rng.normal(size=2000), rng.normal(size=2000))
    assert abs(same['auc'] - 0.5) < 0.045
    rows = [{'status': 'anomalous', 'flags': {'dry': True, 'viscous': False},
             'base_dry': 1.5, 'viscous': 1.0},
            {'status': 'anomalous', 'flags': {'dry': True, 'viscous': True},
             'base_dry': 1.4, 'viscous': 1.1},
            {'status': 'nominal', 'flags': {'dry': False, 'viscous': False},
             'base_dry': 1.0, 'viscous': 1.0},
            {'status': 'unknown', 'flags': {'dry': False, 'viscous': False},
             'base_dry': 2.0, 'viscous': 1.0}]
    v = verdicts('dry', rows)
    assert (v['right'], v['wrong'], v['missed'], v['unknown']) == (1, 1, 1, 1)
    assert verdicts('nominal', rows)['right'] == 1
