"""Gyro-minus-star-tracker diagnosis, its calibration and the MEKF baseline (synthetic)."""

import math

import numpy as np
import pytest

from rwa_monitor.core import gyro_calibration as gc
from rwa_monitor.core.attitude import from_rotation_vector, multiply
from rwa_monitor.core.gyro_diagnosis import GyroDiagnosis
from rwa_monitor.core.mekf import cusum_alarms, mekf_bias
from rwa_monitor.pipelines import vsadc as pv
from rwa_monitor.telemetry.calibration_file import load_gyro_calibration

DT = 0.25
ST_STD = 2.42e-5       # rad, 5 arcsec
GYRO_STD = 1.0e-5      # rad/s per sample


def spacecraft(seconds, seed, error=None, amplitude=0.02, bias=(1e-5, -2e-5, 5e-6)):
    """Return time, gyro, star-tracker q of a body turning with a large sinusoidal rate.

    ``error(t)`` -> (n, 3) gyro error added to the bias (a fault); the true rate swings by
    ``amplitude`` rad/s, 400 times the bias step the tests look for.
    """
    rng = np.random.default_rng(seed)
    n = int(seconds / DT)
    t = DT * np.arange(1, n + 1)
    periods = np.array([700.0, 1100.0, 1500.0])
    rate = amplitude * np.sin(2 * np.pi * t[:, None] / periods)
    mid = amplitude * np.sin(2 * np.pi * (t[:, None] - DT / 2) / periods)
    q = np.empty((n, 4))
    cur = np.array([0.0, 0.0, 0.0, 1.0])
    for k in range(n):
        cur = multiply(cur, from_rotation_vector(mid[k] * DT))
        q[k] = cur
    noise = np.clip(rng.normal(0, ST_STD, (n, 3)), -3 * ST_STD, 3 * ST_STD)
    q_meas = multiply(q, from_rotation_vector(noise))
    q_meas[q_meas[:, 3] < 0] *= -1
    gyro = rate + np.asarray(bias) + rng.normal(0, GYRO_STD, (n, 3))
    if error is not None:
        gyro = gyro + error(t)
    return t, gyro, q_meas


def run(t, gyro, q, **kw):
    det = GyroDiagnosis(**kw)
    events = []
    for k in range(len(t)):
        events += det.update(t[k], gyro[k], q[k], None, k)
    return events, det


@pytest.fixture(scope='module')
def calibration():
    t, g, q = spacecraft(3600, seed=1)
    return gc.calibrate_gyro(t, g, q)


def test_residual_cancels_the_true_rate():
    t, g, q = spacecraft(600, seed=2)
    res = gc.step_residuals(t, g, q)
    # 0.02 rad/s of body rate is gone: the mean is the bias, the spread the sensor noise
    assert np.allclose(np.nanmean(res, axis=0), [1e-5, -2e-5, 5e-6], atol=3e-6)
    st_rate_noise = math.sqrt(2) * ST_STD / DT
    assert np.all(np.nanstd(res, axis=0) < 1.2 * math.hypot(st_rate_noise, GYRO_STD))


def test_calibration_keys_and_block_spread(calibration):
    assert set(calibration) == {'x', 'y', 'z'}
    for axis in calibration.values():
        assert set(axis) >= {'bias_rad_s', 'noise_std_rad_s', 'block_std_rad_s',
                             'correlation_time_s', 'level_threshold_rad_s',
                             'quiet_level_rad_s', 'slope_threshold_rad_s2'}
        assert all(isinstance(v, (int, float)) for v in axis.values())
        # block of 40: gyro 1e-5/sqrt(40) and star tracker sqrt(2) 2.42e-5 / 10 s
        expected = math.hypot(GYRO_STD / math.sqrt(40), math.sqrt(2) * ST_STD / 10.0)
        assert 0.6 * expected < axis['block_std_rad_s'] < 1.5 * expected
        assert axis['block_lag1_correlation'] < 0       # differenced star-tracker noise


def test_calibration_needs_enough_data():
    t, g, q = spacecraft(100, seed=3)
    with pytest.raises(ValueError, match='at least'):
        gc.calibrate_gyro(t, g, q)


def test_healthy_gyro_under_large_rates_is_quiet(calibration):
    t, g, q = spacecraft(5400, seed=4)
    events, det = run(t, g, q, calibration=calibration)
    assert events == []
    assert all(ch.ready for ch in det.channels)


@pytest.mark.parametrize('axis', [0, 1, 2])
def test_bias_step_is_a_bias_on_its_axis(calibration, axis):
    def error(t):
        e = np.zeros((len(t), 3))
        e[:, axis] = np.where(t >= 1000.0, -5e-5, 0.0)
        return e
    t, g, q = spacecraft(1800, seed=10 + axis, error=error)
    events, _ = run(t, g, q, calibration=calibration)
    assert [(e.component, e.kind) for e in events] == [(f'gyro_{"xyz"[axis]}', 'bias')]
    assert 1000.0 <= events[0].declared_time < 1060.0
    assert abs(events[0].time - 1000.0) < 10.0


@pytest.mark.parametrize('slope', [1e-6, 2e-7])
def test_drift_is_a_drift(calibration, slope):
    def error(t):
        e = np.zeros((len(t), 3))
        e[:, 1] = slope * np.maximum(t - 1000.0, 0.0)
        return e
    t, g, q = spacecraft(1800, seed=20, error=error)
    events, _ = run(t, g, q, calibration=calibration)
    assert [(e.component, e.kind) for e in events][:1] == [('gyro_y', 'drift')]
    assert events[0].time < events[0].declared_time


