"""Commissioning calibration: core arithmetic, file contract, calibrated LLR, command line."""

import json

import numpy as np
import pytest
import yaml

from rwa_monitor.cli.main import main
from rwa_monitor.core import calibrate as core
from rwa_monitor.core.identify.model import plain
from rwa_monitor.core.llr import detect_batch_with_counters
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.pipelines import calibrated
from rwa_monitor.sim.undeclared import simulate_undeclared
from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry

N = 12000


@pytest.fixture(scope='module')
def stribeck_block():
    """Calibrate rw1 on a fault-free record with a Stribeck excess model (1) lacks."""
    tele = simulate_undeclared('stribeck', n=N, seed=1)
    wheel = tele.wheels['rw1']
    return core.calibrate_wheel('rw1', tele.time, wheel.speed, wheel.friction)


def test_nominal_prediction_of_model_1_is_the_project_sign():
    model = {'effects': [], 'weights': {'dry': 5e-4, 'viscous': 2e-6}}
    w = np.array([-20.0, -1.0, 0.0, 3.0])
    assert np.allclose(core.nominal_prediction(model, w), -5e-4 * np.sign(w) - 2e-6 * w)
    with pytest.raises(ConfigError, match='viscous'):
        core.nominal_prediction({'effects': [], 'weights': {'dry': 1.0}}, w)


def test_calibration_of_a_fault_free_wheel(stribeck_block):
    block, warnings = stribeck_block
    assert warnings == []
    assert block['changes_found_s'] == []
    assert block['friction_model']['effects']        # the Stribeck excess was identified
    assert abs(block['noise']['std_nm'] / 5e-5 - 1) < 0.1
    tele = simulate_undeclared('stribeck', n=N, seed=1)
    speed = tele.wheels['rw1'].speed
    assert block['speed_range_rad_s'] == [float(speed.min()), float(speed.max())]


def test_nominal_is_fitted_where_it_is_tested_outside_the_low_speed_band():
    # Noise-free model (1) plus a Stribeck excess near zero: a coarse piecewise-linear
    # nominal fitted on every sample bends to the excess and is biased just outside the
    # band; refitted on |w| >= band it is exact there up to the excess left at the band edge.
    w = 12.0 * np.sin(np.linspace(0.0, 40.0 * np.pi, 20000))
    f = -5e-4 * np.sign(w) - 2e-6 * w - 3e-4 * np.sign(w) * np.exp(-(w / 1.0) ** 2)
    model = {'effects': [{'name': 'smooth_speed', 'kind': 'smooth_speed',
                          'params': {'knots_rad_s': [-12.0, -1.5, 0.0, 1.5, 12.0]}}],
             'weights': {}}
    from rwa_monitor.core.identify.model import regressors_from_config
    x = regressors_from_config(model).matrix(w)
    coef = np.linalg.lstsq(x, f, rcond=None)[0]
    model['weights'] = dict(zip(regressors_from_config(model).names, coef))
    tested = np.abs(w) >= 3.0
    before = np.max(np.abs(core.nominal_prediction(model, w) - f)[tested])
    core.refit_outside_band(model, w, f, 3.0)
    after = np.max(np.abs(core.nominal_prediction(model, w) - f)[tested])
    assert before > 2e-6
    assert after < 1e-7   # the excess itself at |w| = 3: 3e-4 exp(-9) = 4e-8


def test_noise_band_found_where_the_residual_is_larger():
    rng = np.random.default_rng(3)
    speed = np.linspace(-30, 30, 20000)
    residual = 5e-5 * rng.standard_normal(speed.size)
    residual[np.abs(speed) < 2.0] *= 4.0
    noise = core.noise_profile(speed, residual)
    assert noise['low_speed_band']['speed_abs_below_rad_s'] == 2.0
    assert abs(noise['low_speed_band']['std_nm'] / 2e-4 - 1) < 0.15
    plain = core.noise_profile(speed, 5e-5 * rng.standard_normal(speed.size))
    assert plain['low_speed_band']['speed_abs_below_rad_s'] == 0.0


