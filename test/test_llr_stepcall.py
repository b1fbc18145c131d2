"""The C call of the streaming step (core/_stepcall.c, core/llr_cstep.py) changes nothing.

``LLRDetector.update`` is a method implemented in C that calls the kernel's step compiled
as a C function when the fast path holds and the sample is three floats, and the Python
``update`` otherwise (which calls the same kernel through numba's dispatcher). Both paths
must give the same events, counters and state arrays, bit for bit: on random streams with
every kind of argument, on the golden files, and when the step raises.
"""

import contextlib
import copy
import gc
import inspect
import json
import math
import os
import pathlib
import pickle
import subprocess
import sys
from unittest import mock
import weakref

import golden_cases
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
from test_llr_equivalence import streams

from rwa_monitor.core import llr_cstep, llr_detector, llr_layout as layout
from rwa_monitor.core.llr import detect_batch_with_counters, LLRDetector
from rwa_monitor.core.schema import llr_kwargs
from rwa_monitor.pipelines import llr as llr_pipeline
from rwa_monitor.telemetry import read_telemetry
from rwa_monitor.telemetry.parameters_file import load_block

SETTINGS = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
COMPILED = llr_cstep.step_address() is not None
REPO = pathlib.Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def python_path():
    """Inside, no detector arms the C step: every update runs the Python method."""
    with mock.patch.object(llr_cstep, 'step_address', return_value=None), \
            mock.patch.object(llr_detector, '_C_CALL', False):
        yield


def feed(det, rows, forms=None):
    """Return the events of ``det`` on ``rows`` (then ``finish``), each row as ``forms``."""
    events = []
    for i, row in enumerate(rows):
        if forms is None:
            events.extend(det.update(*row))
        else:
            events.extend(forms[i](det, row))
    events.extend(det.finish())
    return events


def same_state(a, b):
    """Assert two detectors hold the same state arrays (bytes: NaN compared too)."""
    assert a._live.floats.tobytes() == b._live.floats.tobytes()
    assert a._live.ints.tobytes() == b._live.ints.tobytes()
    assert a.counters == b.counters


# Ways to pass one sample: the C path takes the first two, the others go to Python.
FORMS = [
    lambda det, row: det.update(*row),
    lambda det, row: det.update(*(np.float64(v) for v in row)),
    lambda det, row: det.update(*row, None),
    lambda det, row: det.update(*row, aux=None),
    lambda det, row: det.update(row[0], row[1], friction=row[2]),
    lambda det, row: det.update(*(np.float32(v) for v in row)),
    lambda det, row: det.update(*(int(v) if math.isfinite(v) else v for v in row)),
    lambda det, row: det.update(row[0], str(row[1]), row[2]),
    lambda det, row: det.update(row[0], None, row[2]),
    lambda det, row: LLRDetector.update(det, *row),
]


def test_the_c_module_is_built_and_armed_on_the_fast_path():
    # setup.py builds it wherever a C compiler is present; without numba's compiler
    # (NUMBA_DISABLE_JIT=1) nothing is armed and the Python path runs.
    from numba import config
    if config.DISABLE_JIT:
        pytest.skip('numba disabled: the Python path only')
    assert llr_cstep.available() and COMPILED
    det = LLRDetector('rw1', window=20, noise_std=0.1)
    assert det._fast and det._step_armed()
    fitting = LLRDetector('rw1', window=20, noise_fit_samples=30)
    assert not fitting._fast and not fitting._step_armed()
    for k in range(31):   # the fit at the 30th sample; the next call arms the C step
        fitting.update(0.1 * k, 10.0 + k, 0.01 * k)
    assert fitting._fast and fitting._step_armed()
    fitting.reset()
    assert not fitting._fast and not fitting._step_armed()


def test_update_keeps_the_signature_and_doc_of_the_python_method():
    sig = inspect.signature(LLRDetector.update)
    assert list(sig.parameters) == ['self', 't', 'speed', 'friction', 'aux']
    assert sig.parameters['aux'].default is None
    assert 'Process one sample' in LLRDetector.update.__doc__
    det = LLRDetector('rw1', window=20)
    assert list(inspect.signature(det.update).parameters) == ['t', 'speed', 'friction', 'aux']