def test_fault_that_clears_recovers(calibration):
    def error(t):
        e = np.zeros((len(t), 3))
        e[:, 2] = np.where((t >= 800.0) & (t < 1400.0), 8e-5, 0.0)
        return e
    t, g, q = spacecraft(2000, seed=30, error=error)
    events, det = run(t, g, q, calibration=calibration)
    assert [e.kind for e in events] == ['bias', 'healthy']
    assert events[1].declared_time > 1400.0
    assert det.states['z'] == 0


def test_blinded_star_tracker_holds_and_resumes(calibration):
    t, g, q = spacecraft(3000, seed=40)
    q = q.copy()
    q[(t > 1200) & (t < 1500)] = np.nan          # sun in the field of view: 5 minutes
    events, det = run(t, g, q, calibration=calibration)
    assert events == []
    assert det.counters['held'] >= 1199
    assert det.counters['invalid_quaternions'] >= 1199


def test_saturated_gyro_is_counted_not_diagnosed(calibration):
    def error(t):
        e = np.zeros((len(t), 3))
        e[(t > 1000) & (t < 1100), 0] = 1.0       # the x rate rails at +1 rad/s
        return e
    t, g, q = spacecraft(1800, seed=50, error=error)
    events, det = run(t, g, q, calibration=calibration, saturation_rad_s=0.5)
    assert events == []
    assert det.counters['saturated_x'] >= 399


def test_pipeline_reads_the_calibration_file(tmp_path, calibration):
    import yaml
    path = tmp_path / 'calibration.yaml'
    path.write_text(yaml.safe_dump({'calibration': {'version': 1, 'gyro': calibration}}))
    assert load_gyro_calibration(path) == calibration
    det = pv.make_detector({'calibration_file': str(path)})
    assert det.channels[0].level_threshold == calibration['x']['level_threshold_rad_s']
    (tmp_path / 'bad.yaml').write_text('calibration: {wheels: {}}\n')
    with pytest.raises(ValueError, match='no calibration.gyro'):
        load_gyro_calibration(tmp_path / 'bad.yaml')


def test_mekf_estimates_the_bias_and_cusum_sees_a_step():
    def error(t):
        e = np.zeros((len(t), 3))
        e[:, 0] = np.where(t >= 1500.0, 5e-5, 0.0)
        return e
    t, g, q = spacecraft(2400, seed=60, error=error)
    bias = mekf_bias(t, g, q)
    late = t > 2000
    before = (t > 900) & (t < 1500)
    assert np.allclose(bias[before].mean(axis=0), [1e-5, -2e-5, 5e-6], atol=3e-6)
    assert abs(bias[late, 0].mean() - 6e-5) < 3e-6
    alarms = cusum_alarms(bias, t, spread_rad_s=2e-6, threshold=20.0)
    assert alarms and alarms[0]['axis'] == 0
    assert 1500.0 <= alarms[0]['time'] < 1600.0
    assert 1400.0 <= alarms[0]['onset'] <= alarms[0]['time']


def test_bus_slew_and_thermal_inputs_are_validated():
    from rwa_monitor.sim.basilisk_config import BusConfig
    cfg = BusConfig(slew_rate=0.0175, gyro_thermal_amplitude=1e-5).validated()
    assert cfg.slew_duration >= 2 * cfg.slew_ramp
    with pytest.raises(ValueError, match='slew_duration'):
        BusConfig(slew_duration=10.0, slew_ramp=20.0).validated()
    with pytest.raises(ValueError, match='gyro_thermal_amplitude'):
        BusConfig(gyro_thermal_amplitude=-1.0).validated()


@pytest.mark.slow
def test_demo_drift_then_hold_is_one_drift_then_one_bias():
    """The gyro stream of ``make demo``: a medium drift on y at 5400 s, held from 5600 s.

    Without a calibration the default block spread (bus, 4 Hz) is half this stream's
    (10 Hz, 4 s blocks), so the slope test alone flipped the kind 18 times; a bias turns
    into a drift only when the level has also moved by the level threshold.
    """
    from rwa_monitor.cli.cmd_demo import DEFAULT_HOURS, DEFAULT_SEED, RATE_HZ
    from rwa_monitor.sim.aocs import named_fault, simulate_aocs
    duration = DEFAULT_HOURS * 3600.0
    time = np.arange(int(duration * RATE_HZ)) / RATE_HZ
    tele = simulate_aocs(fault=named_fault('medium', 'y', round(duration / 2)),
                         seed=DEFAULT_SEED, time=time)
    truth = tele.truth['gyro_y']
    changes = time[np.flatnonzero(np.diff(truth)) + 1]
    assert changes.tolist() == pytest.approx([5400.0, 5600.0], abs=0.2)
    res = gc.step_residuals(tele.time, tele.gyro, tele.attitude)
    kinds = []
    for axis in range(3):
        channel = GyroDiagnosis().channels[axis]
        ok = np.isfinite(res[:, axis])
        for t, e in zip(time[ok], res[ok, axis]):
            tr = channel.update(e, t, t)
            if tr is not None:
                kinds.append(('xyz'[axis], tr.state, tr.declared))
    assert [k[:2] for k in kinds] == [('y', 1), ('y', 2)]     # drift, then bias
    assert 5400.0 < kinds[0][2] < 5500.0
    assert 5600.0 < kinds[1][2] < 5700.0
