"""The soak's rules, without ROS: rate steering, backlog estimate and the verdict.

The full soak (``python -m bench soak``) runs for 10 minutes; these check that its result
can never pass on empty checks and that the rate it steers to follows the backlogs.
"""

import copy

from bench.bench_soak import Incarnation, next_rate, run_settings, verdict


def test_rate_goes_down_on_a_backlog_and_up_when_all_keep_up():
    assert next_rate(10.0, {'llr': 0.0, 'vsadc': 500.0}, 300.0, 100.0) == 6.0
    assert next_rate(10.0, {'llr': 0.0, 'vsadc': 50.0}, 300.0, 100.0) == 12.5
    assert next_rate(10.0, {'llr': 0.0, 'vsadc': 200.0}, 300.0, 100.0) == 10.0
    assert next_rate(90.0, {}, 300.0, 100.0) == 100.0
    assert next_rate(0.6, {'llr': 1e6}, 300.0, 100.0) == 0.5


def test_backlog_counts_from_the_first_status_and_the_extra_messages():
    inc = Incarnation()
    assert inc.backlog(5000.0) == 0.0           # no status yet
    inc.update(published=1000.0, received=10.0, now=0.0)
    inc.update(published=1500.0, received=400.0, now=1.0)
    assert inc.backlog(1500.0) == 110.0         # 500 published since, 390 received
    inc.sent_extra = 200.0
    assert inc.backlog(1500.0) == 310.0


def test_backlog_ignores_a_constant_offset_and_sees_a_growing_lag():
    inc = Incarnation(window_s=30.0)
    inc.update(published=1000.0, received=10.0, now=0.0)
    inc.update(published=1100.0, received=210.0, now=1.0)  # the first pair was stale
    inc.update(published=1500.0, received=610.0, now=2.0)
    assert inc.backlog(1500.0) == 0.0
    inc.update(published=2000.0, received=810.0, now=3.0)
    assert inc.backlog(2000.0) == 300.0                    # fell 300 rows behind
    # Rows that never reached the process (before discovery matched it): a constant
    # offset, forgotten after the window.
    for k in range(40):
        inc.update(published=2000.0 + 100 * k, received=810.0 + 100 * k, now=4.0 + k)
    assert inc.backlog(5900.0) == 0.0


def _passing():
    return {'settings': run_settings(False), 'passes_completed': 5,
            'expected_anomalies': [['llr', 'rw2', 'undecided', 2250]], 'expected_missed': [],
            'anomalies_lost': 0, 'crashes': [],
            'kills': {k: {'killed_at_s': 100.0, 'latched_before_kill': 2,
                          'republished_after_restart': 2} for k in ('llr', 'vsadc', 'fss')}}


def test_verdict_passes_only_on_checks_that_ran():
    assert verdict(_passing()) == []
    cases = {'passes_completed': 1, 'expected_anomalies': [],
             'expected_missed': [['llr', 'rw2', 'undecided', 2250]], 'anomalies_lost': 1,
             'crashes': ['llr exited by itself with -11']}
    for field, value in cases.items():
        r = copy.deepcopy(_passing())
        r[field] = value
        assert verdict(r), field
    r = copy.deepcopy(_passing())
    r['kills']['vsadc']['republished_after_restart'] = 1
    assert verdict(r)
    r = copy.deepcopy(_passing())
    del r['kills']['fss']['killed_at_s']
    assert verdict(r)
