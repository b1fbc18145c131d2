"""Per-pass friction levels and the wheel trend test (core/trend.py, docs/fleet.md).

Statistical checks run over fixed seeds; each count is held to the two-sided binomial
interval that a correct method leaves with probability 1 - 1e-6.
"""

import math

import numpy as np
import pytest
import scipy.stats

from rwa_monitor.core.trend import (MIN_SPEED_RAD_S, pass_levels, SECONDS_PER_DAY,
                                    wheel_trend)

DRY, VISC, NOISE = 2.0e-4, 5.0e-7, 5.0e-5


def binomial_bounds(trials: int, p: float) -> tuple[float, float]:
    return scipy.stats.binom.interval(1.0 - 1e-6, trials, p)


def one_pass(rng, n=3000, rate=5.0, ar=0.0, dry=DRY, visc=VISC):
    t = 1000.0 + np.arange(n) / rate
    w = 30.0 + 100.0 * np.sin(2 * np.pi * (t - 1000.0) / 600.0 + rng.uniform(0, 6.28))
    u = rng.normal(0.0, NOISE * math.sqrt(1 - ar ** 2), n)
    e = np.empty(n)
    e[0] = rng.normal(0.0, NOISE)
    for k in range(1, n):
        e[k] = ar * e[k - 1] + u[k]
    return t, w, -dry * np.sign(w) - visc * w + e


def test_levels_recover_the_model_with_the_friction_sign():
    t, w, f = one_pass(np.random.default_rng(1))
    lv = pass_levels(t, w, f)
    assert lv.samples + lv.slow == t.size and lv.nonfinite == 0 and lv.reason == ''
    assert abs(lv.dry - DRY) < 5 * lv.dry_se and abs(lv.viscous - VISC) < 5 * lv.viscous_se
    assert lv.dry_se < 0.02 * DRY
    assert (lv.t_start, lv.t_end) == (t[np.abs(w) >= 1][0], t[np.abs(w) >= 1][-1])


@pytest.mark.parametrize('ar', [0.0, 0.8])
def test_standard_errors_cover_at_their_level_white_and_ar_noise(ar):
    trials, z = 300, scipy.stats.norm.ppf(0.975)
    misses = {'dry': 0, 'viscous': 0}
    for seed in range(trials):
        lv = pass_levels(*one_pass(np.random.default_rng(1000 + seed), ar=ar))
        misses['dry'] += abs(lv.dry - DRY) > z * lv.dry_se
        misses['viscous'] += abs(lv.viscous - VISC) > z * lv.viscous_se
    low, high = binomial_bounds(trials, 0.05)
    assert low <= misses['dry'] <= high and low <= misses['viscous'] <= high, misses


def test_ar_noise_widens_the_errors_by_the_long_run_factor():
    t, w, f = one_pass(np.random.default_rng(5), ar=0.8)
    lv = pass_levels(t, w, f)
    white = pass_levels(t, w, f, max_ar_order=0)
    # Long-run variance of AR(1) over its variance: (1 + a) / (1 - a) = 9, so x3 in std.
    assert lv.ar_order >= 1 and 2.4 < lv.dry_se / white.dry_se < 3.6


def test_levels_against_nominal_are_the_change():
    rng = np.random.default_rng(2)
    t, w, f = one_pass(rng, dry=DRY + 3e-5, visc=VISC - 1e-7)
    nominal = -DRY * np.sign(w) - VISC * w
    lv = pass_levels(t, w, f, nominal)
    assert abs(lv.dry - 3e-5) < 5 * lv.dry_se and abs(lv.viscous + 1e-7) < 5 * lv.viscous_se


def test_slow_and_nonfinite_samples_are_dropped_and_counted():
    t, w, f = one_pass(np.random.default_rng(3))
    slow = int(np.count_nonzero(np.abs(w) < MIN_SPEED_RAD_S))
    f[:7] = np.nan
    w[10] = np.inf
    lv = pass_levels(t, w, f)
    assert slow > 0 and lv.nonfinite == 8
    assert lv.slow == slow - int(np.count_nonzero(np.abs(w[:11]) < MIN_SPEED_RAD_S))
    assert lv.samples == t.size - lv.nonfinite - lv.slow and math.isfinite(lv.dry)