@SETTINGS
@given(streams(), st.lists(st.integers(0, len(FORMS) - 1), min_size=1, max_size=8),
       st.integers(0, 2**32 - 1))
def test_c_and_python_paths_give_identical_events_counters_and_state(stream, forms, seed):
    t, w, f = (a.tolist() for a in stream[:3])
    params = stream[3]
    rows = list(zip(t, w, f))
    picks = np.random.default_rng(seed).choice(forms, len(rows))
    chosen = [FORMS[i] for i in picks]
    compiled = LLRDetector('rw1', **params)
    got = feed(compiled, rows, chosen)
    with python_path():
        plain = LLRDetector('rw1', **params)
        want = feed(plain, rows, chosen)
    assert not plain._step_armed()
    assert [e.to_json() for e in got] == [e.to_json() for e in want]
    same_state(compiled, plain)
    batch, counters = detect_batch_with_counters(*stream[:3], component='rw1', **params)
    if set(picks) <= {0, 1, 2, 3, 4, 9}:   # forms that pass the floats unchanged
        assert [e.to_json() for e in batch] == [e.to_json() for e in got]
        assert counters == compiled.counters


@pytest.mark.parametrize('config', [None, golden_cases.CONFIG], ids=['defaults', 'config'])
def test_golden_file_gives_the_same_events_on_both_paths_and_in_batch(config):
    tele = read_telemetry(golden_cases.data_file('friction_step'))
    values = load_block(config, llr_pipeline.SCHEMA)
    kwargs = llr_kwargs({k: v for k, v in values.items() if k in llr_pipeline.DEFAULTS})
    found = 0
    for wheel, channel in tele.wheels.items():
        rows = list(zip(tele.time.tolist(), channel.speed.tolist(), channel.friction.tolist()))
        compiled = LLRDetector(wheel, **kwargs)
        got = feed(compiled, rows)
        with python_path():
            plain = LLRDetector(wheel, **kwargs)
            want = feed(plain, rows)
        batch, counters = detect_batch_with_counters(
            tele.time, channel.speed, channel.friction, component=wheel, **kwargs)
        assert [e.to_json() for e in got] == [e.to_json() for e in want] == \
            [e.to_json() for e in batch]
        assert counters == compiled.counters
        same_state(compiled, plain)
        found += len(got)
    assert found >= 2   # the file's two changes are declared: the comparison means something


def _zero_noise_level(det):
    """Make the next accepted sample divide by a zero noise level (state set by hand)."""
    det._live.ints[layout.I_SPEED_MODEL] = 1
    det._live.floats[layout.F_SPEED_A:layout.F_SPEED_FLOOR + 1] = 0.0


def test_a_step_that_raises_raises_on_both_paths_with_the_same_state():
    dets = []
    for path in (contextlib.nullcontext, python_path):
        with path():
            det = LLRDetector('rw1', window=20, noise_std=0.1)
            det.update(0.0, 5.0, 0.1)
            _zero_noise_level(det)
            with pytest.raises(ArithmeticError):
                det.update(0.1, 5.0, 0.1)
            dets.append((det, det._step_armed()))
    assert [armed for _, armed in dets] == [COMPILED, False]
    same_state(dets[0][0], dets[1][0])


def test_reset_arms_the_new_arrays():
    rng = np.random.default_rng(3)
    k = np.arange(1500)
    w = 30.0 * np.sin(2 * np.pi * k / 200)
    f = -(1.0 + 0.5 * (k >= 700)) * np.sign(w) - 0.05 * w + 0.2 * rng.standard_normal(k.size)
    rows = list(zip((0.1 * k).tolist(), w.tolist(), f.tolist()))
    det = LLRDetector('rw1', window=60, noise_std=0.2)
    first = feed(det, rows)
    old = weakref.ref(det._live.floats)
    det.reset()
    assert old() is None   # the C side let go of the old arrays
    again = feed(det, rows)
    assert first and [e.to_json() for e in again] == [e.to_json() for e in first]