def test_a_change_in_the_calibration_data_is_named_with_wheel_and_time():
    tele = simulate_undeclared('none', n=N, seed=4, anomaly_time=6000.0, anomaly_dry=1e-3)
    wheel = tele.wheels['rw1']
    block, warnings = core.calibrate_wheel('rw1', tele.time, wheel.speed, wheel.friction)
    assert warnings and all(m.startswith('rw1: a friction change (') for m in warnings)
    assert min(abs(t - 6000.0) for t in block['changes_found_s']) < 30.0


def test_calibrated_detector_removes_false_alarms_and_keeps_the_step(stribeck_block):
    block, _ = stribeck_block
    nominal = core.NominalWheel(block)
    healthy = simulate_undeclared('stribeck', n=N, seed=2)
    w = healthy.wheels['rw1']
    raw, _ = detect_batch_with_counters(healthy.time, w.speed, w.friction, component='rw1')
    residual, _ = nominal.residual(healthy.time, w.speed, w.friction)
    cal, _ = detect_batch_with_counters(healthy.time, w.speed, residual, component='rw1')
    assert len(raw) > 5 and cal == []
    faulty = simulate_undeclared('stribeck', n=N, seed=5, anomaly_time=7000.0,
                                 anomaly_dry=3e-4)
    w = faulty.wheels['rw1']
    residual, _ = nominal.residual(faulty.time, w.speed, w.friction)
    found, _ = detect_batch_with_counters(faulty.time, w.speed, residual, component='rw1')
    assert len({e.index for e in found}) == 1
    assert abs(found[0].time - 7000.0) < 30.0 and found[-1].kind == 'dry'


def test_band_and_range_samples_are_not_tested_and_counted():
    block = {'friction_model': {'effects': [], 'weights': {'dry': 1e-3, 'viscous': 0.0}},
             'noise': {'low_speed_band': {'speed_abs_below_rad_s': 1.0}},
             'speed_range_rad_s': [-10.0, 10.0]}
    residual, counts = core.NominalWheel(block).residual(
        np.arange(5.0), np.array([0.5, -2.0, 12.0, np.nan, 3.0]),
        np.array([0.0, 1e-3, 0.0, 0.0, np.nan]))
    assert counts == {'low_speed_band': 1, 'outside_calibrated_range': 1}
    assert np.isnan(residual[[0, 2, 3, 4]]).all() and residual[1] == pytest.approx(0.0)


def test_streaming_residual_is_the_batch_residual_and_the_model(stribeck_block):
    block, _ = stribeck_block
    nominal = core.NominalWheel(block)
    rng = np.random.default_rng(3)
    lo, hi = block['speed_range_rad_s']
    grid = np.concatenate([nominal._tables[1.0][0], -nominal._tables[-1.0][0]])
    on_grid = np.concatenate([grid, np.nextafter(grid, -np.inf), np.nextafter(grid, np.inf)])
    speed = np.concatenate([rng.uniform(lo - 1.0, hi + 1.0, 3000), [0.0, lo, hi, np.nan],
                            on_grid])
    friction = rng.normal(0.0, 1e-4, speed.size)
    time = np.arange(speed.size, dtype=float)
    batch, counts = nominal.residual(time, speed, friction)
    one = [nominal.residual_one(*row) for row in zip(time, speed, friction)]
    assert np.array_equal(batch, np.array([r for r, _ in one]), equal_nan=True)
    assert counts == {reason: sum(why == reason for _, why in one)
                      for reason in ('low_speed_band', 'outside_calibrated_range')}
    tested = np.isfinite(batch)
    exact = friction - core.nominal_prediction(block['friction_model'], speed)
    assert tested.sum() > 2000
    assert np.max(np.abs(batch - exact)[tested]) < 1e-3 * block['noise']['std_nm']
    assert nominal.table_error_nm < 1e-3 * block['noise']['std_nm']


def _document(block):
    return {'calibration': {'version': 1, 'sources': [], 'wheels': {'rw1': block},
                            'gyro': {}}}