def test_unusable_passes_give_nan_levels_with_a_reason():
    t = np.arange(100.0)
    lv = pass_levels(t, np.full(100, 50.0), np.full(100, -1e-4))
    assert lv.reason == 'not_excited' and math.isnan(lv.dry) and math.isnan(lv.viscous_se)
    lv = pass_levels(t, np.zeros(100), np.zeros(100))
    assert lv.reason == 'too_few_samples' and lv.samples == 0 and lv.slow == 100
    with pytest.raises(ValueError, match='one length'):
        pass_levels(t, t, t[:5])


def test_equal_weights_give_the_ordinary_regression_test():
    rng = np.random.default_rng(4)
    t = np.sort(rng.uniform(0, 90 * SECONDS_PER_DAY, 40))
    y = 2e-4 + 1e-8 * t / SECONDS_PER_DAY + rng.normal(0, 3e-6, t.size)
    tr = wheel_trend(t, y, np.full(t.size, 3e-6))
    ref = scipy.stats.linregress(t / SECONDS_PER_DAY, y)
    assert tr.slope == pytest.approx(ref.slope, rel=1e-9)
    assert tr.slope_se == pytest.approx(ref.stderr, rel=1e-9)
    assert tr.p_value == pytest.approx(ref.pvalue, rel=1e-7)
    assert tr.intercept == pytest.approx(ref.intercept, rel=1e-9)
    assert tr.passes == 40 and tr.dof == 38 and tr.crossing is None


def test_p_value_is_uniform_under_a_zero_slope():
    trials = 2000
    p = np.empty(trials)
    for seed in range(trials):
        rng = np.random.default_rng(20_000 + seed)
        t = np.sort(rng.uniform(0, 120 * SECONDS_PER_DAY, 30))
        se = rng.uniform(1e-6, 6e-6, t.size)         # passes of unequal quality
        scale = rng.uniform(0.5, 2.0)                 # errors known up to a factor
        p[seed] = wheel_trend(t, 2e-4 + rng.normal(0, scale * se), se).p_value
    for level in (0.01, 0.05, 0.5):
        low, high = binomial_bounds(trials, level)
        assert low <= np.count_nonzero(p < level) <= high, level


def test_a_real_wear_slope_is_found():
    rng = np.random.default_rng(6)
    t = np.arange(60) * SECONDS_PER_DAY
    se = np.full(t.size, 2e-6)
    tr = wheel_trend(t, 2e-4 + 1e-7 * np.arange(60) + rng.normal(0, 2e-6, 60), se)
    assert tr.p_value < 1e-6 and abs(tr.slope - 1e-7) < 5 * tr.slope_se
    assert 0.5 < tr.scale < 1.5


def wear_case(seed, n=40, days=120.0):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, days * SECONDS_PER_DAY, n))
    se = rng.uniform(2e-6, 5e-6, n)
    rate = 1e-6                                      # N m per day
    y = 2e-4 + rate * t / SECONDS_PER_DAY + rng.normal(0, se)
    truth = (4e-4 - 2e-4) / rate * SECONDS_PER_DAY   # day 200
    return wheel_trend(t, y, se, limit=4e-4), truth


def test_projection_of_a_known_linear_wear():
    tr, truth = wear_case(7)
    c = tr.crossing
    assert c.limit == 4e-4 and c.low < truth < c.high and c.low < c.time < c.high
    assert abs(c.time - truth) < 20 * SECONDS_PER_DAY and math.isfinite(c.high)


def test_crossing_interval_covers_the_true_crossing_at_its_level():
    trials = 400
    misses = 0
    for seed in range(trials):
        tr, truth = wear_case(30_000 + seed)
        misses += not tr.crossing.low <= truth <= tr.crossing.high
    low, high = binomial_bounds(trials, 0.05)
    assert low <= misses <= high


def test_an_unknown_slope_gives_an_unbounded_crossing():
    days = np.arange(10.0)
    y = 2e-4 + 5e-6 * np.array([1, -1, -1, 1, 1, -1, 1, -1, -1, 1.0])  # slope ~ 0
    tr = wheel_trend(days * SECONDS_PER_DAY, y, np.full(10, 5e-6), limit=4e-4)
    c = tr.crossing
    assert tr.p_value > 0.5 and (math.isinf(c.low) or math.isinf(c.high))
    assert c.low < c.time < c.high


