"""Coast-downs with friction from speed: external torques (a touch, a brake) are cut out."""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from rwa_monitor.cli.main import main
from rwa_monitor.core.identify.data import prepare
from rwa_monitor.core.identify.select import identify
from rwa_monitor.core.identify.transients import external_torques, running_median
from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry

J = 0.01            # kg m^2
NOISE = 2e-3        # rad/s


def _coast(extra=None, n=4000, dt=0.1, seed=0):
    """Return (t, w): J dw/dt = -2e-3 - 2e-5 w - 1e-7 w^2 + extra(t) from 300 rad/s."""
    t = np.arange(n) * dt

    def rate(time, w):
        torque = -2e-3 - 2e-5 * w - 1e-7 * w * w + (extra(time) if extra else 0.0)
        return torque / J
    sol = solve_ivp(rate, (0, t[-1]), [300.0], t_eval=t, rtol=1e-10, atol=1e-10,
                    max_step=0.05)
    return t, sol.y[0] + NOISE * np.random.default_rng(seed).standard_normal(n)


def _touch(start, seconds, torque):
    return lambda time: -torque if start <= time < start + seconds else 0.0


def test_running_median_keeps_a_step_and_follows_a_line_to_the_ends():
    x = np.where(np.arange(400) < 200, 1.0, 3.0) + 0.01 * np.arange(400)
    med = running_median(x, 51)
    assert np.allclose(med, x, atol=1e-9)


def test_a_clean_coast_loses_no_rows():
    t, w = _coast()
    assert external_torques(t, w) == []
    data = prepare(t, w, inertia=J)
    assert data.counts['dropped_external_torque_rows'] == 0
    assert data.runs == [0]


def test_a_touch_is_cut_out_and_splits_the_run_instead_of_passing_for_jumps():
    # 1e-3 N m for 1 s at t = 150 s: the speed loses 0.1 rad/s (50 noise sigmas).
    t, w = _coast(_touch(150.0, 1.0, 1e-3))
    found = external_torques(t, w)
    assert len(found) == 1 and found[0].kind == 'impulse'
    assert found[0].impulse_rad_s == pytest.approx(-0.1, rel=0.2)
    assert t[found[0].first] <= 150.0 <= 151.0 <= t[found[0].last]
    data = prepare(t, w, inertia=J)
    assert 0 < data.counts['dropped_external_torque_rows'] < 40
    assert len(data.runs) == 2
    assert any('external torque' in note for note in data.notes)
    sel = identify(data)
    assert sel.segments.starts == [0]


def test_a_timing_glitch_has_no_net_impulse_and_is_kept():
    t, w = _coast()
    k = 1500
    w[k] += 0.05              # one pulse late: one interval long, the next one short
    w[k + 1] -= 0.05
    assert external_torques(t, w) == []


def test_a_persisting_friction_step_is_not_an_external_torque():
    # the detectors' anomaly: dry friction up by 5e-4 N m from t = 200 s on
    t, w = _coast(lambda time: -5e-4 if time >= 200.0 else 0.0)
    assert external_torques(t, w) == []


def test_a_brake_at_the_end_trims_the_run():
    # the last 2 s (20 samples, shorter than half the trend window: TREND_SAMPLES)
    t, w = _coast(lambda time: -0.02 if time >= 398.0 else 0.0)
    found = external_torques(t, w)
    assert [e.kind for e in found] == ['edge'] and found[0].last == len(t) - 1
    assert t[found[0].first] <= 398.0


def test_a_coast_to_rest_says_hysteresis_cannot_be_identified(tmp_path):
    """Item 5: a coast-down never reverses: hysteresis is not identifiable, others are."""
    t, w = _coast()
    path = tmp_path / 'coast.csv'
    write_telemetry(path, Telemetry(time=t, wheels={'rw1': Wheel(speed=w)}))
    assert main(['identify', str(path), '--inertia', str(J), '-o', str(tmp_path / 'o')]) == 0
    text = (tmp_path / 'o' / 'report.md').read_text()
    assert 'hysteresis' in text and 'cannot be identified from this run' in text
    assert 'Identifiable from this run' in text and 'drag' in text
    details = json.loads((tmp_path / 'o' / 'selection.json').read_text())
    assert details['counts']['dropped_external_torque_rows'] == 0


def test_a_run_through_zero_speed_is_not_searched():
    # friction's own fast structure near zero (sign flip, breakaway) is not a touch
    t = np.arange(0.0, 600.0, 0.1)
    w = 5.0 * np.sin(2 * np.pi * t / 200.0)
    w[3000:3010] -= 0.5           # a touch-like dip while the speed reverses anyway
    assert external_torques(t, w) == []


def test_a_glitched_first_sample_does_not_set_the_integrated_speed():
    from rwa_monitor.core.identify.output_error import speed_rmse
    t, w = _coast()
    clean = w.copy()
    friction = -2e-3 - 2e-5 * clean - 1e-7 * clean ** 2
    w[0] += 0.3                   # one pulse early: the first speed 150 noise sigmas high
    sel = identify(prepare(t, w, friction))
    got = speed_rmse(sel, J)
    # the refined model is the truth here: its speed error stays at the noise level
    assert got['after'] < 5 * NOISE
