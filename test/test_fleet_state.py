"""The fleet's detector state codec: saved mid-stream, restored, continued == uninterrupted.

Cuts fall in the noise-model fit (samples buffered), before and after a declaration and
in the revision period of the LLR detector, and in the gyro diagnosis before and after
its nominal class is learnt and after a fault. The tree goes through JSON and the arrays
through .npz bytes, as on disk.
"""

import io
import json

import numpy as np
import pytest

from rwa_monitor.core.llr import LLRDetector
from rwa_monitor.core.schema import LLR, llr_kwargs, VSADC
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet import codec, state
from rwa_monitor.pipelines import vsadc
from rwa_monitor.sim.aocs import add_gyro_channels, named_fault
from rwa_monitor.sim.friction import parse_anomaly, simulate_friction


def _through_disk(detector):
    tree, arrays = codec.encode(detector)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    with np.load(io.BytesIO(buffer.getvalue()), allow_pickle=False) as npz:
        loaded = {k: npz[k] for k in npz.files}
    return json.loads(json.dumps(tree)), loaded


def _views(detector):
    """Return the pairs of array attributes of ``detector`` that share memory."""
    arrays = {k: v for k, v in vars(detector).items() if isinstance(v, np.ndarray)}
    return {(a, b) for a in arrays for b in arrays
            if a < b and np.shares_memory(arrays[a], arrays[b])}


@pytest.fixture(scope='module')
def wheel_rows():
    tele = simulate_friction(duration_s=3000, rate_hz=10, wheels=('rw2',), seed=3,
                             anomalies=[parse_anomaly('rw2:dry:1200:3e-4')])
    w = tele.wheels['rw2']
    return list(zip(tele.time.tolist(), w.speed.tolist(), w.friction.tolist()))


@pytest.mark.parametrize('cut', [1, 150, 11000, 12400, 13500, 20000])
def test_llr_state_round_trip_continues_identically(wheel_rows, cut):
    kwargs = llr_kwargs(LLR.validate({}))
    whole = LLRDetector('rw2', **kwargs)
    expected = [e for row in wheel_rows for e in whole.update(*row)]
    assert len(expected) >= 2          # a declaration and at least one revision
    first = LLRDetector('rw2', **kwargs)
    found = [e for row in wheel_rows[:cut] for e in first.update(*row)]
    second = LLRDetector('rw2', **kwargs)
    codec.restore(second, *_through_disk(first))
    found += [e for row in wheel_rows[cut:] for e in second.update(*row)]
    assert found == expected
    assert second.counters == whole.counters
    # Attributes that are views of one state array stay views after the restore.
    assert _views(second) == _views(LLRDetector('rw2', **kwargs))


@pytest.mark.parametrize('cut', [300, 4000, 9000])
def test_gyro_state_round_trip_continues_identically(cut):
    tele = simulate_friction(duration_s=1200, rate_hz=10, wheels=('rw1',), seed=4)
    tele = add_gyro_channels(tele, fault=named_fault('fast', 0, 600.0), seed=5)
    params = VSADC.validate({})
    expected = vsadc.label_series(tele, params).events
    assert expected
    rows = list(zip(tele.time.tolist(), tele.gyro.tolist(), tele.attitude.tolist(),
                    tele.reference_rate.tolist()))
    first = vsadc.make_detector(params)
    found = [e for i, r in enumerate(rows[:cut]) for e in first.update(*r, i)]
    second = vsadc.make_detector(params)
    codec.restore(second, *_through_disk(first))
    found += [e for i, r in enumerate(rows[cut:], cut) for e in second.update(*r, i)]
    # As JSON: a detail may be NaN, which never equals itself.
    assert [e.to_json() for e in found] == [e.to_json() for e in expected]


def test_unknown_class_is_refused():
    class Opaque:
        pass

    with pytest.raises(codec.StateError, match='allowlist'):
        codec.encode({'x': Opaque()})
    with pytest.raises(codec.StateError, match='allowlist'):
        codec.restore(None, {'$object': 'os.system', 'attrs': {}}, {})


def test_plain_values_round_trip():
    value = {'a': (1, 2.5, float('inf'), None), 3: [np.float64(0.5), np.int64(7)],
             'b': {1, 2}, 'c': float('nan')}
    tree, arrays = codec.encode(value)
    back = codec.restore(None, json.loads(json.dumps(tree)), arrays)
    assert back['a'] == (1, 2.5, float('inf'), None)
    assert back[3] == [0.5, 7] and type(back[3][1]) is np.int64
    assert back['b'] == {1, 2} and np.isnan(back['c'])


def _saved_chain(rows):
    detector = LLRDetector('rw2', **llr_kwargs(LLR.validate({})))
    for row in rows:
        detector.update(*row)
    return {'detector': codec.encode(detector), 'last_time': rows[-1][0], 'offset': 0,
            'last_ref': None, 'not_tested': {}, 'history': [{'dry': float('nan')}]}


def test_state_save_cut_short_keeps_the_previous_state(wheel_rows, tmp_path):
    first = _saved_chain(wheel_rows[:2000])
    state.save(tmp_path, 'sat', 'print', [{'name': 'p', 'size': 1}], {'rw2': first})
    # A later save that wrote its arrays but not its JSON: the old state still loads.
    state.save(tmp_path / 'next', 'sat', 'print', [], {'rw2': _saved_chain(wheel_rows)})
    for npz in (tmp_path / 'next').glob('sat.*.npz'):
        npz.rename(tmp_path / npz.name)
    passes, chains = state.load(tmp_path, 'sat', 'print')
    assert passes == [{'name': 'p', 'size': 1}]
    assert chains['rw2']['last_time'] == first['last_time']
    assert np.isnan(chains['rw2']['history'][0]['dry'])
    # A completed save leaves one arrays file; a damaged one is refused.
    state.save(tmp_path, 'sat', 'print', [], {'rw2': first})
    (only,) = tmp_path.glob('sat.*.npz')
    only.write_bytes(only.read_bytes()[:-1] + b'x')
    with pytest.raises(ConfigError, match='does not match'):
        state.load(tmp_path, 'sat', 'print')
