"""Configuration and calibration values (issue 24, item 4): bounded YAML, finite values.

On main 09648a8 an alias bomb was expanded by whatever walked the document (3 GB and a
minute for ``--config`` with a 9-level bomb; the bombs here are small enough to be
harmless there, large enough to be refused here), a calibration edited to ``.nan`` loaded
and blinded its wheel, and a friction column of 1e300 was a traceback in calibrate.
"""

import math

import pytest
import yaml

from rwa_monitor.cli.main import main
from rwa_monitor.exceptions import ConfigError, TelemetrySchemaError
from rwa_monitor.pipelines import calibrated
from rwa_monitor.sim.undeclared import simulate_undeclared
from rwa_monitor.telemetry import read_telemetry, write_telemetry
from rwa_monitor.telemetry.calibration_file import load
from rwa_monitor.telemetry.parameters_file import read_parameters_file


def bomb(levels: int, width: int = 10) -> str:
    """Return a YAML document of ``width ** levels`` values once its aliases expand."""
    lines = ['a0: &a0 [x]']
    for k in range(1, levels + 1):
        lines.append(f'a{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * width) + ']')
    return '\n'.join(lines) + '\n'


def test_an_alias_bomb_is_refused_without_being_expanded(tmp_path):
    path = tmp_path / 'params.yaml'
    path.write_text(bomb(6) + 'llr_detector:\n  ros__parameters:\n    window: *a6\n')
    with pytest.raises(ConfigError, match='aliases expand to more than'):
        read_parameters_file(path)
    path.write_text(bomb(30))   # 1e30 values: counted on the 31 composed nodes
    with pytest.raises(ConfigError, match='aliases expand to more than'):
        read_parameters_file(path)


def test_modest_aliases_still_load(tmp_path):
    path = tmp_path / 'params.yaml'
    path.write_text('/**:\n  ros__parameters: &shared\n    use_sim_time: true\n'
                    'llr_detector:\n  ros__parameters: *shared\n')
    assert read_parameters_file(path)['llr_detector']['ros__parameters'] == {
        'use_sim_time': True}


@pytest.mark.parametrize('text', ['a: &a [*a]\n', '[' * 5000 + ']' * 5000 + '\n'])
def test_a_recursive_or_absurdly_deep_document_is_refused(tmp_path, text):
    path = tmp_path / 'params.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError, match='refused'):
        read_parameters_file(path)


def test_detect_config_bomb_exits_2_with_one_line(tmp_path, capsys):
    data = tmp_path / 'in.csv'
    data.write_text('time,rw1_speed,rw1_friction\n0,1,0\n1,2,0\n')
    config = tmp_path / 'bomb.yaml'
    config.write_text(bomb(7) + 'llr_detector:\n  ros__parameters:\n    window: *a7\n')
    assert main(['detect', str(data), '--config', str(config)]) == 2
    err = capsys.readouterr().err
    assert 'aliases expand' in err and len(err.splitlines()) == 1


@pytest.fixture(scope='module')
def calibration(tmp_path_factory):
    out = tmp_path_factory.mktemp('cal')
    tele = simulate_undeclared('stribeck', n=4000, seed=1)
    document, _, arrays = calibrated.commission([tele])
    calibrated.write(document, arrays, out / 'cal')
    return out / 'cal' / 'calibration.yaml'


@pytest.mark.parametrize('key, value', [
    (('noise', 'std_nm'), math.nan), (('noise', 'std_nm'), 0.0),
    (('noise', 'std_nm'), -1e-5), (('noise', 'low_speed_band', 'speed_abs_below_rad_s'),
                                   math.inf),
    (('noise', 'low_speed_band', 'std_nm'), math.nan),
    (('friction_model', 'weights', 'dry'), math.nan),
    (('fss', 'noise_std_nm'), math.nan), (('speed_range_rad_s', 1), math.inf)])
def test_a_calibration_value_that_is_not_finite_or_in_range_is_refused(
        tmp_path, calibration, key, value):
    document = yaml.safe_load(calibration.read_text())
    node = document['calibration']['wheels']['rw1']
    for part in key[:-1]:
        node = node[part]
    node[key[-1]] = value
    edited = tmp_path / 'calibration.yaml'
    edited.write_text(yaml.safe_dump(document))
    with pytest.raises(ConfigError) as err:
        load(edited)
    assert str(key[-1]) in str(err.value) and 'calibration.wheels.rw1' in str(err.value)


def test_detect_with_a_nan_calibration_exits_2(tmp_path, calibration, capsys):
    document = yaml.safe_load(calibration.read_text())
    document['calibration']['wheels']['rw1']['noise']['std_nm'] = math.nan
    edited = tmp_path / 'calibration.yaml'
    edited.write_text(yaml.safe_dump(document))
    data = tmp_path / 'in.csv'
    write_telemetry(data, simulate_undeclared('stribeck', n=2000, seed=3))
    assert main(['detect', str(data), '--calibration', str(edited)]) == 2
    assert 'noise.std_nm' in capsys.readouterr().err


def test_a_friction_model_with_a_nan_weight_is_refused(tmp_path):
    from rwa_monitor.pipelines.llr import friction_model
    path = tmp_path / 'friction_model.yaml'
    path.write_text('friction_model:\n  effects: []\n  weights: {dry: .nan, viscous: 1.0}\n')
    tele = simulate_undeclared('stribeck', n=100, seed=1)
    with pytest.raises(ConfigError, match='weights.dry'):
        friction_model(str(path), tele)


@pytest.mark.parametrize('scale', [1e300, 1e200, 1e10])
def test_calibrate_refuses_implausible_friction_naming_the_column(tmp_path, scale, capsys):
    tele = simulate_undeclared('stribeck', n=3000, seed=1)
    tele.wheels['rw1'].friction = tele.wheels['rw1'].friction * scale
    write_telemetry(tmp_path / 'in.csv', tele)
    assert main(['calibrate', str(tmp_path / 'in.csv'), '-o', str(tmp_path / 'cal')]) == 2
    assert 'rw1_friction' in capsys.readouterr().err
    assert not (tmp_path / 'cal').exists()


def test_calibrate_refuses_to_write_a_non_finite_value():
    document = {'calibration': {'wheels': {'rw1': {'noise': {'std_nm': math.inf}}}}}
    with pytest.raises(ConfigError, match='std_nm'):
        calibrated.write(document, {}, None)


def test_a_recording_whose_metadata_is_an_alias_bomb_is_refused(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text(bomb(7))
    with pytest.raises(TelemetrySchemaError, match='aliases expand'):
        read_telemetry(bag)
