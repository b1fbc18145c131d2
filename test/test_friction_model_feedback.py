"""A model refined by `identify` and fed to `detect` removes the undeclared effect's alarms.

The true anomaly in the same file is still found.
"""

import json

import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.pipelines import llr
from rwa_monitor.sim.undeclared import simulate_undeclared
from rwa_monitor.telemetry import write_telemetry

STEP_TIME, STEP, WINDOW, RATE = 6000.0, 3.0e-4, 500, 1.0e-4


def _events(path, config, out, *extra):
    code = main(['detect', str(path), '--config', str(config), '-o', str(out), *extra])
    events = [e for e in json.loads(out.read_text())['events'] if e['revision'] == 0]
    assert code == (1 if events else 0)   # docs/usage.md: 1 = anomaly found
    return events


@pytest.mark.slow
def test_refined_model_removes_false_alarms_and_keeps_the_anomaly(tmp_path):
    train, test = tmp_path / 'train.csv', tmp_path / 'test.csv'
    write_telemetry(train, simulate_undeclared('drag', n=10000, seed=100))
    write_telemetry(test, simulate_undeclared('drag', n=10000, seed=201,
                                              anomaly_time=STEP_TIME, anomaly_dry=STEP))
    config = tmp_path / 'params.yaml'
    config.write_text('llr_detector:\n  ros__parameters:\n'
                      f'    window: {WINDOW}\n    false_alarm_rate: {RATE:.1e}\n')
    assert main(['identify', str(train), '-o', str(tmp_path / 'id')]) == 0
    model = tmp_path / 'id' / 'friction_model.yaml'

    baseline = _events(test, config, tmp_path / 'base.json')
    refined = _events(test, config, tmp_path / 'refined.json', '--friction-model', str(model))

    def false_alarms(events):
        return [e for e in events if abs(e['time'] - STEP_TIME) > WINDOW]

    # With the right model, Fig. 5 of the llr-realtime paper bounds the expected number of
    # false alarms in n samples by n * r = 1; the undeclared drag makes model (1) wrong, so
    # the baseline must alarm more often than that.
    assert len(false_alarms(refined)) <= 1 < len(false_alarms(baseline))
    found = [e for e in refined if abs(e['time'] - STEP_TIME) <= WINDOW]
    assert len(found) == 1 and found[0]['kind'] == 'dry' and found[0]['delta_dry_nm'] > 0


def test_a_model_that_reads_a_missing_channel_is_refused(tmp_path):
    model = tmp_path / 'm.yaml'
    model.write_text('friction_model:\n  effects:\n  - name: aux:rw1_current:dry\n'
                     '    kind: aux\n'
                     '    params: {column: rw1_current, component: dry, center: 0.0}\n')
    tele = simulate_undeclared('none', n=100)
    with pytest.raises(ConfigError, match='rw1_current'):
        llr.friction_model(str(model), tele)
    with pytest.raises(ConfigError, match='cannot read'):
        llr.friction_model(str(tmp_path / 'absent.yaml'), tele)