def test_too_few_passes_and_bad_rows():
    tr = wheel_trend([0.0, 1.0, np.nan, 2.0], [1.0, 2.0, 3.0, np.nan], [1.0, 1.0, 1.0, 1.0])
    assert tr.passes == 2 and math.isnan(tr.p_value) and tr.crossing is None
    tr = wheel_trend([0, 1, 2, 3.0], [1, 2, 3, 4.0], [1, 0, 1, 1.0], limit=10.0)
    assert tr.passes == 3


def test_compiled_sums_equal_the_matrix_products():
    from rwa_monitor.core.friction import coulomb_viscous
    from rwa_monitor.core.llr_noise import lag_gram
    from rwa_monitor.core.trend_sums import level_sums, residual_lag_gram
    rng = np.random.default_rng(77)
    for top in (0, 1, 3, 5):
        n = 700
        t = 0.1 * np.arange(n)
        w = rng.uniform(-80.0, 80.0, n)
        y = rng.normal(0.0, 1e-4, n)
        y[5], w[9], t[11] = np.nan, np.inf, np.nan
        finite = np.isfinite(t) & np.isfinite(w) & np.isfinite(y)
        kept = finite & (np.abs(w) >= 2.0)
        sums = level_sums(t, w, y, 2.0)
        h = coulomb_viscous().matrix(w[kept])
        assert sums[:3] == (kept.sum(), 3, np.count_nonzero(finite & (np.abs(w) < 2.0)))
        assert sums[3:5] == (t[kept].min(), t[kept].max())
        gram, right = h.T @ h, h.T @ y[kept]
        assert np.allclose(sums[5:8], [gram[0, 0], gram[0, 1], gram[1, 1]], rtol=1e-12)
        assert np.allclose(sums[8:], right, rtol=1e-10)
        x = np.array([2e-4, 3e-7])
        e = y[kept] - h @ x
        lags = residual_lag_gram(t, w, y, 2.0, x[0], x[1], int(kept.sum()), top)
        assert np.allclose(lags[:top + 1], lag_gram(e, top), rtol=1e-12)
        assert lags[top + 1, 0] == pytest.approx(e @ e, rel=1e-12)


def test_autocorrelation_sums_add_in_order_whatever_the_lags():
    """The scalar walk (up to UNROLLED_LAGS) and the array walk give the in-order floats."""
    from rwa_monitor.core.trend_sums import _autocorrelation, UNROLLED_LAGS
    rng = np.random.default_rng(78)
    for n in (0, 1, 2, 3, 4, 7, 500):
        e = rng.normal(0.0, 1e-4, n) * rng.uniform(0.5, 2e3, n)
        for top in range(UNROLLED_LAGS + 3):
            expected = [0.0] * (top + 1)
            for lag in range(top + 1):
                for u in range(lag, n):
                    expected[lag] += float(e[u]) * float(e[u - lag])
            assert _autocorrelation(e, top).tolist() == expected, (n, top)


@pytest.mark.parametrize('ar', [0.0, 0.7])
def test_compiled_fit_gives_the_noise_models_standard_errors(ar):
    """pass_levels' errors are noise_model_from_gram's arithmetic on the pass's lag sums."""
    from rwa_monitor.core.llr_noise import lag_top, noise_model_from_gram
    from rwa_monitor.core.trend_sums import level_sums, residual_lag_gram
    rng = np.random.default_rng(79)
    t = 0.1 * np.arange(6000)
    w = 60.0 * np.sin(2 * np.pi * t / 400.0) + 5.0
    noise = np.empty(t.size)
    prev = 0.0
    for i, u in enumerate(rng.normal(0.0, 2e-5, t.size)):
        prev = ar * prev + u
        noise[i] = prev
    f = -2e-4 * np.sign(w) - 3e-7 * w + noise
    levels = pass_levels(t, w, f)
    sums = level_sums(t, w, f, MIN_SPEED_RAD_S)
    n = int(sums[0])
    top = lag_top(n, 3)
    lags = residual_lag_gram(t, w, f, MIN_SPEED_RAD_S, levels.dry, levels.viscous, n, top)
    model = noise_model_from_gram(lags[:top + 1], n, float(lags[top + 1, 0]), 2)
    inverse = np.linalg.inv(np.array([[sums[5], sums[6]], [sums[6], sums[7]]]))
    variance = model.residual_std ** 2 * model.long_run_ratio
    assert levels.ar_order == len(model.ar) and (levels.ar_order > 0) == (ar > 0)
    assert levels.dry_se == math.sqrt(variance * inverse[0, 0])
    assert levels.viscous_se == math.sqrt(variance * inverse[1, 1])


