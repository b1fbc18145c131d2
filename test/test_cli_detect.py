"""Round trip ``rwa-monitor simulate friction`` -> ``rwa-monitor detect``, and bad input."""

import json

import numpy as np
import pytest

from rwa_monitor.cli.cmd_detect import load_config, node_parameters
from rwa_monitor.cli.main import main
from rwa_monitor.pipelines import llr as llr_pipeline
from rwa_monitor.sim.friction import simulate_friction
from rwa_monitor.telemetry import read_telemetry, write_telemetry

EVENT_FIELDS = {'detector', 'component', 'kind', 'time', 'index', 'declared_time',
                'declared_index', 'p_value', 'revision'}
# r = 1e-7: under no change each p_k is uniform, so by the union bound over the 2 x 12,000
# samples the chance of any false alarm on these files is below 2.4e-3.
STRICT = 'llr_detector:\n  ros__parameters:\n    false_alarm_rate: 1.0e-7\n'


@pytest.fixture(scope='module')
def simulated(tmp_path_factory):
    """Write a 20-minute, 2-wheel file with a +4e-4 N m (8 noise std) dry step on rw2."""
    folder = tmp_path_factory.mktemp('detect')
    path = folder / 'wheels.csv'
    code = main(['simulate', 'friction', '--wheels', '2', '--seconds', '1200', '--rate', '10',
                 '--anomaly', 'rw2:dry:600:+4e-4', '--seed', '1', '-o', str(path)])
    assert code == 0
    config = folder / 'strict.yaml'
    config.write_text(STRICT)
    return folder, path, config


def test_simulate_writes_truth_columns(simulated):
    _, path, _ = simulated
    tele = read_telemetry(path)
    assert list(tele.wheels) == ['rw1', 'rw2']
    assert len(tele) == 12000
    dry = tele.truth['rw2_dry']
    assert np.flatnonzero(np.diff(dry)).tolist() == [5999]
    assert dry[-1] - dry[0] == pytest.approx(4e-4)


def test_detect_round_trip_finds_the_step(simulated):
    folder, path, config = simulated
    out = folder / 'events.json'
    assert main(['detect', str(path), '--config', str(config), '-o', str(out)]) == 1
    document = json.loads(out.read_text())
    assert set(document) == {'events', 'summary'}
    events = document['events']
    for event in events:
        assert EVENT_FIELDS <= set(event)
        assert event['detector'] == 'llr'
        assert event['kind'] in ('dry', 'viscous', 'both', 'undecided')
    assert {e['component'] for e in events} == {'rw2'}
    first = [e for e in events if e['revision'] == 0]
    assert len(first) == 1
    # The estimate must fall within one window (500 samples = 50 s) of the step.
    assert abs(first[0]['time'] - 600.0) <= 50.0
    assert abs(first[0]['index'] - 6000) <= 500
    assert first[0]['declared_index'] > first[0]['index']
    assert 0 <= first[0]['p_value'] <= 1e-7
    summary = document['summary']
    assert summary['samples'] == 12000
    llr = summary['pipelines']['llr']
    assert llr['events'] == len(events)
    assert llr['components']['rw2']['samples'] == 12000
    assert llr['components']['rw1']['events'] == 0
    assert llr['components']['rw2']['changes'] == 1
    assert sum(llr['components']['rw2']['by_kind'].values()) == 1
    assert llr['components']['rw1']['rejected']['non_finite'] == 0


def test_a_parquet_path_is_written_as_parquet_and_detected_alike(simulated, tmp_path):
    """``-o x.parquet`` writes Parquet (it once wrote CSV text the reader refused)."""
    import pyarrow.parquet as pq
    folder, path, config = simulated
    target = tmp_path / 'wheels.parquet'
    write_telemetry(target, read_telemetry(path))
    assert pq.ParquetFile(target).metadata.num_rows == 12000
    assert read_telemetry(target).columns().keys() == read_telemetry(path).columns().keys()
    answers = []
    for source in (path, target):
        out = tmp_path / f'{source.suffix[1:]}.json'
        assert main(['detect', str(source), '--config', str(config), '-o', str(out)]) == 1
        answers.append(json.loads(out.read_text())['events'])
    assert answers[0] == answers[1] and answers[0]