def test_malformed_files_name_the_file_and_the_key(tmp_path, stribeck_block):
    block, _ = stribeck_block
    good = plain(_document(block))
    path = tmp_path / 'calibration.yaml'
    path.write_text(yaml.safe_dump(good))
    assert set(calibrated.load(path)['wheels']) == {'rw1'}
    with pytest.raises(ConfigError, match=f'{tmp_path / "missing.yaml"}: cannot read'):
        calibrated.load(tmp_path / 'missing.yaml')
    cases = [({'calibration': {**good['calibration'], 'version': 2}}, 'calibration.version'),
             ({'calibration': {'version': 1}}, 'calibration.wheels'),
             ({'calibration': {**good['calibration'], 'wheels': {'rw1': {
                 k: v for k, v in good['calibration']['wheels']['rw1'].items()
                 if k != 'noise'}}}}, 'calibration.wheels.rw1.noise'),
             ({'calibration': {**good['calibration'], 'wheels': {'rw1': {
                 **good['calibration']['wheels']['rw1'], 'speed_range_rad_s': [3, 1]}}}},
              'calibration.wheels.rw1.speed_range_rad_s')]
    for document, key in cases:
        path.write_text(yaml.safe_dump(document))
        with pytest.raises(ConfigError, match=f'{path}: key {key}'):
            calibrated.load(path)
    path.write_text('calibration: [unclosed')
    with pytest.raises(ConfigError, match='not valid YAML'):
        calibrated.load(path)


def test_other_wheel_names_are_an_error_naming_them(stribeck_block):
    cal = core.check_calibration(_document(stribeck_block[0]))
    with pytest.raises(ConfigError, match=r'no calibration for wheel\(s\) rw7; it '
                                          r'calibrates rw1'):
        core.check_wheels(cal, ['rw1', 'rw7'], 'cal.yaml')


def test_calibrate_then_detect_from_the_command_line(tmp_path, capsys):
    commissioning = simulate_undeclared('stribeck', n=N, seed=11)
    faulty = simulate_undeclared('stribeck', n=N, seed=12, anomaly_time=7000.0,
                                 anomaly_dry=3e-4)
    for name, tele in (('nominal.csv', commissioning), ('faulty.csv', faulty)):
        write_telemetry(tmp_path / name, Telemetry(time=tele.time, wheels=tele.wheels))
    out = tmp_path / 'cal'
    assert main(['calibrate', str(tmp_path / 'nominal.csv'), '-o', str(out)]) == 0
    assert (out / 'report.md').is_file() and (out / 'rw1_friction.png').is_file()
    cal = yaml.safe_load((out / 'calibration.yaml').read_text())['calibration']
    assert cal['version'] == 1 and cal['sources'][0]['samples'] == N
    events = tmp_path / 'events.json'
    assert main(['detect', str(tmp_path / 'faulty.csv'), '--calibration',
                 str(out / 'calibration.yaml'), '-o', str(events)]) in (0, 1)
    document = json.loads(events.read_text())
    llr = [e for e in document['events'] if e['detector'] == 'llr']
    assert len({e['index'] for e in llr}) == 1 and abs(llr[0]['time'] - 7000.0) < 30.0
    summary = document['summary']['pipelines']['llr']['components']['rw1']
    assert 'not_tested' in summary
    other = tmp_path / 'other.csv'
    write_telemetry(other, Telemetry(time=faulty.time, wheels={'rw9': faulty.wheels['rw1']}))
    assert main(['detect', str(other), '--calibration', str(out / 'calibration.yaml')]) == 2
    assert 'rw9' in capsys.readouterr().err


def test_strict_refuses_data_with_a_change(tmp_path, capsys):
    tele = simulate_undeclared('none', n=N, seed=4, anomaly_time=6000.0, anomaly_dry=1e-3)
    write_telemetry(tmp_path / 'bad.csv', Telemetry(time=tele.time, wheels=tele.wheels))
    code = main(['calibrate', str(tmp_path / 'bad.csv'), '-o', str(tmp_path / 'cal'),
                 '--strict'])
    assert code == 2 and 'rw1: a friction change (' in capsys.readouterr().err
    assert not (tmp_path / 'cal' / 'calibration.yaml').exists()


def test_wheel_without_friction_is_not_calibrated():
    tele = Telemetry(time=np.arange(10.0), wheels={'rw1': Wheel(speed=np.ones(10))})
    with pytest.raises(ConfigError, match='no telemetry file'):
        calibrated.commission([])
    document, warnings, _ = calibrated.commission([tele])
    assert document['calibration']['wheels'] == {} and 'rw1: no friction' in warnings[0]


