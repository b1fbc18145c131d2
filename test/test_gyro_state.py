"""The gyro detectors' state records: a run cut anywhere resumes exactly, bad states refused.

A run is cut at a row, the detector's ``state()`` goes through ``records.encode``, JSON
(``allow_nan=False``) and .npz bytes (``allow_pickle=False``) as on disk, is decoded and
restored into a fresh detector built with the same parameters and calibration, which
takes the rest of the rows: the events must equal those of one uninterrupted run, field
for field. The stream (seed 5, 20 minutes at 4 Hz) has a drift that turns into a bias and
clears on x, a bias step that clears on y, and bad rows: a star tracker silent for 5 s
(rows held), non-finite gyro values (one axis, all axes), a non-finite and a repeated
stamp, an invalid quaternion, a saturated and a malformed gyro sample.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math

from hypothesis import event, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from rwa_monitor.core import gyro_calibration as gc, records
from rwa_monitor.core.gyro_diagnosis import GyroDiagnosis
from rwa_monitor.core.gyro_state import GyroDiagnosisState, VsadcState
from rwa_monitor.core.records import RecordError
from rwa_monitor.core.vsadc import VsadcDetector
from rwa_monitor.sim.aocs import AocsConfig, simulate_aocs

QUIET = AocsConfig(st_dropouts_per_hour=0.0)
# Small windows so that the paper's VSADC is ready after 50 s and changes label often
# (24 events on this stream), hold 2 so that labels wait as candidates.
PAPER = dict(window=40, reference_window=80, hold=2)
HELD, NAN_X, NAN_TIME, REPEATED, BAD_Q, NAN_ALL, SATURATED, SHORT = (
    1000, 1500, 1600, 1700, 1800, 2000, 2200, 2300)


def _rows() -> list[tuple]:
    tele = simulate_aocs(1200.0, seed=5, config=QUIET)
    t, g = tele.time, tele.gyro.copy()
    g[:, 0] += np.where((t >= 300) & (t < 700),
                        np.minimum(1e-6 * np.maximum(t - 300, 0), 1.5e-4), 0.0)
    g[:, 1] += np.where((t >= 500) & (t < 900), 5e-5, 0.0)
    rows = [[t[k], g[k].tolist(), tele.attitude[k].tolist(), tele.reference_rate[k].tolist()]
            for k in range(len(t))]
    for k in range(HELD, HELD + 20):
        rows[k][2] = None
    for k in range(NAN_X, NAN_X + 4):
        rows[k][1][0] = math.nan
    rows[NAN_TIME][0] = math.nan
    rows[REPEATED][0] = rows[REPEATED - 1][0]
    rows[BAD_Q][2] = [0.0, 0.0, 0.0, 2.0]
    for k in range(NAN_ALL, NAN_ALL + 4):
        rows[k][1] = [math.nan] * 3
    rows[SATURATED][1][2] = 1.0
    rows[SHORT][1] = rows[SHORT][1][:2]
    return [tuple(r) for r in rows]


@pytest.fixture(scope='module')
def stream():
    """Return the rows ``(t, gyro, q, ref)`` of the module docstring."""
    return _rows()


@pytest.fixture(scope='module')
def calibration():
    """Thresholds calibrated on another healthy record (seed 6, 30 minutes)."""
    tele = simulate_aocs(1800.0, seed=6, config=QUIET)
    return gc.calibrate_gyro(tele.time, tele.gyro, tele.attitude)


@pytest.fixture(scope='module')
def makers(calibration):
    """Detector name -> a function building it fresh."""
    return {'paper': lambda: VsadcDetector(**PAPER), 'residual': GyroDiagnosis,
            'calibrated': lambda: GyroDiagnosis(calibration=calibration)}


RECORDS = {'paper': VsadcState, 'residual': GyroDiagnosisState,
           'calibrated': GyroDiagnosisState}


def _feed(det, rows, start=0, stop=None):
    stop = len(rows) if stop is None else stop
    events = []
    for k in range(start, stop):
        events += det.update(*rows[k], index=k)
    return events


def _fields(events):
    """Every field of every event, non-finite numbers as text (so NaN equals NaN)."""
    return [records.encode(e)[0] for e in events]


@pytest.fixture(scope='module')
def uninterrupted(makers, stream):
    """Detector name -> events of one uninterrupted run over the whole stream."""
    return {name: _feed(make(), stream) for name, make in makers.items()}


def _through_disk(state):
    tree, arrays = records.encode(state)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    with np.load(io.BytesIO(buffer.getvalue()), allow_pickle=False) as npz:
        loaded = {k: npz[k] for k in npz.files}
    return json.loads(json.dumps(tree, allow_nan=False)), loaded


def _resumed(name, makers, rows, cuts):
    det, events, start = makers[name](), [], 0
    for cut in sorted(cuts):
        events += _feed(det, rows, start, cut)
        tree, arrays = _through_disk(det.state())
        det = makers[name]()
        det.restore(records.decode(RECORDS[name], tree, arrays))
        start = cut
    return events + _feed(det, rows, start), det


def test_the_stream_has_what_the_cases_need(uninterrupted):
    kinds = [(e.component, e.kind) for e in uninterrupted['residual']]
    assert kinds == [('gyro_x', 'drift'), ('gyro_y', 'bias'), ('gyro_x', 'bias'),
                     ('gyro_x', 'healthy'), ('gyro_y', 'healthy')]
    assert _fields(uninterrupted['calibrated']) != _fields(uninterrupted['residual'])
    assert {e.kind for e in uninterrupted['paper']} == {'drift', 'bias', 'healthy'}


@pytest.mark.parametrize('name', ['paper', 'residual', 'calibrated'])
@settings(max_examples=20, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_run_cut_anywhere_resumes_exactly(name, data, makers, stream, uninterrupted):
    cuts = data.draw(st.lists(st.integers(0, len(stream)), min_size=1, max_size=3))
    events, det = _resumed(name, makers, stream, cuts)
    assert _fields(events) == _fields(uninterrupted[name])
    assert det.counters == _counters(name, makers, stream)


def _counters(name, makers, stream, cache={}):
    if name not in cache:
        det = makers[name]()
        _feed(det, stream)
        cache[name] = det.counters
    return cache[name]


def _first_row(det, rows, condition, stride=1):
    """Return the first row (a multiple of ``stride``) after which ``condition(state)``."""
    for k in range(len(rows)):
        det.update(*rows[k], index=k)
        if (k + 1) % stride == 0 and condition(det.state()):
            return k + 1
    raise AssertionError('no row of the stream meets the condition')


def _axes(condition):
    return lambda state: any(condition(a) for a in state.axes.values())


CASES = {
    'paper': {
        'before the nominal is learnt': _axes(lambda a: 0 < a.samples < PAPER['window']),
        'before the reference is full': _axes(lambda a: a.samples > 2 * 40 and not a.ready),
        'candidate label pending': _axes(lambda a: a.run > 0),
        'during a drift': _axes(lambda a: a.label == 1),
        'during a bias': _axes(lambda a: a.label == 2),
        'above the quiet level': _axes(lambda a: a.quiet_since is not None),
    },
    'residual': {
        'inside the first block': _axes(lambda a: 0 < a.samples < 40),
        'before the nominal is learnt': _axes(lambda a: 0 < a.blocks_seen < 6),
        'kind decision pending': _axes(lambda a: a.waited > 0),
        'recovery being confirmed': _axes(lambda a: a.pending_run > 0),
        'during a drift': _axes(lambda a: a.label == 1),
        'during a bias': _axes(lambda a: a.label == 2),
        'bias level held': _axes(lambda a: a.level_blocks > 0),
    },
}
CASES['calibrated'] = CASES['residual']
BAD_ROWS = {'rows held': HELD + 10, 'after a non-finite gyro axis': NAN_X + 2,
            'after a non-finite stamp': NAN_TIME + 1, 'after a repeated stamp': REPEATED + 1,
            'after an invalid quaternion': BAD_Q + 1, 'after a row no axis can use': NAN_ALL + 2,
            'after a saturated sample': SATURATED + 1, 'after a short gyro row': SHORT + 1}


@pytest.mark.parametrize('name, case', [(n, c) for n in CASES for c in CASES[n]]
                         + [(n, c) for n in CASES for c in BAD_ROWS])
def test_seeded_cuts_resume_exactly(name, case, makers, stream, uninterrupted):
    if case in BAD_ROWS:
        cut = BAD_ROWS[case]
    else:
        cut = _first_row(makers[name](), stream, CASES[name][case],
                         stride=1 if name == 'paper' else 3)
    events, _ = _resumed(name, makers, stream, [cut])
    assert _fields(events) == _fields(uninterrupted[name])


@pytest.mark.parametrize('name', ['paper', 'residual', 'calibrated'])
def test_restoring_a_state_gives_the_same_state_back(name, makers, stream):
    det = makers[name]()
    _feed(det, stream, 0, 2500)
    tree, arrays = records.encode(det.state())
    fresh = makers[name]()
    fresh.restore(records.decode(RECORDS[name], *_through_disk(det.state())))
    again, again_arrays = records.encode(fresh.state())
    assert json.dumps(again) == json.dumps(tree)
    assert again_arrays.keys() == arrays.keys()
    assert all(np.array_equal(again_arrays[k], arrays[k]) for k in arrays)


def _replace(record, path, **values):
    """Return ``record`` with the nested field at ``path`` (attribute names) replaced."""
    if not path:
        return dataclasses.replace(record, **values)
    head, *rest = path
    if isinstance(record, dict):
        return {**record, head: _replace(record[head], rest, **values)}
    inner = _replace(getattr(record, head), rest, **values)
    return dataclasses.replace(record, **{head: inner})


def _paper_edits(s):
    a = s.axes['z']
    return [
        (_replace(s, ['axes', 'z'], features=a.features[1:]), r'axes\[z\]\.features'),
        (_replace(s, ['axes', 'z'], distances=a.distances[1:]), r'axes\[z\]\.distances'),
        (_replace(s, ['axes', 'z'], run=2), r'axes\[z\]\.run'),
        (_replace(s, ['axes', 'z'], label=3), r'axes\[z\]\.label'),
        (_replace(s, ['axes', 'z'], samples=-1), r'axes\[z\]\.samples'),
        (_replace(s, ['axes', 'z'], healthy_distance_variance=-1.0), 'healthy_distance'),
        (_replace(s, ['axes', 'z', 'reference'], values=a.reference.values[1:]),
         r'axes\[z\]\.reference\.values'),
        (_replace(s, ['axes', 'z', 'reference'], updates=a.reference.updates + 1),
         r'axes\[z\]\.reference_max\.pushed: differs from reference\.updates'),
        (_replace(s, ['axes', 'z', 'reference_max'], positions=a.reference_max.positions - 1),
         r'axes\[z\]\.reference_max\.positions'),
        (_replace(s, ['axes', 'z', 'regime_max'], pushed=a.regime_max.pushed + 1),
         r'axes\[z\]\.regime_max'),
        (_replace(s, ['axes', 'z', 'stamps'], rows=a.stamps.rows[1:]), r'axes\[z\]\.stamps'),
        (_replace(s, ['axes', 'z'], features=np.full_like(a.features, math.nan)),
         r'axes\[z\]\.features'),
        (_replace(s, ['rows'], held=s.rows.held + 1), r'rows\.rows'),
        (_replace(s, ['rows'], bad_axis={'x': 0}), r'rows\.bad_axis'),
        (_replace(s, ['rows', 'star_tracker'], previous=(0.0, 0.0, 0.0, 2.0)),
         r'rows\.star_tracker\.previous'),
        (_replace(s, ['rows'], last_time=math.nan), r'rows\.last_time'),
        (dataclasses.replace(s, axes={'x': s.axes['x'], 'y': s.axes['y']}), r'\.axes'),
        (dataclasses.replace(s, parameters={**s.parameters, 'window': 50}),
         r'parameters\.window: 50 in the state, 40'),
        (dataclasses.replace(s, parameters={**s.parameters, 'adaptive': 1}),
         r'parameters\.adaptive'),
    ]


def _residual_edits(s):
    a = s.axes['z']
    return [
        (_replace(s, ['axes', 'z'], partial_times=a.partial_times[1:]),
         r'axes\[z\]\.partial_times'),
        (_replace(s, ['axes', 'z'], block_means=a.block_means[1:]), r'axes\[z\]\.block_means'),
        (_replace(s, ['axes', 'z'], block_times=a.block_times[:, 1:]),
         r'axes\[z\]\.block_times'),
        (_replace(s, ['axes', 'z', 'block_stamps'], times=a.block_stamps.times[1:]),
         r'axes\[z\]\.block_stamps'),
        (_replace(s, ['axes', 'z'], nominal=math.nan), r'axes\[z\]\.nominal'),
        (_replace(s, ['axes', 'z'], cusum=(-1.0, 0.0)), r'axes\[z\]\.cusum'),
        (_replace(s, ['axes', 'z'], pending=7), r'axes\[z\]\.pending'),
        (_replace(s, ['axes', 'z'], waited=-2), r'axes\[z\]\.waited'),
        (_replace(s, ['axes', 'z'], lag1_correlation=-0.3), r'axes\[z\]\.calibrated'),
        (_replace(s, ['axes', 'z'], calibrated=not a.calibrated), r'axes\[z\]\.calibrated'),
        (_replace(s, ['axes', 'z', 'thresholds'], level=a.thresholds.level * 2),
         r'axes\[z\]\.thresholds'),
        (_replace(s, ['axes', 'z'], threshold_sample_s=0.0), 'threshold_sample_s'),
        (dataclasses.replace(s, saturated={**s.saturated, 'z': -1}), r'saturated\[z\]'),
        (dataclasses.replace(s, saturated_now={'x': False}), 'saturated_now'),
        (dataclasses.replace(s, previous_time=s.previous_time - 1.0), 'previous_time'),
        (dataclasses.replace(s, previous_gyro=None), 'previous_gyro'),
        (dataclasses.replace(s, parameters={**s.parameters, 'block': 20}),
         r'parameters\.block: 20 in the state, 40'),
        (dataclasses.replace(s, last_event=s.axes['z']), 'last_event'),
    ]


@pytest.mark.parametrize('name', ['paper', 'residual', 'calibrated'])
def test_an_inconsistent_state_is_refused_naming_the_field_and_changes_nothing(
        name, makers, stream, uninterrupted):
    source = makers[name]()
    _feed(source, stream, 0, 3000)
    edits = (_paper_edits if name == 'paper' else _residual_edits)(source.state())
    det = makers[name]()
    events = _feed(det, stream, 0, 2400)
    before = records.encode(det.state())[0]
    for bad, field in edits:
        with pytest.raises(RecordError, match=field):
            det.restore(bad)
        assert records.encode(det.state())[0] == before
    events += _feed(det, stream, 2400)
    assert _fields(events) == _fields(uninterrupted[name])


def test_a_state_of_other_parameters_calibration_or_detector_is_refused(makers, stream,
                                                                        calibration):
    def state_of(det):
        _feed(det, stream, 0, 1200)
        return det.state()

    paper, residual = state_of(makers['paper']()), state_of(makers['residual']())
    calibrated = state_of(makers['calibrated']())
    with pytest.raises(RecordError, match=r'parameters\.window: 40 in the state, 50'):
        VsadcDetector(**{**PAPER, 'window': 50}).restore(paper)
    with pytest.raises(RecordError, match=r'parameters\.sigma_window'):
        VsadcDetector(**PAPER, sigma_window=30).restore(paper)
    with pytest.raises(RecordError, match=r'axes: axes \[.x., .y., .z.\] in the state'):
        VsadcDetector(**PAPER, axes=('x', 'y')).restore(paper)
    with pytest.raises(RecordError, match='expected a GyroDiagnosisState, got VsadcState'):
        GyroDiagnosis().restore(paper)
    with pytest.raises(RecordError, match='expected a VsadcState'):
        VsadcDetector(**PAPER).restore(residual)
    with pytest.raises(RecordError, match=r'parameters\.saturation_rad_s'):
        GyroDiagnosis(saturation_rad_s=0.2).restore(residual)
    with pytest.raises(RecordError, match=r'axes\[x\]\.calibrated'):
        GyroDiagnosis().restore(calibrated)
    with pytest.raises(RecordError, match=r'axes\[x\]\.calibrated'):
        GyroDiagnosis(calibration=calibration).restore(residual)
    other = {a: {**c, 'level_threshold_rad_s': 1.5 * c['level_threshold_rad_s']}
             for a, c in calibration.items()}
    with pytest.raises(RecordError, match=r'axes\[x\]\.thresholds'):
        GyroDiagnosis(calibration=other).restore(calibrated)


def test_a_detector_built_from_the_schema_defaults_checks_auto_as_the_window():
    # sigma_window and reference_window 'auto' are saved as the lengths they stand for.
    det = VsadcDetector(window=30, sigma_window='auto', reference_window='auto')
    state = det.state()
    assert state.parameters['sigma_window'] == state.parameters['reference_window'] == 30
    VsadcDetector(window=30, sigma_window=30, reference_window=30).restore(state)


def test_only_time_and_row_stamps_can_be_saved():
    det = VsadcDetector(window=4, reference_window=4)
    det.channels[0].update(0.0, 0.0, stamp='not a stamp')
    with pytest.raises(RecordError, match='only \\(time, row\\) stamps'):
        det.state()


def test_versions_are_class_level():
    for cls in (VsadcState, GyroDiagnosisState):
        assert cls.VERSION == 1
        assert 'VERSION' not in {f.name for f in dataclasses.fields(cls)}


_JSON = st.recursive(st.none() | st.booleans() | st.integers(-3, 10**6)
                     | st.floats(allow_nan=False) | st.text(max_size=4),
                     lambda inner: st.lists(inner, max_size=3)
                     | st.dictionaries(st.text(max_size=4), inner, max_size=3), max_leaves=8)


@pytest.fixture(scope='module')
def saved(makers, stream):
    """Detector name -> (tree, arrays) of its state at row 2400 (a fault under way)."""
    out = {}
    for name in ('paper', 'residual'):
        det = makers[name]()
        _feed(det, stream, 0, 2400)
        out[name] = _through_disk(det.state())
    return out


def _edit_tree(tree, draw):
    node = tree
    while True:
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        if not keys:
            return
        key = draw(st.sampled_from(keys))
        child = node[key]
        if isinstance(child, (dict, list)) and child and draw(st.booleans()):
            node = child
            continue
        node[key] = draw(_like(child) | _JSON)
        return


def _like(value):
    """Values of the same JSON type as ``value`` (the edits a decoder cannot refuse)."""
    if isinstance(value, bool):
        return st.booleans()
    if isinstance(value, int):
        return st.integers(-3, 10**6)
    if isinstance(value, float) or value in ('nan', 'inf', '-inf'):
        return st.floats() | st.sampled_from(['nan', 'inf', '-inf'])
    return st.just(value)


def _edit_arrays(arrays, draw):
    key = draw(st.sampled_from(sorted(arrays)))
    array = arrays[key]
    size = draw(st.integers(0, array.size + 2))
    values = draw(st.lists(st.integers(-5, 5) | st.sampled_from([math.nan, math.inf]),
                           min_size=size, max_size=size))
    if array.dtype.kind == 'i':
        values = [v if isinstance(v, int) else 0 for v in values]
    edited = np.array(values, dtype=array.dtype)
    if array.ndim == 2 and array.shape[1] and size % array.shape[1] == 0:
        edited = edited.reshape(-1, array.shape[1])
    arrays[key] = edited


@pytest.mark.parametrize('name', ['paper', 'residual'])
@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_an_edited_state_is_refused_or_taken_and_never_poisons_the_detector(
        name, data, makers, stream, saved):
    tree, arrays = saved[name]
    tree, arrays = json.loads(json.dumps(tree)), dict(arrays)
    if data.draw(st.booleans()):
        _edit_tree(tree, data.draw)
    else:
        _edit_arrays(arrays, data.draw)
    det = makers[name]()
    _feed(det, stream, 0, 100)
    before = records.encode(det.state())
    try:
        det.restore(records.decode(RECORDS[name], tree, arrays))
    except RecordError:
        event('refused')
        after = records.encode(det.state())
        assert after[0] == before[0]
        assert all(np.array_equal(after[1][k], before[1][k], equal_nan=True)
                   for k in before[1])
        return
    event('taken')
    _feed(det, stream, 2400, 2800)      # taken: the detector keeps working
