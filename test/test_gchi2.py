"""Tests of the generalised chi-square tail (llr-realtime paper, Lemma 1)."""

import math

import mpmath as mp
import numpy as np
import pytest
from scipy import special, stats

from rwa_monitor.core import gchi2
from rwa_monitor.core.gchi2 import (gchi2_isf, gchi2_logsf, gchi2_logsf_general, gchi2_sf,
                                    log_lower_bound, log_sf2, log_sf2_t, skip_threshold)

RATIOS = (1.0, 1.0 + 1e-9, 3.0, 100.0, 1e6, 1e12)
LEVELS = (0.5, 1e-6, 1e-12)


def reference_sf(x: float, w1: float, w2: float, m1: float = 0.0, m2: float = 0.0) -> float:
    """P(w1 (Z1 + m1)^2 + w2 (Z2 + m2)^2 > x) by conditioning on Z2 (40 digits).

    Independent of the code under test: P = E[P(w1 (Z1 + m1)^2 > x - w2 (Z2 + m2)^2)],
    the inner probability in closed form (normal tails), the outer expectation by
    mpmath's adaptive quadrature split at the points where the inner one becomes 1.
    Relative accuracy ~1e-12 for tails down to 1e-12 (it fails in the far tail beyond).
    """
    with mp.workdps(25):
        x, w1, w2, m1, m2 = (mp.mpf(v) for v in (x, w1, w2, m1, m2))

        def inner(z):
            rest = x - w2 * (z + m2) ** 2
            if rest <= 0:
                return mp.npdf(z)
            r = mp.sqrt(rest / w1)
            return mp.npdf(z) * (mp.ncdf(-r - m1) + mp.ncdf(-r + m1))

        zc = mp.sqrt(x / w2)
        lo, hi = -zc - m2, zc - m2
        body = mp.quad(inner, [lo, (lo + hi) / 2, hi])
        return float(body + mp.ncdf(lo) + mp.ncdf(-hi))


@pytest.mark.slow
def test_two_term_central_matches_high_precision_reference():
    # Brief: relative error <= 1e-6 for tails 0.5 .. 1e-12, weight ratios 1 .. 1e12.
    worst = 0.0
    for ratio in RATIOS:
        w1, w2 = 1.0, 1.0 / ratio
        for level in LEVELS:
            x = gchi2_isf(level, [w1, w2])
            ref = reference_sf(x, w1, w2)
            assert ref == pytest.approx(level, rel=1e-7)
            for got in (math.exp(log_sf2(x, w1, w2)), gchi2_sf(x, [w2, w1])):
                worst = max(worst, abs(got / ref - 1.0))
    assert worst <= 1e-8


@pytest.mark.parametrize('w2', [1.0, 0.25, 1e-4, 0.0])
def test_two_term_closed_forms_and_scaling(w2):
    x = np.array([0.0, 3.0, 30.0, 300.0])
    got = gchi2_logsf(x, [2.0, 2.0 * w2])
    if w2 == 1.0:
        expected = -x / 4.0
    elif w2 == 0.0:
        expected = stats.chi2.logsf(x / 2.0, 1)
    else:
        expected = np.array([log_sf2(v / 2.0, 1.0, w2) for v in x])
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)
    # Tails above 0.5 (not used for decisions): absolute error below 1e-4.
    small = np.array([1e-3, 0.05, 0.3])
    near_one = gchi2_sf(small, [2.0, 2.0 * w2])
    exact = np.exp(-small / 4.0) if w2 == 1.0 else np.array(
        [math.exp(gchi2_logsf_general(v, [2.0, 2.0 * w2] if w2 else [2.0])[0]) for v in small])
    np.testing.assert_allclose(near_one, exact, rtol=0.0, atol=1e-4)


def test_far_tail_agrees_between_the_two_methods():
    # Integral in the angle (log_sf2) vs. Laplace inversion through the saddle point.
    for x in (5.0, 200.0, 2e4, 2e6):
        for w2 in (0.999, 0.6, 0.1, 1e-3, 1e-12):
            general, err = gchi2_logsf_general(x, [1.0, w2])
            assert general == pytest.approx(log_sf2(x, 1.0, w2), rel=1e-10, abs=1e-10)
            assert err < 1e-6


def test_non_central_two_terms_matches_reference():
    for x, w, m in ((2.0, (1.0, 0.3), (0.5, -1.0)), (40.0, (1.0, 0.01), (2.0, 3.0)),
                    (15.0, (0.7, 0.7), (1.0, 0.0))):
        ref = reference_sf(x, w[0], w[1], m[0], m[1])
        assert gchi2_sf(x, w, m) == pytest.approx(ref, rel=1e-8)


@pytest.mark.parametrize('x', [1.0, 10.0, 50.0, 200.0])
def test_equal_weights_match_chi2_and_noncentral_chi2(x):
    assert gchi2_logsf(x, [1.0] * 5) == pytest.approx(stats.chi2.logsf(x, 5), rel=1e-9)
    means = [0.5, 1.0, 2.0]
    nc = sum(v * v for v in means)
    expected = stats.ncx2.logsf(x / 2.0, 3, nc)
    assert gchi2_logsf(x, [2.0] * 3, means) == pytest.approx(expected, rel=1e-8)