def test_an_armed_detector_is_freed():
    det = LLRDetector('rw1', window=20, noise_std=0.1)
    det.update(0.0, 5.0, 0.1)
    ref, fs = weakref.ref(det), weakref.ref(det._live.floats)
    del det
    gc.collect()
    assert ref() is None and fs() is None


def test_arming_checks_the_arrays():
    det = LLRDetector('rw1', window=20, noise_std=0.1)
    if not llr_cstep.available():
        pytest.skip('no C module')
    address = llr_cstep.step_address() or 1
    with pytest.raises(TypeError):
        det._step_arm(address, det._live.ints, det._live.ints)
    with pytest.raises(ValueError):   # numpy refuses a contiguous view of a strided one
        det._step_arm(address, det._live.floats[::2], det._live.ints)
    with pytest.raises(ValueError):
        det._step_arm(0, det._live.floats, det._live.ints)
    assert det._step_armed() == COMPILED   # a refused arming leaves the armed step as it was


@pytest.mark.parametrize('how', ['deepcopy', 'pickle'])
def test_a_copied_detector_continues_as_the_original(how):
    rng = np.random.default_rng(8)
    k = np.arange(2000)
    w = 30.0 * np.sin(2 * np.pi * k / 150)
    f = -(1.0 + 0.5 * (k >= 1400)) * np.sign(w) - 0.05 * w + 0.2 * rng.standard_normal(k.size)
    rows = list(zip((0.1 * k).tolist(), w.tolist(), f.tolist()))
    det = LLRDetector('rw1', window=60)
    for row in rows[:1000]:
        det.update(*row)
    twin = copy.deepcopy(det) if how == 'deepcopy' else pickle.loads(pickle.dumps(det))
    assert twin._live.floats is not det._live.floats
    assert twin._step_armed() == det._step_armed() == COMPILED
    first, second = feed(det, rows[1000:]), feed(twin, rows[1000:])
    assert first and [e.to_json() for e in second] == [e.to_json() for e in first]
    same_state(det, twin)


WITHOUT_C_MODULE = '''
import inspect, json, sys
sys.modules['rwa_monitor.core._stepcall'] = None   # import fails: as if never built
import numpy as np
from rwa_monitor.core import llr_cstep
from rwa_monitor.core.llr import LLRDetector
assert not llr_cstep.available() and llr_cstep.step_address() is None
assert inspect.isfunction(LLRDetector.update)
t, w, f = np.load(sys.argv[1]).T
det = LLRDetector('rw1', window=60, noise_std=0.2)
assert det._fast and not det._step_armed()
events = [e.to_json() for row in zip(t.tolist(), w.tolist(), f.tolist())
          for e in det.update(*row)] + [e.to_json() for e in det.finish()]
print(json.dumps({'events': events, 'fs': det._live.floats.tobytes().hex()}))
'''


def test_without_the_c_module_the_python_update_gives_the_same_events(tmp_path):
    rng = np.random.default_rng(11)
    k = np.arange(3000)
    w = 25.0 * np.sin(2 * np.pi * k / 300)
    f = -(1.0 + 0.4 * (k >= 1800)) * np.sign(w) - 0.05 * w + 0.2 * rng.standard_normal(k.size)
    stream = np.column_stack([0.1 * k, w, f])
    np.save(tmp_path / 'stream.npy', stream)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    out = subprocess.run([sys.executable, '-c', WITHOUT_C_MODULE, str(tmp_path / 'stream.npy')],
                         env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    plain = json.loads(out.stdout.strip().splitlines()[-1])
    det = LLRDetector('rw1', window=60, noise_std=0.2)
    events = feed(det, [tuple(row) for row in stream.tolist()])
    assert events and [e.to_json() for e in events] == plain['events']
    assert det._live.floats.tobytes().hex() == plain['fs']
