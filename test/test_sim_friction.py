"""Tests of the friction telemetry simulator (model (1) of the llr-realtime paper)."""

import math

import numpy as np
import pytest
from scipy import stats

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.sim import profiles
from rwa_monitor.sim.friction import (Anomaly, changes_from_truth, parse_anomaly, REGIMES,
                                      simulate_friction, simulate_friction_with_truth)


def _noise(tele, wheel_id):
    """Return friction minus the noiseless model (1) rebuilt from the truth columns."""
    w = tele.wheels[wheel_id]
    model = (-tele.truth[f'{wheel_id}_dry'] * np.sign(w.speed)
             - tele.truth[f'{wheel_id}_viscous'] * w.speed)
    return w.friction - model


def test_same_seed_same_data_and_other_seed_differs():
    a = simulate_friction(duration_s=600, seed=3)
    b = simulate_friction(duration_s=600, seed=3)
    c = simulate_friction(duration_s=600, seed=4)
    for wheel_id in a.wheels:
        np.testing.assert_array_equal(a.wheels[wheel_id].friction, b.wheels[wheel_id].friction)
        np.testing.assert_array_equal(a.wheels[wheel_id].speed, b.wheels[wheel_id].speed)
        assert not np.array_equal(a.wheels[wheel_id].friction, c.wheels[wheel_id].friction)


def test_wheel_does_not_depend_on_number_of_wheels():
    one = simulate_friction(n_wheels=1, duration_s=300, seed=1)
    four = simulate_friction(n_wheels=4, duration_s=300, seed=1)
    np.testing.assert_array_equal(one.wheels['rw1'].friction, four.wheels['rw1'].friction)
    assert list(four.wheels) == ['rw1', 'rw2', 'rw3', 'rw4']
    assert not np.array_equal(four.wheels['rw1'].speed, four.wheels['rw2'].speed)


def test_truth_columns_and_time_axis():
    tele = simulate_friction(wheels=('a', 'b'), duration_s=10.0, rate_hz=4.0)
    assert len(tele) == 40
    np.testing.assert_allclose(tele.time, np.arange(40) / 4.0)
    assert set(tele.truth) == {'a_dry', 'a_viscous', 'a_noise_std',
                               'b_dry', 'b_viscous', 'b_noise_std'}
    np.testing.assert_array_equal(tele.truth['a_dry'], REGIMES['si']['dry_nm'])


@pytest.mark.parametrize('kind,dry,visc', [('dry', 2e-4, 0.0), ('viscous', 0.0, 3e-7),
                                           ('both', -1e-4, 1e-7)])
def test_step_applied_at_first_sample_at_or_after_its_time(kind, dry, visc):
    # 1234.55 s at 10 Hz falls between samples 12345 and 12346: the step starts at 12346.
    tele, changes = simulate_friction_with_truth(
        duration_s=3600, anomalies=[Anomaly('rw3', kind, 1234.55, dry, visc)], seed=2)
    assert len(changes) == 1 and changes[0].index == 12346
    assert changes[0].time_s == pytest.approx(1234.6)
    d_dry = np.diff(tele.truth['rw3_dry'])
    d_visc = np.diff(tele.truth['rw3_viscous'])
    assert np.flatnonzero(d_dry).tolist() == ([12345] if dry else [])
    assert np.flatnonzero(d_visc).tolist() == ([12345] if visc else [])
    if dry:
        assert d_dry[12345] == pytest.approx(dry)
    if visc:
        assert d_visc[12345] == pytest.approx(visc)
    for other in ('rw1', 'rw2', 'rw4'):
        assert np.ptp(tele.truth[f'{other}_dry']) == 0
    # The friction itself carries the step: the noise left after the truth model is clean.
    noise = _noise(tele, 'rw3')
    assert abs(noise.mean()) < 6 * REGIMES['si']['noise_std_nm'] / math.sqrt(len(noise))
    assert changes_from_truth(tele)[0].index == 12346
    assert changes_from_truth(tele)[0].kind == kind


def test_steps_add_up_and_are_sorted():
    _, changes = simulate_friction_with_truth(
        n_samples=1000, rate_hz=1.0, profile='fig3', units='scaled',
        anomalies=[Anomaly('rw1', 'dry', 700, 0.5), Anomaly('rw1', 'dry', 300, 0.3)])
    assert [c.index for c in changes] == [300, 700]
    tele = simulate_friction(n_samples=1000, rate_hz=1.0, profile='fig3', units='scaled',
                             anomalies=[Anomaly('rw1', 'dry', 700, 0.5),
                                        Anomaly('rw1', 'dry', 300, 0.3)])
    assert tele.truth['rw1_dry'][999] == pytest.approx(REGIMES['scaled']['dry_nm'] + 0.8)


@pytest.mark.parametrize('units', ['si', 'scaled'])
def test_noise_std_within_chi_square_bounds(units):
    # (n - 1) s^2 / sigma^2 ~ chi2(n - 1): the 1e-6 two-sided quantiles bound s^2 / sigma^2,
    # so a correct generator fails this with probability 1e-6 (and the seed is fixed).
    n = 20000
    tele = simulate_friction(n_wheels=1, n_samples=n, profile='realistic', units=units, seed=5)
    sigma = REGIMES[units]['noise_std_nm']
    ratio = np.var(_noise(tele, 'rw1'), ddof=1) / sigma ** 2
    low, high = stats.chi2.ppf([5e-7, 1 - 5e-7], n - 1) / (n - 1)
    assert low < ratio < high