def stepped_case(seed, rate=0.0, n=30, days=120.0, jump=3e-5, limit=None):
    """Return the trend of a wheel with a step of ``jump`` at day 50, a slope of ``rate``."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, days * SECONDS_PER_DAY, n))
    se = rng.uniform(1e-6, 6e-6, n)
    scale = rng.uniform(0.5, 2.0)
    step = 50 * SECONDS_PER_DAY
    y = 2e-4 + rate * t / SECONDS_PER_DAY + jump * (t >= step) + rng.normal(0, scale * se)
    return wheel_trend(t, y, se, limit=limit, steps=[step]), step


def test_a_step_is_a_jump_not_a_slope_the_same_regression_with_a_step_column():
    rng = np.random.default_rng(8)
    t = np.sort(rng.uniform(0, 90 * SECONDS_PER_DAY, 40))
    step = 40 * SECONDS_PER_DAY
    y = 2e-4 + 1e-8 * t / SECONDS_PER_DAY + 5e-5 * (t >= step) + rng.normal(0, 3e-6, 40)
    se = np.full(t.size, 3e-6)
    plain, tr = wheel_trend(t, y, se), wheel_trend(t, y, se, steps=[step])
    assert plain.p_value < 1e-10                        # the step read as a slope
    design = np.column_stack([np.ones(40), t / SECONDS_PER_DAY, t >= step])
    beta, rss = np.linalg.lstsq(design, y, rcond=None)[:2]
    cov = rss[0] / 37 * np.linalg.inv(design.T @ design)
    assert tr.slope == pytest.approx(beta[1], rel=1e-9)
    assert tr.slope_se == pytest.approx(math.sqrt(cov[1, 1]), rel=1e-9)
    assert tr.p_value == pytest.approx(2 * scipy.stats.t.sf(abs(beta[1]) / tr.slope_se, 37),
                                       rel=1e-7)
    assert tr.step_times == (step,) and tr.step_sizes[0] == pytest.approx(beta[2], rel=1e-9)
    assert tr.intercept == pytest.approx(beta[0] + beta[2], rel=1e-9)   # after the step
    assert tr.dof == 37 and tr.passes == 40
    # Steps outside the passes, or with no pass between them, add no column.
    same = wheel_trend(t, y, se, steps=[-1.0, step - 1.0, step, 1e12])
    assert same.step_times == (step,) and same.slope == pytest.approx(tr.slope, rel=1e-12)


def test_p_value_is_uniform_under_a_zero_slope_with_a_step():
    trials = 2000
    p = np.array([stepped_case(40_000 + seed)[0].p_value for seed in range(trials)])
    for level in (0.01, 0.05, 0.5):
        low, high = binomial_bounds(trials, level)
        assert low <= np.count_nonzero(p < level) <= high, level


def test_crossing_after_a_step_covers_the_true_crossing_at_its_level():
    trials = 400
    misses = 0
    for seed in range(trials):
        tr, step = stepped_case(50_000 + seed, rate=1e-6, limit=4e-4)
        truth = (4e-4 - 2e-4 - 3e-5) / 1e-6 * SECONDS_PER_DAY       # day 170
        misses += not tr.crossing.low <= truth <= tr.crossing.high
    low, high = binomial_bounds(trials, 0.05)
    assert low <= misses <= high


def test_too_few_passes_around_the_steps_give_nan():
    t = np.array([0.0, 1.0, 2.0, 3.0]) * SECONDS_PER_DAY
    tr = wheel_trend(t, [1.0, 1.1, 2.0, 2.1], np.ones(4), steps=[1.5 * SECONDS_PER_DAY])
    assert tr.dof == 1 and math.isfinite(tr.p_value)
    tr = wheel_trend(t, [1.0, 1.1, 2.0, 2.1], np.ones(4),
                     steps=[0.5 * SECONDS_PER_DAY, 1.5 * SECONDS_PER_DAY,
                            2.5 * SECONDS_PER_DAY])
    assert math.isnan(tr.p_value) and math.isnan(tr.intercept) and tr.crossing is None
