"""Outputs never destroy data; detect's exit codes; per-axis rejection (issue 17)."""

import json
import signal
import subprocess
import sys

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.pipelines import vsadc
from rwa_monitor.sim.aocs import named_fault, simulate_aocs
from rwa_monitor.sim.friction import simulate_friction_with_truth
from rwa_monitor.telemetry import write_telemetry


@pytest.fixture(scope='module')
def healthy(tmp_path_factory):
    folder = tmp_path_factory.mktemp('outputs')
    tele, _ = simulate_friction_with_truth(wheels=['rw1'], n_samples=3000, rate_hz=10.0,
                                           seed=21)
    path = folder / 'healthy.csv'
    write_telemetry(path, tele)
    return path


def test_output_naming_the_input_is_refused_and_the_input_kept(healthy, capsys):
    before = healthy.read_bytes()
    assert main(['detect', str(healthy), '-o', str(healthy)]) == 2
    assert 'is an input of this command' in capsys.readouterr().err
    assert main(['diagnose', str(healthy), '-o', str(healthy)]) == 2
    assert healthy.read_bytes() == before


def test_dash_is_standard_output_and_healthy_file_exits_0(healthy, capsys, tmp_path,
                                                          monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(['detect', str(healthy), '-o', '-']) == 0
    document = json.loads(capsys.readouterr().out)
    assert document['events'] == []
    assert document['summary']['detectors'] == {'llr': 'ran',
                                                'vsadc': document['summary']['detectors']
                                                ['vsadc']}
    assert document['summary']['detectors']['vsadc'].startswith('not run: needs gyro')
    assert document['summary']['not_examined'] == {}
    assert not (tmp_path / '-').exists()


def test_failed_write_keeps_the_previous_file_and_prints_one_line(healthy, tmp_path):
    out = tmp_path / 'events.json'
    out.write_text('previous\n')
    code = ('import resource, sys\n'
            'from rwa_monitor.cli.main import main\n'
            'resource.setrlimit(resource.RLIMIT_FSIZE, (512, 512))\n'
            f'sys.exit(main(["detect", {str(healthy)!r}, "-o", {str(out)!r}]))\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120, preexec_fn=lambda: signal.signal(signal.SIGXFSZ,
                                                                          signal.SIG_IGN))
    assert result.returncode == 2, result.stderr
    assert out.read_text() == 'previous\n'
    assert 'Traceback' not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_detect_piped_into_head_exits_quietly(healthy):
    result = subprocess.run(f'{sys.executable} -m rwa_monitor.cli.main detect {healthy} '
                            f'-o - | head -c 10', shell=True, capture_output=True, text=True,
                            timeout=120)
    assert result.stderr == ''


def test_nan_gyro_axis_does_not_blind_the_others(tmp_path):
    """Gyro_x NaN from 300 s; a bias on gyro_y is still found, gyro_x is not 'healthy'."""
    tele = simulate_aocs(1800.0, seed=7, fault=named_fault('bias', 'y', 900.0))
    tele.gyro[tele.time >= 300.0, 0] = np.nan
    events, summary = vsadc.run_with_summary(tele, {})
    assert any(e.component == 'gyro_y' and e.kind in ('bias', 'drift') and e.time >= 890.0
               for e in events)
    assert summary['counters']['bad_axis_x'] > 0 and summary['counters']['bad_gyro'] == 0


def test_axis_that_never_became_ready_is_unknown_and_detect_exits_3(tmp_path):
    tele = simulate_aocs(30.0, seed=3)      # too short to learn the nominal class
    _, summary = vsadc.run_with_summary(tele, {})
    assert {summary[f'gyro_{a}']['final_state'] for a in 'xyz'} == {'unknown'}
    path = tmp_path / 'short.csv'
    write_telemetry(path, tele)
    out = tmp_path / 'events.json'
    assert main(['detect', str(path), '-o', str(out)]) == 3
    not_examined = json.loads(out.read_text())['summary']['not_examined']
    assert set(not_examined) >= {'gyro_x', 'gyro_y', 'gyro_z'}