def test_fss_verdict_unknown_when_the_window_is_not_explained():
    from rwa_monitor.core.fss.classify import relative_verdict
    flags = {'dry': True, 'viscous': False}
    from rwa_monitor.core.fss.classify import noise_ratio_bound
    bound = noise_ratio_bound()   # one-sided normal quantile at level 1e-3 of log(ratio)
    assert bound == pytest.approx(np.exp(0.0618 + 3.0902 * 0.0645), rel=1e-4)   # fss1's
    assert noise_ratio_bound({'a': (0.0, 0.02), 'b': (0.01, 0.01)}) == pytest.approx(
        np.exp(3.0902 * 0.02), rel=1e-4)
    status, out, reason = relative_verdict(flags, 1.01 * bound * 1e-4, 1.0e-4)
    assert status == 'unknown' and not any(out.values()) and 'not explained' in reason
    assert relative_verdict(flags, 0.99 * bound * 1e-4, 1.0e-4)[:2] == ('anomalous', flags)
    assert relative_verdict({'dry': False}, 1.0e-4, 1.0e-4)[0] == 'nominal'
    assert relative_verdict(flags, 1.3e-4, 1.0e-4, bound=1.5)[0] == 'anomalous'


def test_fss_diagnosis_relative_to_the_calibrated_nominal(stribeck_block):
    from rwa_monitor.core.fss.pipeline import diagnose, FssConfig
    from rwa_monitor.telemetry.fss_model import load_model
    block, _ = stribeck_block
    model, config = load_model(), FssConfig()
    healthy = simulate_undeclared('stribeck', n=N, seed=7)
    w = healthy.wheels['rw1']
    assert any(diagnose(w.speed, w.friction, healthy.time, model, config)['anomalies'].values())
    result = calibrated.diagnose_wheel(block, healthy.time, w.speed, w.friction, model, config)
    assert result['status'] == 'nominal' and not any(result['anomalies'].values())
    faulty = simulate_undeclared('stribeck', n=N, seed=7, anomaly_time=0.0, anomaly_dry=1.5e-3)
    w = faulty.wheels['rw1']
    result = calibrated.diagnose_wheel(block, faulty.time, w.speed, w.friction, model, config)
    assert result['status'] == 'anomalous' and result['anomalies']['dry']
    noisy = w.friction + 2e-4 * np.random.default_rng(0).standard_normal(N)
    result = calibrated.diagnose_wheel(block, faulty.time, w.speed, noisy, model, config)
    assert result['status'] == 'unknown' and not any(result['anomalies'].values())


def _paper_window(status, size, seed=14):
    """Return (time, speed, friction) SI of a wheel of the FSS paper's Examples 1-2.

    The same seed gives the same speed profile, FSS realisation and noise whatever the
    status: a nominal window and its anomalous twin.
    """
    from rwa_monitor.sim import fss
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
    sig = fss.simulate_wheel(fss.WINDOW_SAMPLES, status, rng, size=size,
                             wheel={'base_dry': 1.0, 'viscous': 1.0, 'noise_std': 0.025})
    speed, friction = fss.to_si(sig['speed'], sig['friction'])
    return np.arange(speed.size) / fss.RATE_HZ, speed, friction


@pytest.fixture(scope='module')
def paper_block():
    """Calibrate a paper-Example wheel on one window, with an extra effect in its nominal.

    The smooth-speed effect is fitted by least squares on that window, as identification
    fits it (it takes the FSS jumps for a function of speed).
    """
    from rwa_monitor.core.identify.model import regressors_from_config
    t, w, f = _paper_window('nominal', None)
    knots = [float(k) for k in np.quantile(w, np.linspace(0.0, 1.0, 12))]
    model = {'effects': [{'name': 'smooth_speed', 'kind': 'smooth_speed',
                          'params': {'knots_rad_s': knots}}]}
    regs = regressors_from_config(model)
    weights = np.linalg.lstsq(regs.matrix(w), f, rcond=None)[0]
    model['weights'] = dict(zip(regs.names, map(float, weights)))
    noise = core.noise_profile(w, f - core.nominal_prediction(model, w))
    noise['low_speed_band']['speed_abs_below_rad_s'] = 0.0
    block = {'friction_model': model, 'noise': noise,
             'speed_range_rad_s': [float(w.min()), float(w.max())]}
    block['fss'] = core.fss_reference(w, f, model, noise)
    return block, (t, w, f)


