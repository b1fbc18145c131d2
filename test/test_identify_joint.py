"""Joint identification of sibling wheels declared identical (core/identify/joint.py)."""

import json

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.core.identify.consistency import compare_effects, weaker_than_siblings
from rwa_monitor.core.identify.effects import canonical_order
from rwa_monitor.core.identify.joint import identify_joint
from rwa_monitor.core.identify.select import identify
from rwa_monitor.pipelines.identify import prepare
from rwa_monitor.sim.undeclared import simulate_undeclared
from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry

N = 4000


def _bus(effects: list[str], seed: int = 30, n: int = N) -> Telemetry:
    """Return one record with a wheel per entry of ``effects`` (own noise each)."""
    wheels, aux = {}, {}
    for i, effect in enumerate(effects, start=1):
        tele = simulate_undeclared(effect, n=n, seed=seed + i, wheel=f'rw{i}')
        wheels.update(tele.wheels)
        aux.update(tele.aux)
    return Telemetry(time=tele.time, wheels=wheels, aux=aux)


@pytest.fixture(scope='module')
def same_drag():
    tele = _bus(['drag'] * 4)
    return identify_joint([prepare(tele, w) for w in tele.wheels])


def test_identical_wheels_get_one_effect_set_and_reach_the_noise_floor(same_drag):
    assert same_drag.effects == ['drag']
    assert same_drag.consistency['consistent'] and same_drag.consistency['rule'] == 'joint'
    for wheel, sel in same_drag.selections.items():
        assert [e.name for e in sel.effects] == ['drag']
        assert sel.final_fit.rmse_test <= 1.10 * sel.data.noise_floor
        own = sel.effects[0].evidence['own']
        assert own['p_value'] < 1e-6 and own['dof'] == 1
    exponents = {sel.effects[0].params['exponent'] for sel in same_drag.selections.values()}
    assert exponents == {2.0}   # the shared nonlinear parameter


def test_a_wheel_with_an_effect_its_siblings_lack_is_flagged():
    tele = _bus(['none', 'none', 'none', 'drag'])
    joint = identify_joint([prepare(tele, w) for w in tele.wheels])
    c = joint.consistency
    assert not c['consistent']
    assert list(c['flagged']) == ['rw4']
    assert c['flagged']['rw4']['extra'] == ['drag']
    assert c['agreeing'] == ['rw1', 'rw2', 'rw3']


def _stribeck_bus(excess_nm: float, seed: int, n: int = 4000) -> Telemetry:
    """Return four identical wheels with a small Stribeck excess, 40 zero passages."""
    t = np.arange(n) * 1.0
    w = 3.0 * np.sin(2 * np.pi * t / 200.0) + 1.5 * np.sin(2 * np.pi * t / 77.0 + 1.0)
    wheels = {}
    for i in range(4):
        noise = 5e-5 * np.random.default_rng(seed + i).standard_normal(n)
        f = -1e-3 * np.sign(w) - 5e-5 * w - excess_nm * np.sign(w) * np.exp(
            -(w / 0.8) ** 2) + noise
        wheels[f'rw{i + 1}'] = Wheel(speed=w, friction=f)
    return Telemetry(time=t, wheels=wheels)


def test_pooled_evidence_adds_an_effect_too_weak_for_most_wheels_alone():
    """A Stribeck excess of 0.4 noise std: one wheel alone finds it, the four together do."""
    tele = _stribeck_bus(2e-5, seed=70)
    alone = [[e.name for e in identify(prepare(tele, w)).effects] for w in tele.wheels]
    assert alone == [['stribeck'], [], [], []]
    joint = identify_joint([prepare(tele, w) for w in tele.wheels])
    assert joint.effects == ['stribeck'] and joint.consistency['consistent']
    for sel in joint.selections.values():
        assert 0.5 < sel.effects[0].params['velocity_rad_s'] < 1.3