def test_zero_noise_gives_exact_model():
    tele = simulate_friction(n_wheels=2, n_samples=500, profile='ramp', noise_std_nm=0.0,
                             dry_nm=1e-3, viscous_nms=2e-6)
    w = tele.wheels['rw2']
    np.testing.assert_allclose(w.friction, -1e-3 * np.sign(w.speed) - 2e-6 * w.speed)


@pytest.mark.parametrize('name,formula', [
    ('fig3', lambda k: 20 - 10 * np.cos(np.pi * k / 1200)),
    ('fig4', lambda k: 20 + 5 * np.cos(np.pi * k / 1000)),
    ('fig5', lambda k: 20 + 5 * np.cos(k / 5000)),
    ('fig6', lambda k: 100 - k / 1250),
])
def test_paper_profiles_match_their_formulas(name, formula):
    tele = simulate_friction(n_wheels=2, n_samples=30000, rate_hz=1.0, profile=name)
    k = np.arange(30000)
    np.testing.assert_allclose(tele.wheels['rw1'].speed, formula(k), rtol=0, atol=1e-12)
    np.testing.assert_allclose(tele.wheels['rw2'].speed, formula(k + 300), atol=1e-12)


def test_ramp_profile_sweeps_through_zero():
    t = np.arange(0, 2400, 0.1)
    w = profiles.ramp_profile(t)
    assert w.max() == pytest.approx(profiles.RAMP_AMPLITUDE_RAD_S, rel=1e-3)
    assert w.min() == pytest.approx(-profiles.RAMP_AMPLITUDE_RAD_S, rel=1e-3)
    slope = 4 * profiles.RAMP_AMPLITUDE_RAD_S / profiles.RAMP_PERIOD_S
    assert np.abs(np.diff(w) / 0.1).max() == pytest.approx(slope, rel=1e-6)


def test_realistic_profile_is_bounded_and_crosses_zero():
    tele = simulate_friction(n_wheels=4, duration_s=3 * 3600, rate_hz=10.0, seed=0)
    # Bound on |dw/dt|: slews at most MAX_ACCEL plus the orbital sinusoid's 2 pi A / T.
    accel_bound = (profiles.MAX_ACCEL_RAD_S2 + 2 * np.pi * profiles.ORBIT_AMPLITUDE_RAD_S
                   / profiles.ORBIT_PERIOD_S)
    crossings = 0
    for w in tele.wheels.values():
        assert np.abs(w.speed).max() <= profiles.MAX_SPEED_RAD_S
        assert np.abs(np.diff(w.speed)).max() * 10.0 <= accel_bound * (1 + 1e-9)
        crossings += np.count_nonzero(np.diff(np.sign(w.speed)) != 0)
        assert np.ptp(w.speed) > 100.0
    assert crossings >= 4


@pytest.mark.parametrize('spec,expected', [
    ('rw2:dry:3600:+2e-4', Anomaly('rw2', 'dry', 3600.0, 2e-4, 0.0)),
    ('rw1:viscous:10.5:-1e-7', Anomaly('rw1', 'viscous', 10.5, 0.0, -1e-7)),
    ('rw4:both:0:1e-4:2e-7', Anomaly('rw4', 'both', 0.0, 1e-4, 2e-7)),
])
def test_parse_anomaly(spec, expected):
    assert parse_anomaly(spec) == expected


@pytest.mark.parametrize('spec,message', [
    ('rw2:dry:3600', 'expected WHEEL:KIND'),
    ('rw2:stiction:3600:1e-4', 'kind must be one of'),
    ('rw2:dry:soon:1e-4', 'must be numbers'),
    ('rw2:dry:-5:1e-4', 'time must be >= 0'),
    ('rw2:both:5:1e-4', 'expected WHEEL:KIND'),
    (':dry:5:1e-4', 'expected WHEEL:KIND'),
    ('rw2:dry:5:nan', 'sizes finite'),
])
def test_parse_anomaly_rejects_bad_specs(spec, message):
    with pytest.raises(ConfigError, match=message):
        parse_anomaly(spec)


@pytest.mark.parametrize('kwargs,message', [
    ({'anomalies': [Anomaly('rw9', 'dry', 1.0, 1e-4)]}, 'unknown wheel'),
    ({'anomalies': [Anomaly('rw1', 'dry', 1e5, 1e-4)]}, 'anomaly time_s'),
    ({'profile': 'sine'}, 'profile must be one of'),
    ({'rate_hz': 0.0}, 'rate_hz'),
    ({'units': 'imperial'}, 'units must be one of'),
    ({'noise_std_nm': -1.0}, 'noise_std_nm'),
    ({'wheels': ('rw1', 'rw1')}, 'distinct'),
])
def test_bad_parameters_raise_value_error_naming_them(kwargs, message):
    with pytest.raises(ValueError, match=message):
        simulate_friction(duration_s=100.0, **kwargs)