def test_fss_reference_is_the_extraction_not_the_identified_extras(paper_block):
    from rwa_monitor.core.fss.pipeline import extract, FssConfig, normalise
    block, (t, w, f) = paper_block
    config = FssConfig()
    raw = extract(*normalise(w, f, config), config)
    ref = block['fss']
    # The extras fitted to the FSS jumps move the nominal by a few 1e-5 N m; refitted
    # with the jumps they are noise-sized, and the reference is the extraction's own.
    fitted = np.std(core.nominal_prediction(block['friction_model'], w)
                    - core.nominal_prediction({'effects': [], 'weights': {
                        'dry': ref['model1_dry_nm'], 'viscous': ref['model1_viscous_nms']}}, w))
    assert fitted > 2e-5 > 5 * np.std(core.fss_extra(block, w))
    assert ref['base_dry_nm'] == pytest.approx(raw.base_dry * config.torque_scale_nm, rel=0.02)
    assert ref['viscous_nms'] == pytest.approx(
        raw.viscous * config.torque_scale_nm / config.speed_scale_rad_s, rel=0.01)


def test_fss_reference_of_a_long_record_is_that_of_its_window_long_pieces(paper_block):
    # The calibration window as a record of four diagnosed windows of 20,000 samples: the
    # reference's base dry is the median of the pieces' own references (a model-(1)
    # nominal: nothing refitted, each piece is extracted as it would be alone), their std
    # kept, the viscous coefficient their mean with its standard error. One window: no
    # split.
    block, (t, w, f) = paper_block
    model1 = {'effects': [], 'weights': {'dry': 2.0e-4, 'viscous': 5.0e-7}}
    ref = core.fss_reference(w, f, model1, block['noise'], window_samples=20_000)
    pieces = [core.fss_reference(w[k:k + 20_000], f[k:k + 20_000], model1, block['noise'],
                                 window_samples=20_000)
              for k in range(0, 80_000, 20_000)]
    whole = core.fss_reference(w, f, model1, block['noise'])
    assert ref['base_dry_windows'] == 4 and 'base_dry_windows' not in whole
    bases = [p['base_dry_nm'] for p in pieces]
    assert ref['base_dry_nm'] == pytest.approx(np.median(bases), rel=1e-12)
    assert ref['base_dry_window_std_nm'] == pytest.approx(np.std(bases, ddof=1), rel=1e-12)
    assert ref['viscous_nms'] == pytest.approx(np.mean([p['viscous_nms'] for p in pieces]),
                                               rel=1e-12)
    assert ref['viscous_se_nms'] == pytest.approx(
        np.sqrt(np.sum([p['viscous_se_nms'] ** 2 for p in pieces])) / 4, rel=1e-12)
    assert ref['noise_std_nm'] == whole['noise_std_nm']


def test_fss_reference_drops_refitted_columns_that_take_the_dry_friction(paper_block,
                                                                         monkeypatch):
    # A refit whose extra part holds -3 x the dry friction (as ill-conditioned columns
    # did on a record with few sign changes left outside a wide low-speed band) would
    # leave a negative base dry: the reference is then model (1)'s, and says so.
    from rwa_monitor.core.fss import segments
    block, (t, w, f) = paper_block
    monkeypatch.setattr(segments, 'fit_extra_columns',
                        lambda *a, **k: (np.zeros(a[3].shape[1]), np.array([-6.0e-4, 0.0])))
    ref = core.fss_reference(w, f, block['friction_model'], block['noise'])
    model1 = core.fss_reference(w, f, {'effects': [], 'weights': {'dry': 2.0e-4,
                                                                  'viscous': 5.0e-7}},
                                block['noise'])
    assert ref['extra_refit_dropped'] and 'extra_refit_dropped' not in block['fss']
    assert not any(ref['extra_weights'].values())
    assert ref['base_dry_nm'] == model1['base_dry_nm'] > 0


