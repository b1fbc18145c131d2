"""Stages 1-4 of the FSS window diagnoser on crafted cases with known answers."""

import itertools

import numpy as np
import pytest
from scipy import stats

from rwa_monitor.core.fss.assign import (assign_bruteforce, assign_changepoints,
                                         base_dry_weights, friction_levels,
                                         score_assignment)
from rwa_monitor.core.fss.classify import histogram, WindowClassifier
from rwa_monitor.core.fss.model import EXAMPLE_1, EXAMPLE_2, LOG_FLOOR, SwitchingSystem
from rwa_monitor.core.fss.segments import combination_se, fit_extra_columns, fit_intervals
from rwa_monitor.core.fss.wglr import detect_changepoints, run_maxima, wglr
from rwa_monitor.telemetry.fss_model import load_model, save_model


def _signal(n, steps, sigma, seed, speed=None):
    rng = np.random.default_rng(seed)
    x = 0.8 + 0.3 * np.sin(np.arange(n) / 700.0) if speed is None else speed
    dry = np.full(n, 1.0)
    for k, delta in steps:
        dry[k:] += delta
    return x, dry * np.sign(x) + 1.0 * x + rng.normal(0.0, sigma, n)


# ---- stage 1 ---------------------------------------------------------------------------

def test_changepoints_at_known_steps():
    x, y = _signal(6000, [(1000, 0.3), (2500, -0.2), (4000, 0.15)], 0.02, seed=1)
    res = detect_changepoints(y, x, window=20)
    # Steps of 7.5-15 sigma: the arg max is within a sample or two of the step.
    assert res.changepoints.size == 3
    assert np.all(np.abs(res.changepoints - [1000, 2500, 4000]) <= 2)


def test_noise_free_changepoints_are_exact():
    x, y = _signal(3000, [(700, 0.3), (1900, -0.3)], 0.0, seed=0)
    res = detect_changepoints(y, x, window=20, sigma=0.01)
    assert res.changepoints.tolist() == [700, 1900]
    assert res.threshold == pytest.approx(1e-4 * stats.chi2.isf(1e-9, 1))


def test_no_changepoint_in_pure_noise():
    x, y = _signal(20000, [], 0.02, seed=2)
    assert detect_changepoints(y, x, window=20).changepoints.size == 0


def test_wglr_is_chi2_under_no_jump():
    # W_b = 0: wGLR / sigma^2 is exactly chi2(1) at every k (Wilks, a linear model). Values
    # within 2w of each other are correlated: about n / (2w) = 500 independent ones, so
    # the mean has sd sqrt(2 / 500) = 0.063 and the exceedance fraction of the 1 % point
    # sd sqrt(0.01 * 0.99 / 500) = 0.0045. Bounds at 5 sd.
    x, y = _signal(20000, [], 0.02, seed=3)
    g = wglr(y, x, window=20, w_bias=0.0, viscous_prior=1.0)[20:-20] / 0.02 ** 2
    assert abs(g.mean() - 1.0) < 0.32
    assert abs(np.mean(g > stats.chi2.isf(0.01, 1)) - 0.01) < 0.023
    # With the prior (correct f~v) the statistic is stochastically smaller: the same
    # exceedance bound holds one-sided.
    g = wglr(y, x, window=20, w_bias=1e-3, viscous_prior=1.0)[20:-20] / 0.02 ** 2
    assert np.mean(g > stats.chi2.isf(0.01, 1)) < 0.01 + 0.023


def test_run_maxima_and_side_lobe_suppression():
    glr = np.array([0, 5, 7, 3, 0, 0, 9, 0, 2, 0], dtype=float)
    assert run_maxima(glr, 1.0).tolist() == [2, 6, 8]
    assert run_maxima(glr, 1.0, separation=3).tolist() == [2, 6]
    assert run_maxima(np.zeros(5), 1.0).size == 0


def test_nan_run_and_constant_speed():
    x, y = _signal(6000, [(1000, 0.3), (4000, -0.3)], 0.02, seed=4)
    y[2000:2300] = np.nan
    res = detect_changepoints(y, x, window=20)
    assert np.all(np.abs(res.changepoints - [1000, 4000]) <= 2)
    xc, yc = _signal(6000, [(3000, 0.3)], 0.02, seed=5, speed=np.full(6000, 0.7))
    res = detect_changepoints(yc, xc, window=20, w_bias=0.0)
    assert np.all(np.isfinite(res.glr))
    assert np.all(np.abs(res.changepoints - [3000]) <= 2)


def test_bad_parameters_name_themselves():
    with pytest.raises(ValueError, match='window'):
        wglr(np.zeros(10), np.ones(10), window=1, w_bias=0.0, viscous_prior=1.0)
    with pytest.raises(ValueError, match='p_false'):
        detect_changepoints(np.zeros(10), np.ones(10), p_false=0.0)


