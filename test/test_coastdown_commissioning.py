"""Commissioning on real drum coast-downs, and healthy coasts after it (issue 35 item 3).

The data are ../shared/data/measured/drum-coastdown, read in place (bench
coastdown_kinds builds the records; docs/results.md has the kinds of the joins).
"""

import pytest

from bench import bench_coastdown_kinds as kinds

pytestmark = pytest.mark.skipif(not kinds.MEASURED.exists(),
                                reason='measured coast-down folder absent')


@pytest.fixture(scope='module')
def coasts():
    return kinds.coasts(quick=False)


def test_one_coast_is_refused_two_are_accepted(coasts, tmp_path):
    one = kinds.calibrate(list(kinds.COMMISSIONING[:1]), coasts, tmp_path)
    assert one['exit'] == 2
    assert 'commission with more data' in one['message']
    two = kinds.calibrate(list(kinds.COMMISSIONING), coasts, tmp_path)
    assert two['exit'] == 0
    (low, high), = two['tested_speeds_rad_s']
    assert low < 5.0 and high > 30.0
    assert two['tested_samples'] > 0.8 * two['samples']


def test_healthy_coasts_raise_no_declaration_after_commissioning(coasts, tmp_path):
    calibration = kinds.calibrate(list(kinds.COMMISSIONING), coasts, tmp_path)['path']
    others = [run for run in coasts if run not in kinds.COMMISSIONING]
    assert len(others) >= 30
    for i, run in enumerate(others):
        c = coasts[run]
        csv = tmp_path / f'single_{i}.csv'
        kinds.write_record(csv, [(c['time'], c['speed'], c['friction'])])
        doc = kinds.detect(csv, kinds.pathlib.Path(calibration))
        drum = doc['summary']['pipelines']['llr']['components']['drum']
        assert drum['verdict'] == 'examined', run
        assert not [e for e in doc['events'] if e.get('detector') == 'llr'], run
