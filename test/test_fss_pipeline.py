"""The FSS window diagnoser end to end: seeded windows, bad input, commands."""

import json

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.core.fss.pipeline import diagnose, extract, FssConfig, SlidingWindow
from rwa_monitor.core.schema import FSS, fss_config
from rwa_monitor.sim import fss
from rwa_monitor.telemetry.fss_model import load_model


@pytest.fixture(scope='module')
def model():
    return load_model()


def test_seeded_windows_are_diagnosed(model):
    # One window per status at the legacy magnitudes (2.5-3x), apart from the training
    # seed. The shipped model flags its own kind in >= 97 % of such windows per anomaly
    # (docs/results.md, section FSS), so two or more misses among the four anomalous
    # windows have probability below 6 x 0.03^2 < 0.01. Nominal windows are not judged
    # here: uncalibrated, the slow FSS can add 0.5-0.9 to the base dry estimate, above
    # the model's x1.6 threshold (docs/fss.md, "Anomaly sizes").
    tele = fss.simulate_fss(statuses=fss.STATUSES, seed=99, anomalies='legacy')
    missed = 0
    for wheel_id, status in zip(tele.wheels, fss.STATUSES):
        wheel = tele.wheels[wheel_id]
        out = diagnose(wheel.speed, wheel.friction, tele.time, model)
        assert set(out) >= {'anomalies', 'estimates', 'changepoints'}
        assert set(out['anomalies']) == {'dry', 'viscous', 'fss1', 'fss2'}
        if status != 'nominal':
            missed += not out['anomalies'][status]
    assert missed <= 1


def test_extraction_matches_truth_on_a_clean_window():
    rng = np.random.default_rng(5)
    sig = fss.simulate_wheel(80_000, 'nominal', rng, profile='biased')
    ext = extract(sig['speed'], sig['friction'])
    assert ext.viscous == pytest.approx(sig['viscous'], abs=0.01)
    assert ext.sigma == pytest.approx(sig['noise_std'], rel=0.1)
    true = np.flatnonzero(sig['jump'])
    found = np.min(np.abs(ext.accepted[:, None] - true[None, :]), axis=1)
    # Jumps of >= 4 sigma with w = 20: nearly every accepted changepoint is a true one.
    assert np.mean(found <= 3) > 0.9


def test_window_without_changepoints():
    rng = np.random.default_rng(6)
    x = fss.spin_profile(20_000, rng, kind='biased')
    y = 1.0 * np.sign(x) + 1.0 * x + rng.normal(0, 0.02, x.size)
    ext = extract(x, y)
    assert ext.accepted.size == 0
    assert ext.levels == [[0.0], [0.0]]
    assert ext.base_dry == pytest.approx(1.0, abs=0.01)


def test_nan_runs_constant_speed_and_more_changepoints_than_the_beam(model):
    rng = np.random.default_rng(7)
    sig = fss.simulate_wheel(30_000, 'nominal', rng)
    y = sig['friction'].copy()
    y[5000:7000] = np.nan
    y[9000] = np.inf
    out = diagnose(sig['speed'] * 400.0, -y * 2e-4, np.arange(y.size) / 10.0, model,
                   FssConfig(beam=2))
    assert set(out['anomalies']) == {'dry', 'viscous', 'fss1', 'fss2'}
    assert out['estimates']['assignment_exact'] is False
    assert np.isfinite(out['estimates']['base_dry_nm'])
    speed = np.full(20_000, 300.0)
    friction = -(2e-4 + 5e-7 * speed) + rng.normal(0, 5e-6, speed.size)
    out = diagnose(speed, friction, np.arange(speed.size) / 10.0, model)
    assert out['estimates']['viscous_identifiable'] is False
    assert out['anomalies']['viscous'] is False


def test_bad_config_and_lengths():
    with pytest.raises(ValueError, match='wglr_window'):
        FssConfig(wglr_window=1)
    with pytest.raises(ValueError, match='same length'):
        extract(np.zeros(10), np.zeros(11))
    assert FSS.validate({'wglr_window': 30}, strict=False)['wglr_window'] == 30
    assert fss_config(FSS.validate({'wglr_window': 30})).wglr_window == 30