# ---- stage 2 ---------------------------------------------------------------------------

def test_least_squares_recovers_noise_free_coefficients():
    n = 3000
    x = 0.5 + 0.4 * np.sin(np.arange(n) / 300.0)
    levels = np.repeat([1.0, 1.4, 0.9], [1000, 1000, 1000])
    y = levels + 0.7 * x
    fit = fit_intervals(y, x, [1000, 2000], dk_error=10)
    assert fit.dry == pytest.approx([1.0, 1.4, 0.9], abs=1e-9)
    assert fit.viscous == pytest.approx(0.7, abs=1e-9)
    # H^T H diagonal: samples per interval after the margins (eq. 12-13, 16).
    assert fit.hth.tolist() == [990, 980, 990]
    # Eq. (17) by hand.
    expected = [990 * 980 / 1970 * 0.4 ** 2, 980 * 990 / 1970 * 0.5 ** 2]
    assert fit.rejection_cost == pytest.approx(expected)


def test_rejection_cost_is_the_squared_error_increase():
    # Eq. (17) is exactly the increase of the residual sum of squares when two intervals
    # share one dry coefficient, with the viscous coefficient held fixed (x = 0 here).
    rng = np.random.default_rng(6)
    y = np.concatenate([rng.normal(1.0, 0.05, 400), rng.normal(1.1, 0.05, 300)])
    x = np.full(700, 1e-9)
    a, b = y[:400], y[400:]
    split = np.sum((a - a.mean()) ** 2) + np.sum((b - b.mean()) ** 2)
    merged = np.sum((y - y.mean()) ** 2)
    fit = fit_intervals(y, x, [400], dk_error=0)
    assert fit.rejection_cost[0] == pytest.approx(merged - split, rel=1e-6)


def test_noise_variance_is_estimated():
    # Residual variance with n = 20000: sd of the estimate sigma^2 sqrt(2 / n) = 1 %.
    x, y = _signal(20000, [(5000, 0.3), (12000, -0.2)], 0.03, seed=7)
    fit = fit_intervals(y, x, [5000, 12000])
    assert fit.sigma2 == pytest.approx(0.03 ** 2, rel=0.05)


def test_empty_interval_merges_and_constant_speed_fixes_viscous():
    x, y = _signal(3000, [(1000, 0.3)], 0.01, seed=8)
    y[1400:1600] = np.nan
    fit = fit_intervals(y, x, [1000, 1400, 1600], dk_error=0)
    assert fit.changepoints.tolist() == [1000, 1400]  # [1400, 1600) joined [1600, 3000)
    xc = np.full(2000, 0.5)
    fit = fit_intervals(xc * 1.2 + 1.0, xc, [1000], viscous_prior=0.9)
    assert not fit.identifiable and fit.viscous == 0.9


# ---- stage 3 ---------------------------------------------------------------------------

SMALL = (SwitchingSystem('a', residence=((1, 60), (1, 30)), levels=((0, 0.1), (0.3, 0.4))),
         SwitchingSystem('b', residence=((40, 200),) * 3, levels=((0, 1), (1, 2), (2, 3))))


@pytest.mark.parametrize('seed', range(6))
def test_dp_optimum_equals_enumeration(seed):
    rng = np.random.default_rng(seed)
    m = 6
    times = np.sort(rng.choice(np.arange(1, 300), m, replace=False))
    signs = rng.choice([-1, 1], m)
    cost = rng.exponential(3.0, m)
    best, best_u = assign_bruteforce(times, signs, cost, 300, SMALL)
    res = assign_changepoints(times, signs, cost, 300, SMALL, beam=100_000)
    assert res.exact
    assert res.score == pytest.approx(best, abs=1e-9)
    # The dominance pruning is exact: the same optimum without it.
    plain = assign_changepoints(times, signs, cost, 300, SMALL, beam=100_000, dominance=False)
    assert plain.score == pytest.approx(best, abs=1e-9)
    q0 = res.configs[0]
    assert score_assignment(times, signs, cost, 300, SMALL, q0, res.inputs) == \
        pytest.approx(best, abs=1e-9)


def test_a_rejection_must_happen():
    # One two-configuration system cannot go up twice: the second rise is rejected.
    system = SMALL[:1]
    res = assign_changepoints([10, 20, 40], [1, 1, -1], [100.0, 0.5, 100.0], 60, system)
    assert res.inputs.tolist() == [1, 0, 1]
    assert res.configs[:, 0].tolist() == [0, 1, 1, 0]