def test_paper_example_pair_judged_against_a_one_window_calibration(paper_block):
    from rwa_monitor.core.fss.pipeline import FssConfig
    from rwa_monitor.telemetry.fss_model import load_model
    block, (t, w, f) = paper_block
    model, config = load_model(), FssConfig()
    base = block['fss']['base_dry_nm'] / 2.0e-4          # the reference's own estimate

    def judged(status, size):
        res = core.diagnose_fss(block, *_paper_window(status, size), model, config)
        est = res['estimates']
        return (res['status'], {k for k, v in res['anomalies'].items() if v},
                est['base_dry_nm'] / block['fss']['base_dry_nm'],
                est['viscous_nms'] / block['fss']['viscous_nms'])

    status, flags, dry, visc = judged('nominal', None)     # the calibration window itself
    assert (status, flags) == ('nominal', set())
    assert dry == pytest.approx(1.0, abs=0.01) and visc == pytest.approx(1.0, abs=0.01)
    status, flags, dry, visc = judged('viscous', 1.5)
    assert (status, flags) == ('anomalous', {'viscous'}) and visc == pytest.approx(1.5, abs=0.03)
    # Base dry +50 % (the twin window): +0.5 on the reference's estimate, exactly.
    status, flags, dry, visc = judged('dry', 1.5)
    assert dry == pytest.approx((base + 0.5) / base, abs=0.03)
    assert visc == pytest.approx(1.0, abs=0.01)
    assert flags <= {'dry'}
    status, flags, dry, visc = judged('dry', 2.0)
    assert (status, flags) == ('anomalous', {'dry'})


def test_paper_example_window_the_model_cannot_explain_is_unknown(paper_block):
    from rwa_monitor.core.fss.pipeline import FssConfig
    from rwa_monitor.telemetry.fss_model import load_model
    block, _ = paper_block
    t, w, f = _paper_window('nominal', None, seed=15)
    model, config = load_model(), FssConfig()
    assert core.diagnose_fss(block, t, w, f, model, config)['status'] != 'unknown'
    # A torque oscillating every 20 samples, neither model (1) nor an FSS: 1.5 x the
    # noise in amplitude, the residual std grows by sqrt(1 + 1.5^2 / 2) = 1.46.
    wobble = 1.5 * 0.025 * 2.0e-4 * np.sin(2 * np.pi * np.arange(w.size) / 20.0)
    res = core.diagnose_fss(block, t, w, f + wobble, model, config)
    assert res['status'] == 'unknown' and not any(res['anomalies'].values())
    assert 'not explained' in res['unknown_reason']


def test_a_viscous_flag_needs_a_significant_change(paper_block):
    from rwa_monitor.core.fss.classify import viscous_significant, viscous_z
    from rwa_monitor.core.fss.pipeline import FssConfig
    from rwa_monitor.telemetry.fss_model import load_model
    assert viscous_z(1.1, 0.03, 1.0, 0.04) == pytest.approx(2.0)
    assert viscous_z(1.1, 0.03, 1.0, float('nan')) == pytest.approx(0.1 / 0.03)
    assert viscous_significant(3.2) and not viscous_significant(3.0)   # z(1e-3) = 3.09
    assert viscous_significant(float('nan'))
    block, (t, w, f) = paper_block
    model, config = load_model(), FssConfig()
    # A reference 15 % low: the window reads 1.18 x it, above the classifier's x1.14.
    low = {**block, 'fss': {**block['fss'], 'viscous_nms': 0.85 * block['fss']['viscous_nms']}}
    res = core.diagnose_fss(low, t, w, f, model, config)
    assert res['anomalies']['viscous'] and res['calibration']['viscous_z'] > 10
    # The same reference known to +-10 % only: the difference is not significant.
    vague = {**low, 'fss': {**low['fss'], 'viscous_se_nms': 0.1 * low['fss']['viscous_nms']}}
    res = core.diagnose_fss(vague, t, w, f, model, config)
    assert not res['anomalies']['viscous'] and res['viscous_not_significant']
    assert 1.0 < res['calibration']['viscous_z'] < 3.09
