"""The audit's cases of issue 36 (main 91ca172), each failing there, and their causes.

Each case of bench/faults_audit.py runs the real command and raises AssertionError on a
wrong behaviour; the tests below pin the causes in the code that had them.
"""

import json
import math
import pathlib

import numpy as np
import pytest

from bench.faults_audit import BENCH_ONLY, CASES, wide_csv
from rwa_monitor.cli.output import json_text
from rwa_monitor.core.fss.assign import assign_changepoints
from rwa_monitor.core.fss.model import DEFAULT_SYSTEMS
from rwa_monitor.core.fss.pipeline import diagnose, FssConfig, plausible
from rwa_monitor.core.schema import FSS, LLR


UNTIMED = [(n, c) for n, c in CASES if n not in BENCH_ONLY]


@pytest.mark.parametrize('case', [c for _, c in UNTIMED], ids=[n for n, _ in UNTIMED])
def test_fault_case(case, tmp_path):
    outcome = case(tmp_path)
    assert isinstance(outcome, str) and '\n' not in outcome


def test_the_diagnoser_has_the_detectors_plausibility_limits():
    for name in ('max_abs_speed', 'max_abs_friction'):
        assert FSS[name] is LLR[name]           # one definition (core/schema.py)
        assert getattr(FssConfig(), name) == LLR[name].default
    speed = np.array([1.0, 1e5, -1e5 + 1, np.nan, 2.0])
    friction = np.array([1e-4, 1e-4, 1e-4, 1e-4, -1e3])
    w, f, counts = plausible(speed, friction, FssConfig())
    assert counts == {'non_finite': 1, 'out_of_range': 2}
    assert np.isfinite(w).tolist() == [True, False, True, False, False]
    assert np.array_equal(np.isfinite(w), np.isfinite(f))


def test_a_window_with_values_no_wheel_has_is_diagnosed_on_the_rest():
    rng = np.random.default_rng(361)
    t = np.arange(4000) * 0.1
    speed = 200.0 + 150.0 * np.sin(t / 20.0)
    friction = -2e-4 - 5e-7 * speed + rng.normal(0, 5e-5, t.size)
    bad = rng.choice(t.size, 40, replace=False)
    friction[bad] = -1e300
    from rwa_monitor import load_fss_model
    result = diagnose(speed, friction, t, load_fss_model())
    assert result['rejected'] == {'non_finite': 0, 'out_of_range': 40}
    assert 3e-5 < result['estimates']['noise_std_nm'] < 8e-5


def test_the_assignment_refuses_a_non_finite_rejection_cost():
    """An infinite cost dropped every state of a stage: IndexError at assign.py 132."""
    with pytest.raises(ValueError, match='reject_cost must be finite'):
        assign_changepoints(np.array([10, 20]), np.array([1, -1]),
                            np.array([1.0, math.inf]), 100, DEFAULT_SYSTEMS)


def test_json_text_is_strict():
    text = json_text({'a': math.nan, 'b': [math.inf, -math.inf, 1.5], 'c': np.float64('nan')})
    assert json.loads(text) == {'a': None, 'b': [None, None, 1.5], 'c': None}
    for word in ('NaN', 'Infinity'):
        assert word not in text


def test_a_temporary_of_an_ended_process_is_removed_and_others_kept(tmp_path):
    """Temporaries are named after their host and process (telemetry/temporaries.py)."""
    import subprocess
    import sys
    from rwa_monitor.telemetry import temporaries
    target = tmp_path / 'cal'
    ended = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'],
                           capture_output=True, text=True, check=True)
    pid = int(ended.stdout)
    host = temporaries._host()
    mine = temporaries.temporary_prefix(target) + 'abc.tmp'
    names = {'ended': f'.cal.{host}-{pid}-12345.x1.tmp', 'mine': mine,
             'other_host': f'.cal.elsewhere-{pid}-12345.x2.tmp',
             'foreign_content': f'.cal.{host}-{pid}-12345.x3.tmp',
             'not_ours': '.cal.abcdefgh.tmp'}
    for key, name in names.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / ('thesis.tex' if key == 'foreign_content' else 'cal')).mkdir()
    swapped = tmp_path / f'.cal.{host}-{pid}-12345.x4.tmp'    # killed between two renames
    (swapped / '.previous').mkdir(parents=True)
    (swapped / '.previous' / 'calibration.yaml').write_text('previous')
    removed = temporaries.remove_stale(target, ('cal',))
    assert sorted(removed) == sorted([names['ended'], swapped.name])
    assert (target / 'calibration.yaml').read_text() == 'previous'
    left = {p.name for p in tmp_path.iterdir()}
    assert left == {'cal', *(n for k, n in names.items() if k != 'ended')}


