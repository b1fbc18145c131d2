"""Honest verdicts (issue 24): "not examined" is never "healthy"; errors exit 2, one line.

Each fault case of bench/faults_verdicts.py runs the real CLI and raises AssertionError
on a wrong behaviour; every one but ``package_error`` (a guard) failed on 09648a8.
"""

import types

import pytest

from bench.faults_verdicts import CASES
from rwa_monitor.cli.cmd_dashboard import unexamined_note
from rwa_monitor.core.coverage import judge, llr_samples_needed, MOSTLY_UNTESTED_SHARE
from rwa_monitor.core.gyro_runner import axis_coverage
from rwa_monitor.core.schema import LLR


@pytest.mark.parametrize('case', [c for _, c in CASES], ids=[n for n, _ in CASES])
def test_fault_case(case, tmp_path):
    outcome = case(tmp_path)
    assert isinstance(outcome, str) and '\n' not in outcome


def test_judge_boundaries():
    assert MOSTLY_UNTESTED_SHARE == 0.5
    assert judge(1000, 99, 100).verdict == 'not_examined'
    assert judge(1000, 100, 100).verdict == 'unknown'        # 900 of 1000 untested
    assert judge(1000, 500, 100).verdict == 'examined'       # exactly half: stands
    assert judge(1000, 499, 100).verdict == 'unknown'
    assert judge(0, 0, 0).verdict == 'not_examined'          # nothing is never examined
    fields = judge(1000, 499, 100, 'the LLR test').fields()
    assert fields['usable_samples'] == 499 and fields['samples'] == 1000
    assert '501 of 1000' in fields['verdict_reason']


def test_llr_needs_its_reference_and_window():
    assert llr_samples_needed(LLR.defaults()) == 2 * LLR['window'].default + 1
    assert llr_samples_needed({'window': 200, 'noise_fit_samples': 5000}) == 5000


def test_axis_never_ready_is_not_examined_whatever_its_count():
    channel = types.SimpleNamespace(samples=900, ready=False, block=100, nominal_blocks=3)
    verdict = axis_coverage(1000, channel)
    assert verdict.verdict == 'not_examined' and 'never ready' in verdict.reason
    channel.ready = True
    assert axis_coverage(1000, channel).verdict == 'examined'


def test_dashboard_shows_unknown_with_counts():
    fields = judge(9600, 1199, 240).fields()
    assert unexamined_note(fields) == 'unknown: 1199 of 9600 samples usable'
    assert unexamined_note(judge(9600, 9600, 240).fields()) is None
    assert unexamined_note({'kind': 'bias'}) is None


def test_dashboard_row_of_a_mostly_rejected_axis_reads_unknown():
    from rwa_monitor.cli.cmd_dashboard import Board, render
    board = Board(clock=lambda: 0.0)
    board.health[('vsadc_detector: gyro_y', 'gyro_y')] = {
        'level': 0, 'message': 'ok', 'received': 0.0, 'namespace': '/',
        'fields': {'kind': 'healthy', **judge(9600, 1199, 240).fields()}}
    row = [line for line in render(board).splitlines() if line.startswith('gyro_y')][0]
    assert 'unknown' in row and 'healthy' not in row and '1199 of 9600' in row


def test_window_with_no_tested_sample_keeps_the_keys_a_node_reads():
    import numpy as np

    from rwa_monitor.core.fss.pipeline import diagnose
    from rwa_monitor.telemetry.fss_model import load_model
    nan = np.full(1000, np.nan)
    result = diagnose(nan, nan, np.arange(1000.0), load_model(None))
    assert result['status'] == 'unknown' and not any(result['anomalies'].values())
    assert set(result['estimates']) >= {'base_dry_nm', 'viscous_nms', 'noise_std_nm'}
    assert result['coverage']['usable_samples'] == 0


def test_star_tracker_invalid_for_most_of_a_record_leaves_every_axis_unknown():
    import numpy as np

    from rwa_monitor.pipelines import vsadc
    from rwa_monitor.sim.aocs import simulate_aocs
    tele = simulate_aocs(2400.0, seed=7)
    tele.attitude[tele.time >= 600.0] = np.nan          # 75 % of the rows
    _, summary = vsadc.run_with_summary(tele, {})
    for axis in 'xyz':
        entry = summary[f'gyro_{axis}']
        assert entry['verdict'] == 'unknown' and entry['final_state'] == 'unknown', entry
        assert entry['samples'] == len(tele) - 1 and entry['usable_samples'] < len(tele) / 2