def test_non_finite_samples_are_counted_not_fatal(tmp_path):
    tele = simulate_friction(n_wheels=1, n_samples=3000, seed=4)
    tele.wheels['rw1'].friction[[10, 20, 30]] = np.nan
    tele.wheels['rw1'].speed[40] = np.inf
    path = tmp_path / 'holes.csv'
    write_telemetry(path, tele)
    out = tmp_path / 'events.json'
    assert main(['detect', str(path), '-o', str(out)]) == 0
    rejected = json.loads(out.read_text())['summary']['pipelines']['llr']['components'][
        'rw1']['rejected']
    assert rejected['non_finite'] == 4


def test_detect_prints_a_table_without_output(simulated, capsys):
    _, path, config = simulated
    assert main(['detect', str(path), '--config', str(config)]) == 1  # anomaly found
    text = capsys.readouterr().out
    assert 'rw2' in text and 'llr' in text and '12000 samples' in text


def test_file_without_friction_runs_no_friction_detector(tmp_path):
    tele = simulate_friction(n_wheels=1, n_samples=100)
    tele.wheels['rw1'].friction = None
    path = tmp_path / 'speed_only.csv'
    write_telemetry(path, tele)
    out = tmp_path / 'events.json'
    assert main(['detect', str(path), '-o', str(out)]) == 3  # nothing could be examined
    document = json.loads(out.read_text())
    assert document['events'] == []
    assert 'llr' not in document['summary']['pipelines']


def test_missing_speed_column_is_named(tmp_path, capsys):
    path = tmp_path / 'bad.csv'
    path.write_text('time,rw1_friction\n0,1e-4\n0.1,1e-4\n')
    assert main(['detect', str(path)]) == 2
    err = capsys.readouterr().err
    assert 'rw1_speed' in err and 'bad.csv' in err


def test_missing_time_column_is_named(tmp_path, capsys):
    path = tmp_path / 'notime.csv'
    path.write_text('rw1_speed,rw1_friction\n1,1e-4\n')
    assert main(['detect', str(path)]) == 2
    assert "'time'" in capsys.readouterr().err


def test_missing_file_is_an_error(tmp_path, capsys):
    assert main(['detect', str(tmp_path / 'nothing.csv')]) == 2
    assert 'no such file' in capsys.readouterr().err


@pytest.mark.parametrize('spec', ['rw2:dry:600', 'rw2:bump:600:1e-4', 'rw9:dry:1:1e-4',
                                  'rw1:dry:99999:1e-4'])
def test_bad_anomaly_spec_is_an_error(tmp_path, capsys, spec):
    path = tmp_path / 'x.csv'
    code = main(['simulate', 'friction', '--wheels', '2', '--seconds', '60', '--anomaly',
                 spec, '-o', str(path)])
    assert code == 2
    assert 'error' in capsys.readouterr().err
    assert not path.exists()


@pytest.mark.parametrize('block,name', [('window: 1', 'window'),
                                        ('false_alarm_rate: 2.0', 'false_alarm_rate'),
                                        ('noise_std: -1.0', 'noise_std'),
                                        ('k_verif: -3', 'k_verif')])
def test_bad_config_value_is_named(simulated, tmp_path, capsys, block, name):
    _, path, _ = simulated
    config = tmp_path / 'bad.yaml'
    config.write_text(f'llr_detector:\n  ros__parameters:\n    {block}\n')
    assert main(['detect', str(path), '--config', str(config)]) == 2
    assert name in capsys.readouterr().err


def test_unreadable_config_is_an_error(simulated, tmp_path, capsys):
    _, path, _ = simulated
    config = tmp_path / 'broken.yaml'
    config.write_text('llr_detector: [unclosed\n')
    assert main(['detect', str(path), '--config', str(config)]) == 2
    assert 'YAML' in capsys.readouterr().err


def test_installed_config_has_the_llr_block():
    params = node_parameters(load_config(None), llr_pipeline.NODE)
    kwargs = llr_pipeline.detector_kwargs(params)
    assert {k: kwargs[k] for k in ('window', 'k_verif', 'false_alarm_rate', 'noise_std')} == {
        'window': 500, 'k_verif': 'auto', 'false_alarm_rate': 1e-5, 'noise_std': 'auto'}