def test_jumps_go_to_the_system_whose_timing_fits():
    # Fast toggles of 'a' every 20 steps and one slow rise of 'b' at step 150, which would
    # break a's alternation.
    times = [20, 40, 60, 80, 150, 170, 190]
    signs = [1, -1, 1, -1, 1, 1, -1]
    res = assign_changepoints(times, signs, np.full(7, 50.0), 250, SMALL)
    assert res.inputs.tolist()[:4] == [1, 1, 1, 1]
    assert res.inputs[4] == 2 or res.inputs[5] == 2


def test_beam_bounds_the_search():
    rng = np.random.default_rng(9)
    m = 400
    times = np.sort(rng.choice(np.arange(1, 80_000), m, replace=False))
    signs = np.tile([1, -1], m // 2)
    cost = np.full(m, 30.0)
    narrow = assign_changepoints(times, signs, cost, 80_000, (EXAMPLE_1, EXAMPLE_2), beam=4)
    wide = assign_changepoints(times, signs, cost, 80_000, (EXAMPLE_1, EXAMPLE_2), beam=64)
    assert not narrow.exact
    assert narrow.iterations <= 4 + m * 4 + (2 * 3)
    assert narrow.score <= wide.score + 1e-9
    assert narrow.inputs.size == m and np.isfinite(narrow.score)


def test_no_changepoint_assignment():
    res = assign_changepoints([], [], [], 80_000, (EXAMPLE_1, EXAMPLE_2))
    assert res.inputs.size == 0 and res.configs.shape == (1, 2)
    # EXAMPLE_2 cannot stay 80,000 steps in one configuration: a floored score.
    assert res.score <= LOG_FLOOR


def test_algorithm_1_levels():
    base, levels, qs = friction_levels(np.array([1.0, 1.3, 1.0, 1.5, 1.2]),
                                       np.array([1, 1, 2, 1]),
                                       np.array([[0, 0], [1, 0], [0, 0], [0, 1], [1, 1]]), 2)
    assert levels[0] == pytest.approx([0.3, 0.6, 0.3, 0.0])
    assert levels[1] == pytest.approx([0.0, 0.5])
    assert base == pytest.approx(0.7)
    assert qs == [[0, 1, 0, 1], [0, 1]]


def test_model_probabilities_are_normalised():
    for system in (EXAMPLE_1, EXAMPLE_2):
        for q in range(system.n_config):
            d = np.arange(1, system.residence[q][1] + 1)
            pmf = np.exp(system.log_pmf(np.full(d.size, q), d))
            assert pmf[pmf > np.exp(LOG_FLOOR)].sum() == pytest.approx(1.0)
        for q, dq in itertools.product(range(system.n_config), (-1, 1)):
            p = np.exp(system.log_pq(np.array(q), np.array(dq)))
            assert p <= 1.0


# ---- stage 4 ---------------------------------------------------------------------------

def test_histogram_is_normalised_and_clips():
    z = histogram([0.0, 0.05, 0.5, 0.99, 5.0, np.nan], 4, 0.0, 1.0)
    assert z.tolist() == [0.4, 0.0, 0.2, 0.4]
    assert histogram([], 4, 0.0, 1.0).tolist() == [0.0] * 4


def _features(rng, status):
    # Every class is separable by construction: disjoint ranges of the scalars, and FSS
    # levels in (0.5, 0.8] or (1.2, 2] only under the anomaly.
    high1, high2 = (0.5, 0.8) if status == 'fss1' else (0.0, 0.4), \
        (1.2, 2.0) if status == 'fss2' else (0.0, 1.0)
    return {'base_dry': rng.normal(2.5 if status == 'dry' else 1.0, 0.1),
            'viscous': rng.normal(1.5 if status == 'viscous' else 1.0, 0.05),
            'levels': [[0.0] + list(rng.uniform(*high1, 30)),
                       [0.0] + list(rng.uniform(*high2, 4))]}


def test_svms_learn_separable_anomalies(tmp_path):
    rng = np.random.default_rng(10)
    statuses = ['nominal', 'dry', 'viscous', 'fss1', 'fss2'] * 20
    feats = [_features(rng, s) for s in statuses]
    model = WindowClassifier.fit(feats, statuses, bins=10)
    test = [_features(rng, s) for s in statuses]
    for f, s in zip(test, statuses):
        flags = model.predict(f)
        assert flags == {k: k == s for k in flags}
    path = tmp_path / 'm.json'
    save_model(model, path)
    again = load_model(path)
    assert again.decision(test[0]) == pytest.approx(model.decision(test[0]))
    with pytest.raises(ValueError, match='fss2'):
        WindowClassifier.fit(feats[:4], statuses[:4])


def test_an_fss_without_jumps_is_not_judged():
    rng = np.random.default_rng(11)
    statuses = ['nominal', 'dry', 'viscous', 'fss1', 'fss2'] * 10
    model = WindowClassifier.fit([_features(rng, s) for s in statuses], statuses, bins=10)
    quiet = {'base_dry': 1.0, 'viscous': 1.0, 'levels': [[0.0], [0.0]]}
    assert model.predict(quiet) == {'dry': False, 'viscous': False, 'fss1': False,
                                    'fss2': False}


def test_extra_columns_fitted_beside_the_interval_jumps():
    # Speed crossing zero; dry jumps at known changepoints; an extra effect of speed
    # (exp(-|x| / 0.3) sign(x), a Stribeck-like bump) that model (1) cannot hold.
    n = 12000
    x = 1.2 * np.sin(np.arange(n) / 900.0) + 0.1
    bump = np.exp(-np.abs(x) / 0.3) * np.sign(x)
    cps = np.array([3000, 7000])
    x_free, y_jumps = _signal(n, [(3000, 0.4), (7000, -0.25)], 0.02, seed=3, speed=x)
    y = y_jumps + 0.5 * bump
    columns = np.column_stack([bump, x ** 2])   # a column with no effect in the data
    c, d = fit_extra_columns(y, x, cps, columns)
    fitted = columns @ c + d[0] * np.sign(x) + d[1] * x
    truth = 0.5 * bump
    s = np.column_stack([np.sign(x), x])
    truth -= s @ np.linalg.lstsq(s, truth, rcond=None)[0]   # its non-model-(1) part
    assert np.max(np.abs(fitted - truth)) < 0.02
    assert c[0] == pytest.approx(0.5, abs=0.02) and abs(c[1]) < 0.01
    # Without the changepoints the jumps leak into the columns.
    c0, d0 = fit_extra_columns(y, x, np.array([], dtype=int), columns)
    assert np.max(np.abs(columns @ c0 + d0[0] * np.sign(x) + d0[1] * x - truth)) > 0.05
    # No columns, or too few samples: nothing fitted.
    assert fit_extra_columns(y, x, cps, np.zeros((n, 0)))[0].size == 0
    assert not np.any(fit_extra_columns(y[:10], x[:10], cps[:0], columns[:10])[0])


def test_viscous_standard_error_is_the_scatter_of_the_estimate():
    # 400 noise draws on one speed profile with two dry jumps: the std of the viscous
    # estimates is the reported standard error, within 4 sigma of a std from 400 draws
    # (sqrt(1 / (2 * 399)) = 3.5 %).
    n, sigma = 3000, 0.05
    x = 0.8 + 0.3 * np.sin(np.arange(n) / 300.0)
    clean = np.where(np.arange(n) < 1000, 1.0, 1.3) * np.sign(x) + 1.0 * x
    rng = np.random.default_rng(5)
    fits = [fit_intervals(clean + rng.normal(0.0, sigma, n), x, np.array([1000, 2000]))
            for _ in range(400)]
    scatter = np.std([f.viscous for f in fits], ddof=1)
    reported = np.mean([f.viscous_se for f in fits])
    assert scatter == pytest.approx(reported, rel=0.14)
    assert fit_intervals(clean, np.full(n, 0.5), np.array([1000])).viscous_se == np.inf


def test_base_dry_standard_error_is_the_scatter_of_algorithm_1():
    # Levels 1, 1.3 (FSS 1 up), 1.05 (FSS 1 down), 1.55 (FSS 2 up) on a speed crossing zero
    # (each minimum clear of the noise, so that the same intervals hold it in every draw):
    # Algorithm 1's base is a fixed combination of the interval coefficients; over 400
    # noise draws its std is the reported standard error (4 sigma of a std from 400
    # draws: 14 %), and the combination reproduces friction_levels' base exactly.
    n, sigma = 4000, 0.05
    x = 0.2 + 0.6 * np.sin(np.arange(n) / 400.0)
    cps, inputs = np.array([1000, 1500, 2500]), np.array([1, 1, 2])
    level = np.select([np.arange(n) < k for k in cps], [1.0, 1.3, 1.05], 1.55)
    clean = level * np.sign(x) + 1.0 * x
    configs = np.array([[0, 0], [1, 0], [0, 0], [0, 1]])
    rng = np.random.default_rng(6)
    bases, ses = [], []
    for _ in range(400):
        y = clean + rng.normal(0.0, sigma, n)
        fit = fit_intervals(y, x, cps)
        weights = base_dry_weights(fit.dry, inputs, 2)
        base = friction_levels(fit.dry, inputs, configs, 2)[0]
        assert weights @ fit.dry == pytest.approx(base, abs=1e-12)
        bases.append(base)
        ses.append(combination_se(fit, y, x, weights))
    assert np.mean(bases) == pytest.approx(1.0, abs=4 * np.mean(ses) / np.sqrt(400))
    assert np.std(bases, ddof=1) == pytest.approx(np.mean(ses), rel=0.14)
    with pytest.raises(ValueError, match='one per interval'):
        combination_se(fit, y, x, weights[:2])
