"""The Basilisk bus on the simulator itself (skipped where the optional extra is absent).

One seeded 30-minute run with a friction step on rw2 (600 s) and a gyro drift on x
(900 s) is shared by the tests. Statistical bounds: with n independent samples a mean is
within 5 sigma / sqrt(n) and a standard deviation within 5 / sqrt(2 n) (relative) of its
true value except with probability < 1e-6; a lag-1 autocorrelation of white noise is
within 5 / sqrt(n) of 0 with the same probability.
"""

import math
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip('Basilisk', reason='optional extra bsk not installed (make test-bsk)')

from rwa_monitor.core.attitude import conjugate, multiply  # noqa: E402
from rwa_monitor.sim.basilisk import BasiliskBus, FRICTION_SIGN  # noqa: E402
from rwa_monitor.sim.basilisk_config import (AXES, BIAS, BusConfig, DRIFT,  # noqa: E402
                                             FrictionFault, HEALTHY, parse_fault, WHEEL_IDS)

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi

DURATION = 1800.0
FAULTS = ('friction:rw2:600:dry=3e-4', 'gyro:x:900:drift=1e-6,level=2e-4')


@pytest.fixture(scope='module')
def run():
    bus = BasiliskBus(BusConfig(), [parse_fault(s) for s in FAULTS], seed=7)
    return bus, bus.run(DURATION)


def _five_sigma_mean(n):
    return 5.0 / math.sqrt(n)


def test_time_base_and_columns(run):
    bus, tele = run
    n = int(DURATION * bus.config.rate_hz)
    assert len(tele) == n
    np.testing.assert_allclose(tele.time, np.arange(1, n + 1) * bus.dt)
    assert list(tele.wheels) == list(WHEEL_IDS)
    assert sorted(tele.aux) == [f'{w}_motor_torque' for w in WHEEL_IDS]
    for name in ('rw2_dry', 'rw2_viscous', 'rw2_friction_true', 'gyro_x', 'gyro_error_x',
                 'rate_z', 'q_w'):
        assert name in tele.truth
    assert all(np.all(np.isfinite(v)) for v in tele.columns().values())


def test_friction_opposes_motion_as_the_project_convention(run):
    """The simulator's friction torque has the sign of -speed away from zero speed."""
    _, tele = run
    assert FRICTION_SIGN == 1.0
    for w in WHEEL_IDS:
        speed, friction = tele.wheels[w].speed, tele.truth[f'{w}_friction_true']
        away = np.abs(speed) > 3.0
        assert away.sum() > 1000
        assert np.all(np.sign(friction[away]) == -np.sign(speed[away]))


def test_friction_far_from_zero_is_coulomb_plus_viscous_with_the_step(run):
    """|w| > 5 beta: Stribeck term < 1e-8 N m (exp(-12.5)); the rest is model (1) exactly."""
    _, tele = run
    for w in WHEEL_IDS:
        speed = tele.wheels[w].speed
        dry, viscous = tele.truth[f'{w}_dry'], tele.truth[f'{w}_viscous']
        model = -dry * np.sign(speed) - viscous * speed
        away = np.abs(speed) > 5.0
        assert np.max(np.abs(tele.truth[f'{w}_friction_true'] - model)[away]) < 1e-7
    dry = tele.truth['rw2_dry']
    start = int(np.searchsorted(tele.time, 600.0))
    assert np.all(dry[:start] == BusConfig.coulomb)
    np.testing.assert_allclose(dry[start:], BusConfig.coulomb + 3e-4)
    for w in ('rw1', 'rw3', 'rw4'):
        assert np.all(tele.truth[f'{w}_dry'] == BusConfig.coulomb)


def test_stribeck_excess_after_zero_crossings(run):
    """Near zero speed the simulator is not model (1): the undeclared effect."""
    _, tele = run
    excess = []
    for w in WHEEL_IDS:
        speed = tele.wheels[w].speed
        model = -tele.truth[f'{w}_dry'] * np.sign(speed) - tele.truth[f'{w}_viscous'] * speed
        near = np.abs(speed) < 3.0
        excess.append(np.max(np.abs(tele.truth[f'{w}_friction_true'] - model)[near]))
    assert max(excess) > 0.5 * (BusConfig.static - BusConfig.coulomb)


def test_friction_noise_is_white_with_the_configured_std(run):
    _, tele = run
    noise = np.concatenate([tele.wheels[w].friction - tele.truth[f'{w}_friction_true']
                            for w in WHEEL_IDS])
    sigma, n = BusConfig.friction_noise_std, noise.size
    assert abs(noise.mean()) < _five_sigma_mean(n) * sigma
    assert abs(noise.std() / sigma - 1.0) < 5.0 / math.sqrt(2 * n)


def test_wheel_speeds_vary_and_cross_zero(run):
    _, tele = run
    for w in WHEEL_IDS:
        speed = tele.wheels[w].speed
        assert np.count_nonzero(np.diff(np.sign(speed))) >= 1, w
        assert np.ptp(speed) > 10.0, w


def test_speed_motor_torque_and_friction_belong_to_the_same_step(run):
    """Js dw/dt = u + f over each step (the one-step lag trap would break this)."""
    bus, tele = run
    js = bus.config.wheel_inertia
    for w in WHEEL_IDS:
        speed = tele.wheels[w].speed
        accel = js * np.diff(speed) / bus.dt
        torque = tele.aux[f'{w}_motor_torque'] + tele.truth[f'{w}_friction_true']
        away = np.abs(speed[1:]) > 3.0
        aligned = np.sqrt(np.mean((accel - torque[1:])[away] ** 2))
        lagged = np.sqrt(np.mean((accel - torque[:-1])[away] ** 2))
        assert aligned < 0.01 * np.sqrt(np.mean(accel[away] ** 2)), w
        assert aligned < lagged, w


