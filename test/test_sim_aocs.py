"""AOCS telemetry simulator: schema, seeds, truth labels, sensor noise and fault slopes."""

import math

import numpy as np
import pytest

from rwa_monitor.cli.main import main as cli_main
from rwa_monitor.core.attitude import star_tracker_rates
from rwa_monitor.sim.aocs import (add_gyro_channels, AocsConfig, DRIFT_SLOPES, GyroFault,
                                  named_fault, simulate_aocs)
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel


def test_seeded_and_schema():
    a = simulate_aocs(200.0, fault=named_fault('fast', 'y', 50.0), seed=7)
    b = simulate_aocs(200.0, fault=named_fault('fast', 'y', 50.0), seed=7)
    c = simulate_aocs(200.0, fault=named_fault('fast', 'y', 50.0), seed=8)
    np.testing.assert_array_equal(a.gyro, b.gyro)
    assert not np.array_equal(a.gyro, c.gyro)
    assert len(a) == 801 and np.allclose(np.diff(a.time), 0.25)
    cols = a.columns()
    for name in ('gyro_x', 'q_w', 'ref_z', 'truth_gyro_x', 'truth_gyro_y', 'truth_gyro_z'):
        assert name in cols


@pytest.mark.parametrize('name', ['fast', 'medium', 'slow', 'bias'])
def test_truth_labels_follow_the_fault(name):
    fault = named_fault(name, 'x', 100.0, level=2e-4)
    tele = simulate_aocs(1400.0, fault=fault, seed=1)
    lab = tele.truth['gyro_x']
    t = tele.time
    assert np.all(lab[t < 100.0] == 0)
    assert np.all(tele.truth['gyro_y'] == 0) and np.all(tele.truth['gyro_z'] == 0)
    if name == 'bias':
        assert np.all(lab[t >= 100.0] == 2)
    else:
        end = 100.0 + 2e-4 / DRIFT_SLOPES[name]
        assert np.all(lab[(t >= 100.0) & (t < end - 1e-9)] == 1)
        assert np.all(lab[t > end + 1e-9] == 2)
    np.testing.assert_allclose(tele.truth['gyro_error_x'][-1], 2e-4)


def test_drift_slope_is_seen_in_the_gyro_residual():
    # Least-squares slope of ref - gyro on the faulty axis over the 1000 s ramp: white noise
    # 1e-5 rad/s at 4 Hz gives a slope std of 1e-5 / sqrt(sum (t - mean)^2) ~ 5.5e-10
    # rad/s^2; the closed loop does not act on the gyro error, so the slope must be -2e-7
    # within 2e-9 (about 4 sigma plus the rate random walk).
    tele = simulate_aocs(1300.0, fault=named_fault('slow', 'x', 200.0), seed=2)
    inside = (tele.time > 210.0) & (tele.time < 1190.0)
    res = tele.reference_rate[inside, 0] - tele.gyro[inside, 0]
    slope = np.polyfit(tele.time[inside], res, 1)[0]
    assert abs(slope + 2e-7) < 2e-9


def test_sensor_noise_levels():
    # Gyro white noise: ARW 5e-6 rad/sqrt(s) at 4 Hz -> 1e-5 rad/s per sample. Star-tracker
    # rate noise per axis: sqrt(2) * 5 arcsec * 4 Hz = 1.37e-4 rad/s. 14400 samples give a
    # relative standard error of the std below 1 %; bounds at 5 %.
    cfg = AocsConfig(st_dropouts_per_hour=0.0, gyro_rrw=0.0, gyro_thermal=0.0)
    tele = simulate_aocs(3600.0, seed=3, config=cfg)
    true_rate = np.column_stack([tele.truth[f'rate_{a}'] for a in 'xyz'])
    gyro_noise = np.std(tele.gyro - true_rate, axis=0)
    np.testing.assert_allclose(gyro_noise, 1e-5, rtol=0.05)
    st = star_tracker_rates(tele.time, tele.attitude, max_gap=1.0)
    st_noise = np.nanstd(st - true_rate, axis=0)
    np.testing.assert_allclose(st_noise, math.sqrt(2) * 5 * math.pi / 648000 * 4, rtol=0.05)


def test_closed_loop_tracks_the_reference_and_the_slew():
    tele = simulate_aocs(3600.0, seed=5)
    true_rate = np.column_stack([tele.truth[f'rate_{a}'] for a in 'xyz'])
    assert np.max(np.abs(tele.reference_rate[:, 2])) > 8e-4           # the slew happens
    assert np.max(np.abs(true_rate - tele.reference_rate)) < 5e-5     # and is tracked


def test_dropouts_are_nan_rows():
    tele = simulate_aocs(3600.0, seed=6, config=AocsConfig(st_dropouts_per_hour=20.0))
    missing = np.isnan(tele.attitude).all(axis=1)
    assert missing.any()
    np.testing.assert_array_equal(missing, tele.truth['st_valid'] == 0)


def test_add_gyro_channels_on_an_existing_time_base():
    t = np.arange(0, 100.0, 0.1)
    tele = Telemetry(time=t, wheels={'rw1': Wheel(np.ones_like(t))}, truth={'rw1_dry': t})
    both = add_gyro_channels(tele, fault=GyroFault(1, 20.0, 1e-4, 1e-5), seed=0)
    assert both.gyro.shape == (1000, 3) and 'rw1' in both.wheels and 'rw1_dry' in both.truth
    assert both.truth['gyro_y'][-1] == 2 and both.truth['gyro_y'][250] == 1


def test_bad_parameters():
    with pytest.raises(ValueError, match='fault'):
        named_fault('sideways')
    with pytest.raises(ValueError, match='estimator_gain'):
        simulate_aocs(10.0, config=AocsConfig(estimator_gain=2.0))


def test_cli_writes_a_readable_file(tmp_path, capsys):
    out = tmp_path / 'g.csv'
    assert cli_main(['simulate', 'aocs', '--seconds', '60', '--fault', 'bias',
                     '--fault-time', '10', '--seed', '1', '-o', str(out)]) == 0
    tele = read_telemetry(out)
    assert tele.gyro.shape == (241, 3) and tele.truth['gyro_x'][-1] == 2
    assert cli_main(['simulate', 'aocs', '--seconds', '-1', '-o', str(out)]) == 2