def test_three_terms_by_conditioning_on_the_third():
    w = (1.0, 0.4, 0.05)
    for x in (1.0, 12.0, 45.0):
        with mp.workdps(30):
            def inner(z):
                rest = float(x - w[2] * z * z)
                return mp.npdf(z) * mp.e ** log_sf2(rest, w[0], w[1]) if rest > 0 else mp.npdf(z)
            zc = mp.sqrt(x / w[2])
            ref = float(mp.quad(inner, [-zc, 0, zc]) + 2 * mp.ncdf(-zc))
        assert gchi2_sf(x, w) == pytest.approx(ref, rel=1e-8)


def test_monte_carlo_tail_of_random_weights():
    rng = np.random.default_rng(7)
    n = 200_000
    for p in (2, 4):
        w = rng.uniform(0.05, 1.0, p)
        q = (rng.standard_normal((n, p)) ** 2) @ w
        for level in (0.1, 0.01):
            x = gchi2_isf(level, w)
            count = np.count_nonzero(q > x)
            # Binomial(n, level): 5 standard deviations (two-sided failure prob < 1e-6).
            assert abs(count - n * level) <= 5.0 * math.sqrt(n * level * (1.0 - level))


@pytest.mark.parametrize('weights', [(1.0, 0.3), (1.0, 1e-9), (2.0, 1.0, 0.5)])
def test_isf_inverts_sf(weights):
    for level in (0.5, 1e-5, 1e-12):
        x = gchi2_isf(level, weights)
        assert gchi2_sf(x, weights) == pytest.approx(level, rel=1e-9)


def test_vectorised_equals_scalar_and_edge_values():
    x = np.array([-1.0, 0.0, 1e-9, 0.5, 7.0, 70.0, 7e4])
    got = gchi2_logsf(x, [0.8, 0.1])
    expected = [log_sf2(v, 0.8, 0.1) for v in x]
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)
    assert got[0] == 0.0 and got[1] == 0.0
    assert gchi2_sf(x.reshape(7, 1), [0.8, 0.1]).shape == (7, 1)
    assert isinstance(gchi2_sf(1.0, [0.8, 0.1]), float)


def test_bounds_used_by_the_detector_hold():
    for b in np.concatenate([[0.0], np.logspace(-6, 6, 61)]):
        exact = math.log(2.0) + float(special.log_ndtr(-math.sqrt(2.0 * b)))  # erfc(sqrt b)
        assert log_lower_bound(b) <= exact + 1e-13 * abs(exact)  # equal to rounding far out
    for log_p in (-0.3, -1.0, -12.0, -300.0, -1e5):
        y = skip_threshold(log_p)
        assert y >= 0.0
        assert log_lower_bound(y) > log_p
        assert log_lower_bound(y * (1.0 + 1e-6) + 1e-9) <= log_p
    assert skip_threshold(0.0) == 0.0
    # The two-term tail lies between the one-term tail of w1 and the chi2_2 tail of w1.
    for x in (0.1, 3.0, 60.0):
        for w2 in (0.9, 0.2, 1e-6):
            lp = log_sf2(x, 1.0, w2)
            assert log_lower_bound(x / 2.0) <= lp <= -x / 2.0 + 1e-15


@pytest.mark.parametrize('bad', [[], [1.0, -0.1], [0.0, 0.0], [1.0, math.nan]])
def test_invalid_weights_raise(bad):
    with pytest.raises(ValueError, match='weights'):
        gchi2_sf(1.0, bad)


@pytest.mark.parametrize('level', [0.0, 1.0, -0.1, 2.0])
def test_invalid_level_raises(level):
    with pytest.raises(ValueError, match='p must be'):
        gchi2_isf(level, [1.0, 0.5])


def test_quadrature_rule_is_the_documented_one():
    assert len(gchi2._NODES) == gchi2._GL_ORDER
    assert sum(gchi2._WEIGHTS) == pytest.approx(1.0, abs=1e-14)


def test_studentised_tail_matches_reference_and_closed_form():
    # E_S[P(Q > x S)], S ~ chi2_nu / nu, by mpmath quadrature over S of the (separately
    # validated) Gaussian tail; equal weights: (1 + x / nu)^(-nu / 2) for Q = Z1^2 + Z2^2.
    for nu in (9.0, 1e3):
        for w2 in (0.4, 1e-6):
            for x in (2.0, 60.0):
                def density(s):
                    return (mp.e ** log_sf2(float(x * s), 1.0, w2)
                            * nu * stats.chi2.pdf(float(s * nu), nu))
                with mp.workdps(20):
                    ref = float(mp.log(mp.quad(density, [0, 0.5, 1, 2, 5, mp.inf])))
                assert log_sf2_t(x, 1.0, w2, nu) == pytest.approx(ref, rel=1e-8, abs=1e-9)
                general = gchi2_logsf_general(x, [1.0, w2], None, nu)[0]
                assert general == pytest.approx(ref, rel=1e-8, abs=1e-9)
        for x in (3.0, 30.0):
            closed = -nu / 2.0 * math.log1p(x / nu)
            assert gchi2_logsf(x, [1.0, 1.0], dof=nu) == pytest.approx(closed, rel=1e-12)
    level = 1e-6
    x = gchi2_isf(level, [1.0, 0.3], dof=50)
    assert gchi2_sf(x, [1.0, 0.3], dof=50) == pytest.approx(level, rel=1e-9)
    assert x > gchi2_isf(level, [1.0, 0.3])
    with pytest.raises(ValueError, match='dof'):
        gchi2_sf(1.0, [1.0], dof=0.0)
