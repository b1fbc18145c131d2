"""Metrics of the vsadc bench (READING-NOTES definitions) and the baselines' plumbing."""

import numpy as np
import pytest

from bench.bench_vsadc import delay, scores
from rwa_monitor.core import baselines
from rwa_monitor.sim.aocs import named_fault, simulate_aocs


def test_scores_by_hand():
    # 4 healthy rows, 6 faulty (3 drift, 3 bias). One healthy row labelled drift (false
    # alarm), two faulty rows labelled healthy (missed), one drift row labelled bias.
    truth = np.array([0, 0, 0, 0, 1, 1, 1, 2, 2, 2])
    pred = np.array([0, 1, 0, 0, 0, 0, 2, 2, 2, 2])
    s = scores(pred, truth)
    assert s['far'] == pytest.approx(100 * 1 / 6)
    assert s['mar'] == pytest.approx(100 * 2 / 6)
    assert s['idr'] == pytest.approx(100 * 3 / 6)
    assert s['accuracy'] == pytest.approx(100 * 6 / 10)
    assert s['switches'] == 3             # 0->1, 1->0, 0->2


def test_delay_by_hand():
    t = np.arange(10) * 0.25
    assert delay(t, np.array([1, 0, 0, 0, 0, 0, 2, 0, 0, 0]), 1.0) == pytest.approx(0.5)
    assert np.isnan(delay(t, np.zeros(10, int), 1.0))


def test_smoothed_features_hold_over_missing_rows():
    res = np.array([[1.0, 2.0], [3.0, 4.0], [np.nan, np.nan], [5.0, 6.0], [7.0, 8.0]])
    out = baselines.smoothed_features(res, 2)
    assert np.isnan(out[0]).all()
    np.testing.assert_allclose(out[1:], [[2, 3], [2, 3], [4, 5], [6, 7]])


def test_every_baseline_fits_and_predicts():
    # Bias step of 2e-4 rad/s on x: per-sample gyro residuals are 20 noise sigmas apart,
    # so every non-linear method (and the linear SVM) separates healthy from bias rows.
    tele = simulate_aocs(600.0, fault=named_fault('bias', 'x', 300.0), seed=5)
    res = baselines.residuals(tele.time, tele.gyro, tele.attitude, tele.reference_rate, 0)
    ok = np.isfinite(res).all(axis=1)
    y = tele.truth['gyro_x'].astype(int)
    x, y = res[ok], y[ok]
    rng = np.random.default_rng(0)
    order = rng.permutation(len(y))
    train, test = order[:1500], order[1500:]
    for name in baselines.methods():
        pred = baselines.fit_predict(name, x[train], y[train], x[test], svm_max_train=500)
        assert np.mean(pred == y[test]) > 0.99, name
    with pytest.raises(ValueError, match='name'):
        baselines.fit_predict('forest', x[train], y[train], x[test])
