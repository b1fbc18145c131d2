"""Identification of history-dependent friction, output error, consistency, bad input."""

import json

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.core.identify.consistency import compare_effects
from rwa_monitor.core.identify.data import speed_history
from rwa_monitor.core.identify.differentiate import choose_half_width
from rwa_monitor.core.identify.effects import stribeck_shape
from rwa_monitor.core.identify.report import identifiability
from rwa_monitor.core.identify.select import identify
from rwa_monitor.pipelines.identify import prepare
from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry


def _reversing(n=12000, dt=0.25, hysteresis=True, seed=4):
    """Return friction with a Stribeck peak only on the branch leaving zero speed."""
    t = np.arange(n) * dt
    w = 6.0 * np.sin(2 * np.pi * t / 300.0) + 2.0 * np.sin(2 * np.pi * t / 71.0 + 1.0)
    left = speed_history(t, w).left_zero
    f = -5e-4 * np.sign(w) - 2e-6 * w
    if hysteresis:
        f = f - 3e-4 * np.sign(w) * stribeck_shape(w, 1.0, 'peak') * left
    f = f + 5e-5 * np.random.default_rng(seed).standard_normal(n)
    return Telemetry(time=t, wheels={'rw1': Wheel(speed=w, friction=f)})


def test_history_marks_the_branch_that_leaves_zero():
    t = np.arange(0.0, 40.0, 0.5)
    w = np.sin(2 * np.pi * t / 20.0)          # zero at 0, 10, 20, 30 s; peaks at 5, 15...
    past = speed_history(t, w)
    assert past.passages >= 3
    assert past.left_zero[(t > 11) & (t < 14.5)].all()       # leaving zero (negative side)
    assert not past.left_zero[(t > 16) & (t < 19)].any()     # approaching zero
    # the passage is the first sample of the new sign (10.5 s: sin(pi) is 1e-16 > 0)
    assert past.since_zero_s[t == 13.0][0] == pytest.approx(2.5)


def test_hysteresis_is_named_and_its_stribeck_speed_recovered():
    sel = identify(prepare(_reversing()))
    names = [e.name for e in sel.effects]
    assert names[:1] == ['stribeck_hysteresis']
    assert 'smooth_speed' not in names
    assert sel.effects[0].params['velocity_rad_s'] == pytest.approx(1.0, rel=0.25)
    assert sel.final_fit.rmse_test < 1.05 * sel.data.noise_floor
    before, after = (d['tests']['approach'] for d in (sel.diagnostics_before,
                                                      sel.diagnostics_after))
    assert after['statistic'] < before['statistic']


def test_run_without_reversal_says_hysteresis_cannot_be_identified(tmp_path):
    t = np.arange(0.0, 3000.0, 1.0)
    w = 20.0 + 10.0 * np.sin(2 * np.pi * t / 900.0)          # never near zero
    f = -5e-4 - 2e-6 * w + 5e-5 * np.random.default_rng(1).standard_normal(len(t))
    tele = Telemetry(time=t, wheels={'rw1': Wheel(speed=w, friction=f)})
    sel = identify(prepare(tele))
    ident = identifiability(sel)
    assert 'cannot be identified' in ident['not_identifiable']['stribeck_hysteresis']
    assert 'drag' in ident['testable'] and 'stribeck' in ident['testable']
    path = tmp_path / 'one_way.csv'
    write_telemetry(path, tele)
    assert main(['identify', str(path), '-o', str(tmp_path / 'out')]) == 0
    text = (tmp_path / 'out' / 'report.md').read_text()
    assert 'hysteresis' in text and 'Identifiable from this run' in text


def test_siblings_with_different_effects_are_flagged():
    got = compare_effects({'rw1': ['a', 'b'], 'rw2': ['b', 'a'], 'rw3': ['a'],
                           'rw4': ['a', 'b']})
    assert got['reference'] == ['a', 'b']
    assert list(got['flagged']) == ['rw3'] and got['flagged']['rw3']['missing'] == ['b']
    assert compare_effects({'rw1': ['a'], 'rw2': ['a']})['consistent']


def test_wheel_all_writes_one_folder_per_wheel_and_the_side_by_side(tmp_path):
    one = _reversing(n=3000)
    tele = Telemetry(time=one.time, wheels={'rw1': one.wheels['rw1'],
                                            'rw2': _reversing(n=3000, seed=5).wheels['rw1']})
    path = tmp_path / 'two.csv'
    write_telemetry(path, tele)
    assert main(['identify', str(path), '--wheel', 'all', '-o', str(tmp_path / 'o')]) == 0
    for wheel in ('rw1', 'rw2'):
        assert (tmp_path / 'o' / wheel / 'report.json').exists()
    summary = json.loads((tmp_path / 'o' / 'wheels.json').read_text())
    assert set(summary['wheels']) == {'rw1', 'rw2'}
    assert 'consistency' in summary


def test_speed_rmse_in_report_when_friction_comes_from_speed(tmp_path):
    from scipy.integrate import solve_ivp
    j = 0.01
    t = np.arange(0.0, 300.0, 0.1)
    sol = solve_ivp(lambda _, w: (-2e-3 - 2e-5 * w - 1e-7 * w * w) / j, (0, t[-1]), [300.0],
                    t_eval=t, rtol=1e-10, atol=1e-10)
    w = sol.y[0] + 2e-3 * np.random.default_rng(0).standard_normal(len(t))
    path = tmp_path / 'coast.csv'
    write_telemetry(path, Telemetry(time=t, wheels={'rw1': Wheel(speed=w)}))
    assert main(['identify', str(path), '--inertia', str(j), '-o', str(tmp_path / 'o')]) == 0
    rep = json.loads((tmp_path / 'o' / 'report.json').read_text())
    assert set(rep['speed_rmse']) == {'before', 'after'}
    assert rep['speed_rmse']['after'] < 0.2 * rep['speed_rmse']['before']
    details = json.loads((tmp_path / 'o' / 'selection.json').read_text())
    assert details['differentiator']['chosen_from'].startswith('data')


def test_differentiator_width_trades_noise_against_bias():
    t = np.arange(0.0, 200.0, 0.1)
    rng = np.random.default_rng(2)
    noisy_line = 5.0 - 0.2 * t + 1e-2 * rng.standard_normal(len(t))
    wide, _ = choose_half_width(t, noisy_line)
    wiggly = np.sin(2 * np.pi * t / 3.0) + 1e-6 * rng.standard_normal(len(t))
    narrow, table = choose_half_width(t, wiggly)
    assert wide > narrow
    assert table[narrow]['bias_rms'] < table[max(table)]['bias_rms']