def test_gyro_noise_bias_and_drift_fault(run):
    _, tele = run
    rate = np.column_stack([tele.truth[f'rate_{a}'] for a in AXES])
    nominal = np.column_stack([tele.truth[f'gyro_nominal_bias_{a}'] for a in AXES])
    fault = np.column_stack([tele.truth[f'gyro_error_{a}'] for a in AXES])
    noise = tele.gyro - rate - nominal - fault
    sigma, n = BusConfig.gyro_noise_std, len(tele)
    assert np.all(np.abs(noise.mean(axis=0)) < _five_sigma_mean(n) * sigma)
    assert np.all(np.abs(noise.std(axis=0) / sigma - 1.0) < 5.0 / math.sqrt(2 * n))
    for i in range(3):
        assert abs(np.corrcoef(noise[1:, i], noise[:-1, i])[0, 1]) < 5.0 / math.sqrt(n)
    assert np.all(np.abs(nominal - nominal[0]) <= 2 * BusConfig.gyro_walk_bound)
    labels = tele.truth['gyro_x']
    t = tele.time
    assert np.all(labels[t < 900.0] == HEALTHY)
    assert np.all(labels[(t >= 900.0) & (t < 1099.0)] == DRIFT)
    assert np.all(labels[t > 1101.0] == BIAS)
    np.testing.assert_allclose(fault[t > 1101.0, 0], 2e-4)
    np.testing.assert_allclose(fault[(t >= 900.0) & (t < 1099.0), 0],
                               1e-6 * (t[(t >= 900.0) & (t < 1099.0)] - 900.0))
    assert np.all(tele.truth['gyro_y'] == HEALTHY) and np.all(fault[:, 1:] == 0.0)


def test_star_tracker_noise_is_white_and_bounded(run):
    """Angle error per axis: std 5 arcsec (clipped at 3 sigma), never beyond 3 sigma."""
    _, tele = run
    q_true = np.column_stack([tele.truth[c] for c in ('q_x', 'q_y', 'q_z', 'q_w')])
    err = multiply(conjugate(q_true), tele.attitude)
    angle = 2.0 * np.sign(err[:, 3:4]) * err[:, :3] * ARCSEC_PER_RAD
    sigma, n = BusConfig.st_noise_arcsec, len(tele)
    assert np.all(np.abs(angle) <= 3.0 * sigma * (1 + 1e-6))
    # clipping at 3 sigma lowers the std by < 0.2 %
    assert np.all(np.abs(angle.std(axis=0) / sigma - 1.0) < 5.0 / math.sqrt(2 * n) + 0.002)
    for i in range(3):
        assert abs(np.corrcoef(angle[1:, i], angle[:-1, i])[0, 1]) < 5.0 / math.sqrt(n)
    assert np.all(tele.attitude[:, 3] >= 0.0)
    np.testing.assert_allclose(np.linalg.norm(tele.attitude, axis=1), 1.0, atol=1e-9)


def test_reference_rate_is_tracked(run):
    _, tele = run
    rate = np.column_stack([tele.truth[f'rate_{a}'] for a in AXES])
    assert np.max(np.abs(tele.reference_rate - rate)[len(tele) // 10:]) < 1e-3
    assert np.max(np.abs(tele.reference_rate)) > 0.01


def test_same_seed_same_telemetry_other_seed_other_noise():
    a = BasiliskBus(seed=3).run(25.0)
    b = BasiliskBus(seed=3).run(25.0)
    c = BasiliskBus(seed=4).run(25.0)
    for name, values in a.columns().items():
        np.testing.assert_array_equal(values, b.columns()[name], err_msg=name)
    assert not np.array_equal(a.gyro, c.gyro)
    assert not np.array_equal(a.attitude, c.attitude)
    assert not np.array_equal(a.wheels['rw1'].friction, c.wheels['rw1'].friction)


def test_fault_scheduled_while_running_starts_at_the_next_sample():
    bus = BasiliskBus(seed=1)
    for _ in range(10):
        bus.step()
    bus.schedule(parse_fault('friction:rw3:now:dry=2e-4', now=bus.time))
    sample = bus.step()
    assert sample.truth['rw3_dry'] == pytest.approx(BusConfig.coulomb + 2e-4)
    assert sample.truth['rw1_dry'] == BusConfig.coulomb
    with pytest.raises(ValueError, match='wheel'):
        bus.schedule(FrictionFault('rw7', 0.0, 1e-4))


def test_run_rejects_a_duration_shorter_than_a_sample():
    with pytest.raises(ValueError, match='duration_s'):
        BasiliskBus().run(0.1)


def test_bad_configuration_raises_before_the_simulator_sees_it():
    """The wheel factory helper would exit(1); values are validated and it is not used."""
    with pytest.raises(ValueError, match='wheel_inertia'):
        BasiliskBus(BusConfig(wheel_inertia=-1.0))
    with pytest.raises(ValueError, match='static'):
        BasiliskBus(BusConfig(static=1e-5))


def test_no_gravity_or_wheel_factory_helper_is_imported():
    """The gravity helper makes a network request at import; neither helper is needed."""
    code = ('import sys\n'
            'import rwa_monitor.sim.basilisk as b\n'
            'b.BasiliskBus().run(1.0)\n'
            'bad = [m for m in sys.modules if m.endswith(("simIncludeGravBody", '
            '"simIncludeRW"))]\n'
            'assert not bad, bad\n')
    subprocess.run([sys.executable, '-c', code], check=True)
