"""The compiled solves of small symmetric systems (core/scaled_solve.py) against numpy's pinv.

On well-conditioned systems the two agree to rounding: the bound on the explained sum
``theta . r`` is ``100 n kappa eps``, with ``kappa`` the condition number of the matrix
scaled to unit diagonal (both solves are backward stable, so each is within ``n kappa eps``
of the exact value, up to a modest constant). Rank-deficient systems get the
minimum-norm solution of the scaled problem, as numpy's ``pinv`` gives; bad input gives a
defined NaN.
"""

import numpy as np
import pytest

from rwa_monitor.core.llr_stats import solve_scaled
from rwa_monitor.core.scaled_solve import RCOND, solve_scaled_stack

EPS = np.finfo(float).eps


def _numpy_solve(m, r):
    diag = np.diagonal(m, axis1=-2, axis2=-1)
    d = np.sqrt(np.where(diag > 0.0, diag, 1.0))
    scaled = m / (d[..., :, None] * d[..., None, :])
    with np.errstate(all='ignore'):
        inverse = np.linalg.pinv(scaled, rcond=RCOND, hermitian=True)
    return np.einsum('...ij,...j->...i', inverse, r / d) / d, scaled


@pytest.mark.parametrize('n', [1, 2, 3, 4, 6, 8])
@pytest.mark.parametrize('seed', range(10))
def test_well_conditioned_systems_agree_with_numpy_to_rounding(n, seed):
    rng = np.random.default_rng(seed)
    rows = n + int(rng.integers(5, 200))
    a = rng.standard_normal((40, rows, n)) * 10.0 ** rng.uniform(-6, 6, (40, 1, n))
    m = np.einsum('kij,kil->kjl', a, a)
    r = np.einsum('kij,ki->kj', a, rng.standard_normal((40, rows)))
    expected, scaled = _numpy_solve(m, r)
    got = solve_scaled_stack(m, r)
    values = np.linalg.eigvalsh(scaled)
    kappa = values[:, -1] / values[:, 0]
    explained = np.einsum('ki,ki->k', got, r)
    reference = np.einsum('ki,ki->k', expected, r)
    assert np.all(np.abs(explained - reference) <= 100 * n * kappa * EPS * np.abs(reference))


def test_a_collinear_system_gets_numpy_s_minimum_norm_solution():
    rng = np.random.default_rng(3)
    speed = rng.uniform(1.0, 100.0, 300)
    h = np.column_stack([np.ones(300), np.full(300, 37.0), speed])  # first two collinear
    f = h @ np.array([0.2, 0.01, 3e-4]) + 1e-3 * rng.standard_normal(300)
    m, r = (h.T @ h)[None], (h.T @ f)[None]
    got = solve_scaled_stack(m, r)
    expected, _ = _numpy_solve(m, r)
    assert np.allclose(got, expected, rtol=1e-9, atol=0.0)
    fitted_lstsq = h @ np.linalg.lstsq(h, f, rcond=None)[0]
    assert np.allclose(h @ got[0], fitted_lstsq, rtol=1e-9, atol=0.0)


def test_a_constant_speed_segment_is_fitted_not_divided_by_zero():
    h = np.column_stack([np.ones(50), np.full(50, 45.6)])
    f = np.full(50, 0.3)
    got = solve_scaled_stack((h.T @ h)[None], (h.T @ f)[None])
    assert np.all(np.isfinite(got)) and np.allclose(h @ got[0], f, rtol=1e-12)


def test_a_zero_matrix_gives_zero_and_bad_input_gives_nan_without_touching_others():
    good = np.array([[2.0, 0.5], [0.5, 1.0]])
    m = np.stack([np.zeros((2, 2)), np.array([[1.0, np.nan], [np.nan, 1.0]]),
                  np.array([[np.inf, 0.0], [0.0, 1.0]]), good, good])
    r = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [np.nan, 1.0], [1.0, 2.0]])
    got = solve_scaled_stack(m, r)
    assert np.array_equal(got[0], [0.0, 0.0])
    assert np.all(np.isnan(got[1:4]))
    assert np.allclose(got[4], np.linalg.solve(good, [1.0, 2.0]), rtol=1e-14)


def test_leading_axes_are_kept_and_broadcast():
    rng = np.random.default_rng(5)
    a = rng.standard_normal((4, 3, 30, 3))
    m = np.einsum('...ij,...il->...jl', a, a)
    r = rng.standard_normal(3)
    got = solve_scaled(m, r)
    assert got.shape == (4, 3, 3)
    assert np.allclose(got, np.linalg.solve(m, np.broadcast_to(r, (4, 3, 3))[..., None])[..., 0],
                       rtol=1e-9)
    assert solve_scaled(m[0, 0], r).shape == (3,)
    assert solve_scaled(m[0, 0], np.broadcast_to(r, (5, 3))).shape == (5, 3)