def test_an_input_path_problem_is_named_plainly(tmp_path):
    from rwa_monitor.telemetry.atomic import path_problem
    (tmp_path / 'a').symlink_to('b')
    (tmp_path / 'b').symlink_to('a')
    (tmp_path / 'd').symlink_to(tmp_path / 'nowhere.csv')
    (tmp_path / 'f').write_text('')
    assert 'form a loop' in path_problem(tmp_path / 'a')
    assert path_problem(tmp_path / 'd') == (f'a symbolic link to {tmp_path}/nowhere.csv, '
                                            'which does not exist')
    assert 'should be a folder is a file' in path_problem(tmp_path / 'f' / 'x.csv')
    assert path_problem(tmp_path / 'no' / 'x.csv') == (
        f'no such file (its folder {tmp_path}/no does not exist)')


def test_a_wide_file_is_read_whole_and_its_duplicates_found(tmp_path):
    """100,000 columns: every wheel read; a duplicate far along the header named.

    Its time is measured by the bench (``python -m bench faults``: 100,000 columns took
    60 s on main 91ca172, the header check was quadratic).
    """
    from rwa_monitor.exceptions import TelemetrySchemaError
    from rwa_monitor.telemetry import read_telemetry
    path = wide_csv(tmp_path / 'wide.csv', 100_000, rows=3)
    tele = read_telemetry(path)
    assert len(tele.wheels) == 50_000 and len(tele) == 3
    assert tele.wheels['rw49999'].friction.shape == (3,)
    lines = path.read_text().splitlines()
    lines[0] = lines[0] + ',rw7_friction'
    lines[1:] = [line + ',0' for line in lines[1:]]
    path.write_text('\n'.join(lines) + '\n')
    with pytest.raises(TelemetrySchemaError, match="column 'rw7_friction': duplicate column"):
        read_telemetry(path)


def test_detect_prints_a_table_a_person_reads(tmp_path, capsys):
    """Issue 36: the table printed each component as raw JSON with 17-digit floats."""
    import re
    from rwa_monitor.cli.main import main
    path = tmp_path / 'run.csv'
    assert main(['simulate', 'friction', '--wheels', '2', '--seconds', '600', '--anomaly',
                 'rw2:dry:300:+3e-4', '--seed', '36', '-o', str(path)]) == 0
    capsys.readouterr()
    assert main(['detect', str(path)]) == 1
    out = capsys.readouterr().out
    assert '{' not in out and not re.search(r'\d\.\d{8,}', out), out
    assert 'rw2: examined; 6000 samples (6000 usable)' in out
    rows = [line for line in out.splitlines() if ' rw2 ' in line and ' llr ' in line]
    # the p-value column: '< 1e-300' where it underflowed (it printed 0)
    assert rows and all(re.match(r'\s+[\d.]+ rw2\s+llr\s+\w+\s+\d+\s+(< 1e-300|\d\.?\d*e-\d+) ',
                                 line) for line in rows), rows


def test_p_values_and_numbers_as_printed():
    from rwa_monitor.cli.readable import number_text, p_value_text
    assert p_value_text(0.0) == '< 1e-300' and p_value_text(float('nan')) == 'n/a'
    assert p_value_text(None) == 'n/a' and p_value_text(3.2e-9) == '3.2e-09'
    assert number_text(0.00029876543210987) == '0.000299' and number_text(7) == '7'


def test_a_recording_is_written_under_the_topics_given(tmp_path):
    from rwa_monitor.exceptions import ConfigError, TelemetrySchemaError
    from rwa_monitor.sim.aocs import simulate_aocs
    from rwa_monitor.telemetry import read_telemetry, write_telemetry
    tele = simulate_aocs(60.0, seed=1)
    topics = 'gyro=/sc/imu,star_tracker=/sc/st/q'
    write_telemetry(tmp_path / 'flight_bag', tele, topics)
    try:
        plain = read_telemetry(tmp_path / 'flight_bag')    # the default names: not there
    except TelemetrySchemaError as err:
        assert '--topics' in str(err)
    else:
        assert plain.gyro is None and plain.attitude is None
    again = read_telemetry(tmp_path / 'flight_bag', topics)
    assert np.array_equal(again.gyro, tele.gyro)
    with pytest.raises(ConfigError, match='not of another file'):
        write_telemetry(tmp_path / 'x.csv', tele, topics)


def test_a_missing_config_name_is_the_installed_copy(tmp_path, monkeypatch):
    from rwa_monitor import paths
    monkeypatch.chdir(tmp_path)
    found = paths.installed_or_given('config/rwa_monitor.yaml')
    assert found.is_file() and found.is_absolute()
    argv, notes = paths.with_installed_params_files(
        ['llr', '--ros-args', '--params-file', 'config/rwa_monitor.yaml'])
    assert argv[-1] == str(found) and 'installed copy' in notes[0]
    (tmp_path / 'config').mkdir()
    (tmp_path / 'config' / 'rwa_monitor.yaml').write_text('{}\n')
    assert paths.installed_or_given('config/rwa_monitor.yaml') == \
        pathlib.Path('config/rwa_monitor.yaml')            # a file of this folder wins
    assert paths.installed_or_given('mine/rwa_monitor.yaml') == \
        pathlib.Path('mine/rwa_monitor.yaml')
