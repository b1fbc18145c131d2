"""Quaternion helpers and the star-tracker rate (vsadc paper, eqs. (4)-(6))."""

import math

import numpy as np
import pytest

from rwa_monitor.core import attitude
from rwa_monitor.sim.aocs import AocsConfig, simulate_aocs


def _about(axis, angle):
    q = np.zeros(4)
    q[axis] = math.sin(angle / 2.0)
    q[3] = math.cos(angle / 2.0)
    return q


def test_multiply_by_hand():
    # i (x) j = k for the Hamilton product.
    i, j = np.array([1.0, 0, 0, 0]), np.array([0, 1.0, 0, 0])
    np.testing.assert_allclose(attitude.multiply(i, j), [0, 0, 1.0, 0])
    np.testing.assert_allclose(attitude.multiply(j, i), [0, 0, -1.0, 0])
    q = _about(2, 0.3)
    np.testing.assert_allclose(attitude.multiply(q, attitude.conjugate(q)), [0, 0, 0, 1.0],
                               atol=1e-15)


def test_rate_about_one_axis():
    # 0.01 rad about z in 0.25 s: 0.04 rad/s about z.
    rate = attitude.rate_between(_about(2, 0.2), attitude.multiply(_about(2, 0.2),
                                                                   _about(2, 0.01)), 0.25)
    np.testing.assert_allclose(rate, [0, 0, 0.04], atol=1e-15)


def test_rate_is_in_the_body_frame():
    # Attitude rotated 90 deg about z, then a body step about body x: the rate is along x.
    q0 = _about(2, math.pi / 2)
    q1 = attitude.multiply(q0, _about(0, 0.002))
    np.testing.assert_allclose(attitude.rate_between(q0, q1, 0.5), [0.004, 0, 0], atol=1e-14)


def test_small_angle_matches_the_paper_formula():
    # Paper eq. (6): w = 2 vec(dq) / Ts; exact and small-angle agree to third order.
    q0 = _about(0, 0.1)
    step = attitude.from_rotation_vector(np.array([1e-4, -2e-4, 3e-5]))
    q1 = attitude.multiply(q0, step)
    paper = 2.0 * step[:3] / 0.25
    np.testing.assert_allclose(attitude.rate_between(q0, q1, 0.25), paper, rtol=1e-8)


@pytest.mark.parametrize('flip_prev,flip_cur', [(True, False), (False, True), (True, True)])
def test_sign_flip_of_q_gives_the_same_rate(flip_prev, flip_cur):
    q0 = _about(1, 2.5)
    q1 = attitude.multiply(q0, _about(1, 0.001))
    ref = attitude.rate_between(q0, q1, 0.25)
    got = attitude.rate_between(-q0 if flip_prev else q0, -q1 if flip_cur else q1, 0.25)
    np.testing.assert_allclose(got, ref, atol=1e-12)
    np.testing.assert_allclose(ref, [0, 0.004, 0], atol=1e-12)


def test_180_degree_step_is_pi_over_dt_about_the_axis():
    got = attitude.rate_between(np.array([0, 0, 0, 1.0]), np.array([1.0, 0, 0, 0]), 2.0)
    assert abs(abs(got[0]) - math.pi / 2.0) < 1e-12 and np.allclose(got[1:], 0.0)


def test_just_past_180_degrees_takes_the_short_way():
    # +181 deg about x is -179 deg: the rate is negative with magnitude 179 deg / dt.
    got = attitude.rate_between(np.array([0, 0, 0, 1.0]), _about(0, math.radians(181)), 1.0)
    np.testing.assert_allclose(got, [-math.radians(179), 0, 0], atol=1e-12)


def test_rotation_vector_round_trip():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(100, 3))
    v *= (rng.uniform(0, math.pi * 0.999, 100) / np.linalg.norm(v, axis=1))[:, None]
    np.testing.assert_allclose(attitude.to_rotation_vector(attitude.from_rotation_vector(v)),
                               v, atol=1e-12)
    np.testing.assert_allclose(attitude.to_rotation_vector(-attitude.from_rotation_vector(v)),
                               v, atol=1e-12)


def test_streaming_rejects_bad_quaternions_and_counts_them():
    est = attitude.StarTrackerRate(max_gap=1.0)
    assert est.update(0.0, _about(0, 0.0)) is None              # first sample: no rate yet
    assert est.update(0.25, [np.nan, 0, 0, 1]) is None
    assert est.update(0.25, [0, 0, 0, 2.0]) is None             # norm 2: rejected
    assert est.update(0.0, _about(0, 0.001)) is None            # stamp not after the last
    rate = est.update(0.25, 1.05 * _about(0, 0.001))            # norm 1.05: normalised
    np.testing.assert_allclose(rate, [0.004, 0, 0], atol=1e-12)
    assert (est.invalid, est.non_increasing_time, est.gaps) == (2, 1, 0)


def test_streaming_restarts_after_a_gap():
    est = attitude.StarTrackerRate(max_gap=1.0)
    est.update(0.0, _about(0, 0.0))
    assert est.update(5.0, _about(0, 0.5)) is None              # 5 s gap: no averaged rate
    assert est.gaps == 1
    np.testing.assert_allclose(est.update(5.25, _about(0, 0.501)), [0.004, 0, 0], atol=1e-9)


def test_batch_equals_streaming_on_simulated_data_with_flips_and_dropouts():
    tele = simulate_aocs(300.0, seed=4, config=AocsConfig(st_sign_flip_probability=0.5,
                                                          st_dropouts_per_hour=60.0))
    q = tele.attitude.copy()
    q[10] = [0, 0, 0, 3.0]
    time = tele.time.copy()
    batch = attitude.star_tracker_rates(time, q, max_gap=1.0)
    est = attitude.StarTrackerRate(max_gap=1.0)
    stream = np.array([est.update(t, qi) or (np.nan,) * 3 for t, qi in zip(time, q)])
    np.testing.assert_allclose(batch, stream, atol=1e-15)
    assert np.isnan(batch[:, 0]).sum() > 3                       # dropouts leave holes
    # Half the samples are flipped to -q. The true rate is at most the slew rate 8.7e-4
    # rad/s plus 6 sigma of star-tracker noise (6 * 1.4e-4); an unhandled flip would read
    # as a 2 pi turn in 0.25 s, 25 rad/s.
    assert np.nanmax(np.abs(batch)) < 5e-3


def test_parameters_are_checked():
    with pytest.raises(ValueError, match='max_gap'):
        attitude.StarTrackerRate(max_gap=0.0)
    with pytest.raises(ValueError, match='norm_tolerance'):
        attitude.StarTrackerRate(norm_tolerance=1.5)