def test_sliding_window_is_bounded_and_ordered():
    win = SlidingWindow(length=100, period=30)
    due = [win.update(float(t), 1.0, float(t)) for t in range(250)]
    assert win.size == 100
    assert [i for i, d in enumerate(due) if d] == [99, 129, 159, 189, 219, 249]
    t, w, f = win.snapshot()
    assert t.tolist() == list(range(150, 250))
    assert not win.update(10.0, 1.0, 1.0) and win.non_increasing_time == 1
    win.update(300.0, float('nan'), 1.0)
    assert win.non_finite == 1 and win.snapshot()[0][-1] == 300.0
    assert win.gaps == 1  # 300 after 249 with a step of 1
    win.reset()
    assert win.size == 0
    with pytest.raises(ValueError, match='length'):
        SlidingWindow(length=1)


def test_commands_end_to_end(tmp_path, capsys):
    data = tmp_path / 'fss.csv'
    assert main(['simulate', 'fss', '--status', 'nominal,fss1', '--samples', '20000',
                 '--seed', '1', '-o', str(data)]) == 0
    out = tmp_path / 'd.json'
    assert main(['diagnose', str(data), '-o', str(out)]) == 0
    result = json.loads(out.read_text())
    assert set(result['wheels']) == {'rw1', 'rw2'}
    rw1 = result['wheels']['rw1']
    assert set(rw1['anomalies']) == {'dry', 'viscous', 'fss1', 'fss2'}
    assert all(isinstance(v, bool) for v in rw1['anomalies'].values())
    assert {'base_dry_nm', 'viscous_nms', 'fss1_levels_nm'} <= set(rw1['estimates'])
    assert all({'index', 'time', 'fss'} <= set(c) for c in rw1['changepoints'])
    ds = tmp_path / 'ds'
    assert main(['fss', 'build', str(ds), '--per-status', '2', '--samples', '6000']) == 0
    assert main(['fss', 'train', str(ds), '-o', str(tmp_path / 'm.json'), '--bins', '5']) == 0
    assert main(['fss', 'evaluate', str(ds), '--model', str(tmp_path / 'm.json')]) == 0
    assert 'nominal' in capsys.readouterr().out
    assert json.loads((tmp_path / 'm.json').read_text())['relative'] is True
    legacy = tmp_path / 'legacy'
    assert main(['fss', 'build', str(legacy), '--per-status', '1', '--samples', '6000',
                 '--anomalies', 'legacy']) == 0
    assert main(['fss', 'evaluate', str(legacy), '--model', str(tmp_path / 'm.json')]) == 0
    assert 'absolute features' in capsys.readouterr().err
    assert main(['diagnose', str(tmp_path / 'missing.csv'), '-o', str(out)]) == 2


@pytest.mark.parametrize('seed', [2641, 2642])
def test_a_persistent_step_is_an_onset_not_an_fss_jump(model, seed):
    # A wheel without FSSs (the friction simulator, model (1)) with one dry or one
    # viscous step inside an 80,000-sample window: the step's level lasts longer than
    # any FSS residence (Example 2's longest is 30,000), so it is an onset; the part
    # after it is diagnosed and names the kind injected; no FSS is flagged. Seeds not
    # used while the rule was written (demo seed 7; checks on 2611-2615).
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    tele, _ = simulate_friction_with_truth(
        wheels=['a', 'b', 'c'], n_samples=80_000, rate_hz=10.0, seed=seed,
        anomalies=[Anomaly('a', 'dry', 3000.0, delta_dry=2.0e-4),
                   Anomaly('b', 'viscous', 6000.0, delta_viscous=1.0e-6)])
    expected = {'a': {'dry'}, 'b': {'viscous'}, 'c': set()}
    for wheel_id, kinds in expected.items():
        wheel = tele.wheels[wheel_id]
        out = diagnose(wheel.speed, wheel.friction, tele.time, model)
        assert {k for k, v in out['anomalies'].items() if v} == kinds
        if kinds:
            (onset,) = out['onsets']
            start = 30_000 if 'dry' in kinds else 60_000
            assert abs(onset['index'] - start) <= 20   # wGLR half-window
            assert out['estimates']['diagnosed_from_index'] == onset['index']
        else:
            assert out['onsets'] == [] and out['estimates']['diagnosed_from_index'] == 0


def test_paper_windows_hold_no_onset():
    # Examples 1-2 jump within their residences: no accepted changepoint is an onset on
    # windows of every status (seed apart from the other tests').
    tele = fss.simulate_fss(statuses=fss.STATUSES, seed=2643)
    for wheel_id in tele.wheels:
        wheel = tele.wheels[wheel_id]
        ext = extract(wheel.speed / 400.0, -wheel.friction / 2.0e-4)
        assert ext.onsets.size == 0 and ext.start == 0