def test_weaker_than_siblings_needs_both_a_wald_contradiction_and_no_own_evidence():
    cov = np.array([[1e-4]])
    items = [(np.array([1.0]), cov)] * 3 + [(np.array([0.0]), cov)]
    absent = {'p_value': 0.5}
    present = {'p_value': 1e-9}
    out = weaker_than_siblings(items, [present] * 3 + [absent], 1e-3, 1e-3)
    assert [r['contradicts'] for r in out] == [False, False, False, True]
    assert out[3]['dof'] == 1 and out[3]['wald'] == pytest.approx(1.0 / (1e-4 + 1e-4 / 3))
    # the same weights, but the wheel's own test shows the effect: not a contradiction
    out = weaker_than_siblings(items, [present] * 4, 1e-3, 1e-3)
    assert not any(r['contradicts'] for r in out)
    # a stronger effect than the siblings' is a different size, not a missing effect
    items = [(np.array([1.0]), cov)] * 3 + [(np.array([3.0]), cov)]
    out = weaker_than_siblings(items, [present] * 3 + [absent], 1e-3, 1e-3)
    assert not out[3]['contradicts'] and not out[3]['weaker']


def test_effects_are_compared_as_sets_in_the_vocabulary_order():
    assert canonical_order(['presliding', 'stribeck', 'stribeck_hysteresis']) == \
        ['stribeck', 'stribeck_hysteresis', 'presliding']
    c = compare_effects({'rw1': ['stribeck_hysteresis', 'presliding'],
                         'rw2': ['presliding', 'stribeck_hysteresis'],
                         'rw3': ['aux:rw3_motor_torque:dry', 'presliding',
                                 'stribeck_hysteresis']})
    assert c['reference'] == ['stribeck_hysteresis', 'presliding']
    assert c['flagged'] == {'rw3': {'missing': [], 'extra': ['aux:<wheel>_motor_torque:dry']}}


def test_cli_wheel_all_is_joint_unless_separately(tmp_path):
    path = tmp_path / 'bus.csv'
    write_telemetry(path, _bus(['drag', 'drag'], n=1500))
    assert main(['identify', str(path), '-o', str(tmp_path / 'all'), '--wheel', 'all']) == 0
    summary = json.loads((tmp_path / 'all' / 'wheels.json').read_text())
    assert summary['consistency']['rule'] == 'joint'
    assert summary['consistency']['reference'] == ['drag']
    report = json.loads((tmp_path / 'all' / 'rw2' / 'report.json').read_text())
    assert [e['name'] for e in report['effects']] == ['drag']
    assert report['effects'][0]['evidence']['added_at_step'] == 1
    assert main(['identify', str(path), '-o', str(tmp_path / 'sep'), '--wheel', 'all',
                 '--separately']) == 0
    summary = json.loads((tmp_path / 'sep' / 'wheels.json').read_text())
    assert summary['consistency']['rule'] == 'majority'
    assert summary['consistency']['reference'] == ['drag']


def test_an_effect_a_wheel_cannot_show_is_noted_not_flagged():
    """Hysteresis on two reversing wheels; the third never comes near zero speed."""
    from rwa_monitor.core.identify.data import speed_history
    from rwa_monitor.core.identify.effects import stribeck_shape
    n, dt = 6000, 0.25
    t = np.arange(n) * dt
    wheels = {}
    for i, offset in enumerate((0.0, 0.0, 30.0), start=1):
        w = offset + 6.0 * np.sin(2 * np.pi * t / 300.0) + 2.0 * np.sin(
            2 * np.pi * t / 71.0 + 1.0)
        left = speed_history(t, w).left_zero
        f = (-5e-4 * np.sign(w) - 2e-6 * w
             - 3e-4 * np.sign(w) * stribeck_shape(w, 1.0, 'peak') * left
             + 5e-5 * np.random.default_rng(80 + i).standard_normal(n))
        wheels[f'rw{i}'] = Wheel(speed=w, friction=f)
    tele = Telemetry(time=t, wheels=wheels)
    joint = identify_joint([prepare(tele, w) for w in tele.wheels])
    assert joint.effects[:1] == ['stribeck_hysteresis']
    c = joint.consistency
    assert 'stribeck_hysteresis' in c['not_testable']['rw3']
    assert 'rw3' not in c['flagged']
    assert 'stribeck_hysteresis' not in [e.name for e in joint.selections['rw3'].effects]
    for w in ('rw1', 'rw2'):
        sel = joint.selections[w]
        assert sel.effects[0].params['velocity_rad_s'] == pytest.approx(1.0, rel=0.25)
