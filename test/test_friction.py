"""Tests of the friction regressors and least squares (llr-realtime paper, eq. (1)-(3))."""

import numpy as np
import pytest

from rwa_monitor.core.friction import (coulomb_viscous, dry_column, least_squares,
                                       normal_equations, RecursiveLeastSquares,
                                       RegressorSet, viscous_column)


def test_paper_model_rows_and_sign_convention():
    reg = coulomb_viscous()
    assert reg.names == ('dry', 'viscous') and reg.p == 2 and reg.is_coulomb_viscous
    speed = np.array([-3.0, 0.0, 2.0])
    h = reg.matrix(speed)
    np.testing.assert_array_equal(h, [[1.0, 3.0], [0.0, 0.0], [-1.0, -2.0]])
    # The simulator's torque -f_c sign(w) - f_v w is h x with x = [f_c, f_v] >= 0.
    x = np.array([0.4, 0.02])
    np.testing.assert_allclose(h @ x, -x[0] * np.sign(speed) - x[1] * speed)


def test_least_squares_recovers_the_parameters():
    rng = np.random.default_rng(3)
    speed = 20.0 - 10.0 * np.cos(np.pi * np.arange(4000) / 1200.0)
    speed[::7] *= -1.0
    x = np.array([1.2, 0.05])
    h = coulomb_viscous().matrix(speed)
    f = h @ x + 0.1 * rng.standard_normal(speed.size)
    est = least_squares(h, f)
    pi, q = normal_equations(h, f)
    np.testing.assert_allclose(est, np.linalg.solve(pi, q), rtol=1e-9)
    # Standard errors from sigma^2 Pi^-1; 6 sigma.
    se = 0.1 * np.sqrt(np.diag(np.linalg.inv(pi)))
    assert np.all(np.abs(est - x) < 6.0 * se)


def test_recursive_update_matches_batch_least_squares():
    rng = np.random.default_rng(4)
    speed = rng.uniform(-30.0, 30.0, 300)
    h = coulomb_viscous().matrix(speed)
    f = h @ np.array([0.8, 0.03]) + rng.standard_normal(300)
    rls = RecursiveLeastSquares(2)
    rls.initialise(h[:10], f[:10])
    for row, value in zip(h[10:], f[10:]):
        rls.add(row, value)
    np.testing.assert_allclose(rls.estimate, least_squares(h, f), rtol=1e-9)
    np.testing.assert_allclose(rls.inverse, np.linalg.inv(h.T @ h), rtol=1e-9)
    assert rls.n_samples == 300
    # From the ridge start the bias is ~prior / smallest eigenvalue of Pi (~1e-7 here).
    ridge = RecursiveLeastSquares(2, prior=1e-6)
    for row, value in zip(h, f):
        ridge.add(row, value)
    np.testing.assert_allclose(ridge.estimate, least_squares(h, f), rtol=1e-5)


def test_extra_columns_with_auxiliary_channels():
    def power(speed, time, aux):
        return -np.sign(speed) * np.abs(speed) ** 0.5

    def temperature(speed, time, aux):
        return -np.sign(speed) * aux['temperature']

    reg = RegressorSet(('dry', 'viscous', 'power', 'temp'),
                       (dry_column, viscous_column, power, temperature))
    assert reg.p == 4 and not reg.is_coulomb_viscous
    speed = np.array([4.0, -9.0])
    h = reg.matrix(speed, np.array([0.0, 1.0]), {'temperature': np.array([20.0, 30.0])})
    np.testing.assert_allclose(h, [[-1.0, -4.0, -2.0, -20.0], [1.0, 9.0, 3.0, 30.0]])
    with pytest.raises((KeyError, TypeError)):
        reg.matrix(speed)


@pytest.mark.parametrize('names, columns, match', [
    (('viscous', 'dry'), (viscous_column, dry_column), 'names must start'),
    (('dry',), (dry_column,), 'names must start'),
    (('dry', 'viscous', 'dry'), (dry_column, viscous_column, dry_column), 'unique'),
    (('dry', 'viscous'), (dry_column,), 'one callable per name'),
    (('dry', 'viscous'), (dry_column, 3.0), 'callables'),
])
def test_regressor_set_validation(names, columns, match):
    with pytest.raises(ValueError, match=match):
        RegressorSet(names, columns)


def test_recursive_least_squares_validation():
    with pytest.raises(ValueError, match='p must be'):
        RecursiveLeastSquares(0)
    with pytest.raises(ValueError, match='prior must be'):
        RecursiveLeastSquares(2, prior=0.0)
