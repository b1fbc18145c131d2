"""Every exported detector through its family's protocol, generically (core/protocol.py).

One table (``FAMILIES``) names each exported detector's family, a small constructor and a
short stream with a change in it; every test below runs on every row of that table, and
the first test fails when a detector is exported without a row.
"""

import inspect
import math

from conftest import REPO
import numpy as np
import pytest

import rwa_monitor
from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.fss.diagnoser import WindowDiagnosis
from rwa_monitor.core.protocol import GyroDetector, StreamingDetector, WheelDetector, \
    WindowDiagnoser
from rwa_monitor.telemetry import read_telemetry

GOLDEN = REPO / 'test' / 'data' / 'golden'
PROTOCOLS = (StreamingDetector, WheelDetector, GyroDetector, WindowDiagnoser)


def _wheel_stream():
    rng = np.random.default_rng(3)
    t = np.arange(2000) * 0.1
    speed = 200.0 + 150.0 * np.sin(t / 20.0)
    friction = -(2e-4 + 4e-4 * (t >= 100.0)) - 5e-7 * speed + rng.normal(0, 5e-5, t.size)
    return [(t[k], speed[k], friction[k]) for k in range(t.size)]


def _gyro_stream():
    tele = read_telemetry(GOLDEN / 'aocs_bias.csv')
    return [(tele.time[k], tele.gyro[k], tele.attitude[k], tele.reference_rate[k])
            for k in range(len(tele))]


def _fss():
    return rwa_monitor.FssDiagnoser(rwa_monitor.load_fss_model(), window_length=300,
                                    window_period=100)


# name -> (family protocol, constructor, stream, finding type)
FAMILIES = {
    'LLRDetector': (WheelDetector, lambda: rwa_monitor.LLRDetector('rw1', window=50),
                    _wheel_stream, AnomalyEvent),
    'VsadcDetector': (GyroDetector, lambda: rwa_monitor.VsadcDetector(
        window=40, sigma_window=40, reference_window=200), _gyro_stream, AnomalyEvent),
    'GyroDiagnosis': (GyroDetector, lambda: rwa_monitor.GyroDiagnosis(), _gyro_stream,
                      AnomalyEvent),
    'FssDiagnoser': (WindowDiagnoser, _fss, lambda: _wheel_stream()[:400], WindowDiagnosis),
}
# Bad rows of each family: a non-finite stamp, then a stamp equal to the last accepted one.
BAD_ROWS = {
    WheelDetector: lambda t: [(math.nan, 1.0, 0.0), (t, 1.0, 0.0)],
    GyroDetector: lambda t: [(math.nan, [0.0] * 3, [0.0, 0.0, 0.0, 1.0], [0.0] * 3),
                             (t, [0.0] * 3, [0.0, 0.0, 0.0, 1.0], [0.0] * 3)],
    WindowDiagnoser: lambda t: [(math.nan, 1.0, 0.0), (t, 1.0, 0.0)],
}


def _case(name, part):
    return pytest.param(name, id=name)


def cases(part):
    return [_case(name, part) for name in FAMILIES]


def _findings(det, rows):
    out = []
    for row in rows:
        found = det.update(*row)
        out += found if isinstance(found, list) else [found] if found is not None else []
    return out


def _stable(finding):
    """Return a finding without its wall-clock timings (a window diagnosis has some)."""
    if isinstance(finding, WindowDiagnosis):
        return finding._replace(result={k: v for k, v in finding.result.items()
                                        if k != 'timings_s'})
    return finding


def test_every_exported_detector_has_a_family():
    exported = {name for name in rwa_monitor.__all__
                if inspect.isclass(obj := getattr(rwa_monitor, name))
                and obj not in PROTOCOLS and hasattr(obj, 'update') and hasattr(obj, 'reset')}
    assert exported == set(FAMILIES)


@pytest.mark.parametrize('name', cases('signature'))
def test_update_has_the_family_signature(name):
    family, make, _, _ = FAMILIES[name]
    det = make()
    assert isinstance(det, family) and isinstance(det, StreamingDetector)
    got = inspect.signature(type(det).update).parameters
    want = inspect.signature(family.update).parameters
    assert [(p.name, p.kind, p.default, p.annotation) for p in got.values()] == \
        [(p.name, p.kind, p.default, p.annotation) for p in want.values()]


@pytest.mark.parametrize('name', cases('read_only'))
def test_last_event_counters_params_are_read_only_properties(name):
    det = FAMILIES[name][1]()
    for attribute in ('last_event', 'counters', 'params'):
        prop = inspect.getattr_static(type(det), attribute)
        assert isinstance(prop, property) and prop.fset is None
        with pytest.raises(AttributeError):
            setattr(det, attribute, None)


@pytest.mark.parametrize('name', cases('params_only'))
def test_params_only(name):
    det = FAMILIES[name][1]()
    assert not hasattr(det, 'parameters')
    params = det.params
    assert isinstance(params, dict) and params
    params.clear()
    assert det.params, 'params must return a copy'


@pytest.mark.parametrize('name', cases('stream'))
def test_a_change_is_found_kept_as_last_event_and_forgotten_by_reset(name):
    _, make, stream, finding = FAMILIES[name]
    det = make()
    assert det.last_event is None
    found = _findings(det, stream())
    assert found and all(isinstance(f, finding) for f in found)
    assert det.last_event == found[-1]
    det.reset()
    assert det.last_event is None
    assert all(v == 0 for v in det.counters.values())
    again = _findings(det, stream())
    assert list(map(_stable, again)) == list(map(_stable, found)), 'reset must restore all'


@pytest.mark.parametrize('name', cases('bad_input'))
def test_bad_input_is_counted_by_the_shared_names(name):
    family, make, stream, _ = FAMILIES[name]
    det = make()
    rows = stream()[:5]
    clean = _findings(det, rows)
    before = det.counters
    assert before[keys.NON_FINITE] == before[keys.NON_INCREASING_TIME] == 0
    assert _findings(det, BAD_ROWS[family](rows[-1][0])) == []
    after = det.counters
    assert after[keys.NON_FINITE] == 1 and after[keys.NON_INCREASING_TIME] == 1
    assert {k: v for k, v in after.items() if v != before[k]} == {
        keys.NON_FINITE: 1, keys.NON_INCREASING_TIME: 1,
        **({'rows': before['rows'] + 2} if 'rows' in after else {})}
    assert clean == []
