"""The compiled per-sample path (core/llr_kernel.py) gives the detector's events exactly."""

import json
import os
import subprocess
import sys

import numpy as np
from test_llr import friction_signal, stream

from rwa_monitor.core.calibrate import NominalWheel
from rwa_monitor.core.llr import LLRDetector

SCRIPT = '''
import json, sys
import numpy as np
sys.path.insert(0, {test_dir!r})
from test_llr import friction_signal, stream
from rwa_monitor.core.calibrate import NominalWheel
from rwa_monitor.core.llr import detect_batch, LLRDetector
t, w, f = friction_signal(4000, 61, ((2000, 0.6, 0.0),), profile='crossing')
det = LLRDetector('rw1', window=150)
events = [e.to_json() for e in stream(det, t, w, f)] + [det.counters]
batch = [e.to_json() for e in detect_batch(t, w, f, window=150)]
print(json.dumps([events, batch]))
'''


def test_inputs_other_than_floats_give_the_events_of_floats():
    # Python ints, numpy scalars and numeric strings take the kernel's conversion or the
    # fallback through float(); None is counted as non-finite, as before.
    t, w, f = friction_signal(3000, 62, ((1500, 0.6, 0.0),))
    plain = LLRDetector('rw1', window=120)
    mixed = LLRDetector('rw1', window=120)
    expected = stream(plain, t, w, f)
    got = []
    for i, (a, b, c) in enumerate(zip(t.tolist(), w.tolist(), f.tolist())):
        if i % 3 == 0:
            a, b, c = np.float64(a), np.float64(b), str(c)
        elif i % 3 == 1:
            a = int(a) if a == int(a) else a
        got.extend(mixed.update(a, b, c))
    assert [e.to_json() for e in got] == [e.to_json() for e in expected]
    assert mixed.counters == plain.counters
    assert mixed.update(None, 1.0, 0.0) == [] and mixed.counters['non_finite'] == 1
    assert mixed.update(t[-1] + 1.0, 'x', 0.0) == [] and mixed.counters['non_finite'] == 2
    assert mixed.n_samples == plain.n_samples + 2


def test_uncompiled_kernel_gives_the_same_events():
    # NUMBA_DISABLE_JIT runs the kernel's functions as plain Python: one implementation,
    # streaming and batch (the compiled loop over arrays, then a Python loop).
    t, w, f = friction_signal(4000, 61, ((2000, 0.6, 0.0),), profile='crossing')
    det = LLRDetector('rw1', window=150)
    compiled = [e.to_json() for e in stream(det, t, w, f)] + [det.counters]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    script = SCRIPT.format(test_dir=os.path.join(root, 'test'))
    out = subprocess.run([sys.executable, '-c', script], check=True, capture_output=True,
                         text=True, timeout=300,
                         env=dict(os.environ, NUMBA_DISABLE_JIT='1'))
    assert len(compiled) > 1
    plain_stream, plain_batch = json.loads(out.stdout.strip().splitlines()[-1])
    assert plain_stream == json.loads(json.dumps(compiled))
    assert plain_batch == json.loads(json.dumps(compiled[:-1]))


def test_batch_and_streaming_can_take_turns_on_one_detector():
    # process_arrays and update act on the same state: chunks of arrays, then samples one
    # by one, give the events of one pass (the noise fit and a declaration span the cuts).
    t, w, f = friction_signal(6000, 64, ((2500, 0.6, 0.0), (4200, 0.0, 0.03)),
                              profile='crossing')
    whole = LLRDetector('rw1', window=120)
    expected = whole.process_arrays(t, w, f)
    det = LLRDetector('rw1', window=120)
    got = det.process_arrays(t[:100], w[:100], f[:100])
    got += det.process_arrays(t[100:2600], w[100:2600], f[100:2600])
    got += stream(det, t[2600:3000], w[2600:3000], f[2600:3000], end=False)
    got += det.process_arrays(t[3000:], w[3000:], f[3000:])
    assert len(expected) >= 2
    assert [e.to_json() for e in got] == [e.to_json() for e in expected]
    assert det.counters == whole.counters and det.n_samples == whole.n_samples == len(t)


def test_one_call_calibrated_update_equals_lookup_then_update():
    block = {'friction_model': {'effects': [], 'weights': {'dry': 0.5, 'viscous': 0.02}},
             'noise': {'low_speed_band': {'speed_abs_below_rad_s': 1.0}},
             'speed_range_rad_s': [-12.0, 16.0]}
    t, w, f = friction_signal(6000, 63, ((3000, 0.8, 0.0),), profile='crossing')
    two_calls, one_call = NominalWheel(block), NominalWheel(block)
    det_two, det_one = LLRDetector('rw1', window=150), LLRDetector('rw1', window=150)
    expected, got, reasons = [], [], []
    for row in zip(t.tolist(), w.tolist(), f.tolist()):
        residual, why = two_calls.residual_one(*row)
        reasons.append(why)
        expected.extend(det_two.update(row[0], row[1], residual))
        got.extend(det_one.update_nominal(one_call.table, *row))
    assert expected and [e.to_json() for e in got] == [e.to_json() for e in expected]
    assert det_one.counters == det_two.counters and det_one.n_samples == len(t)
    counts = {name: reasons.count(name) for name in ('low_speed_band',
                                                     'outside_calibrated_range')}
    assert min(counts.values()) > 0
    assert one_call.not_tested == two_calls.not_tested == counts


def _read_only(*arrays):
    out = []
    for a in arrays:
        a = np.array(a, dtype=float)
        a.setflags(write=False)
        out.append(a)
    return out


def test_read_only_arrays_give_the_events_of_writable_ones():
    # np.load(mmap_mode='r'), np.frombuffer and zero-copy Arrow columns are read-only;
    # the compiled kernels' signatures are of writable arrays (a TypeError before), so
    # the entries copy such inputs (jit.kernel_array) and never write into the caller's.
    from rwa_monitor.core.jit import kernel_array
    from rwa_monitor.core.schema import LLR
    from rwa_monitor.core.trend import pass_levels
    from rwa_monitor.core.wheel_runner import WheelRunner
    t, w, f = friction_signal(4000, 65, ((2000, 0.6, 0.0),), profile='crossing')
    frozen = _read_only(t, w, f)
    expected = LLRDetector('rw1', window=150).process_arrays(t, w, f)
    got = LLRDetector('rw1', window=150).process_arrays(*frozen)
    assert expected and [e.to_json() for e in got] == [e.to_json() for e in expected]
    block = {'friction_model': {'effects': [], 'weights': {'dry': 0.5, 'viscous': 0.02}},
             'noise': {'low_speed_band': {'speed_abs_below_rad_s': 1.0}},
             'speed_range_rad_s': [-12.0, 16.0]}
    runs = []
    for arrays in ((t, w, f), frozen):
        runner = WheelRunner('rw1', {**LLR.defaults(), 'window': 150},
                             nominal=NominalWheel(block))
        runs.append([e.to_json() for e in runner.feed(*arrays)] + [runner.facts()])
    assert runs[0] == runs[1]
    assert pass_levels(*frozen) == pass_levels(t, w, f)
    assert not any(a.flags.writeable for a in frozen)
    assert np.array_equal(frozen[2], f)
    writable = np.arange(3.0)
    assert kernel_array(writable) is writable and kernel_array(frozen[0]) is not frozen[0]
