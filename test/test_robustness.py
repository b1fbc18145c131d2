"""No input crashes a detector core; what cannot be used is counted (issue 17, item 1).

The zero-crossing streams reproduce a rounding failure of the LLR candidate statistic
(two nearly equal eigenvalues gave a correlation above 1 and the square root of a
negative number in the tail bound). The property tests drive the cores with arbitrary
finite streams (zero crossings, constant speed, denormals, huge values) and non-finite
values; each keeps its example count small so that the suite stays quick.
"""

import math

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from rwa_monitor.core import llr
from rwa_monitor.core.gchi2 import log_lower_bound
from rwa_monitor.core.llr import detect_batch_with_counters, LLRDetector
from rwa_monitor.core.vsadc import VsadcDetector
from rwa_monitor.exceptions import RwaMonitorError

SETTINGS = settings(max_examples=15, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def oscillating_wheel(period_s: float, seed: int, duration_s: float = 1200.0):
    """Speed 5 sin(2 pi t / P) rad/s at 10 Hz; healthy Coulomb + viscous friction, noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 0.1)
    w = 5.0 * np.sin(2.0 * np.pi * t / period_s)
    f = -(2e-4 * np.sign(w) + 5e-7 * w) + 5e-5 * rng.standard_normal(t.size)
    return t, w, f


@pytest.mark.parametrize('period_s', [2.0, 5.0, 10.0, 50.0])
def test_llr_wheel_oscillating_through_zero_runs_to_the_end(period_s):
    """Both paths finish the stream and agree; before the fix each raised ValueError."""
    for seed in (1, 2):
        t, w, f = oscillating_wheel(period_s, seed)
        det = LLRDetector()
        streamed = []
        for a, b, c in zip(t.tolist(), w.tolist(), f.tolist()):
            streamed.extend(det.update(a, b, c))
        batch, counters = detect_batch_with_counters(t, w, f)
        assert det.n_samples == t.size
        assert [(e.kind, e.index) for e in streamed] == [(e.kind, e.index) for e in batch]
        assert counters['non_finite'] == counters['out_of_range'] == 0


def test_candidate_bound_with_equal_eigenvalues_rounded_apart():
    """tr^2 / 4 slightly below det (rounding) must give a finite bound, not a domain error."""
    half = 0.3
    dm = half * half * (1.0 + 4e-16)
    for dof in (None, 50.0):
        value = llr.candidate_log_p2(40.0, 2.0 * half, dm, 0.0, dof)
        assert value is not None and math.isfinite(value) and value < 0.0
    assert log_lower_bound(-1e-17) == log_lower_bound(0.0)


# -- streams -------------------------------------------------------------------------------
FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)
ANY = st.floats(allow_nan=True, allow_infinity=True, width=64)
SPECIAL = st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 2.2e-308, 1e300, -1e300, 1.7e308,
                           math.nan, math.inf, -math.inf])


@st.composite
def wheel_streams(draw, n_max: int = 100, parts: str = 'twf'):
    """Draw (time, speed, friction) lists: profiles with arbitrary values mixed in.

    ``parts``: the columns that receive arbitrary values.
    """
    n = draw(st.integers(1, n_max))
    kind = draw(st.sampled_from(['sine', 'constant', 'arbitrary', 'tiny', 'huge']))
    k = np.arange(n, dtype=float)
    if kind == 'sine':
        period = draw(st.integers(2, 60))
        w = draw(st.floats(1e-6, 1e3)) * np.sin(2.0 * np.pi * k / period)
    elif kind == 'constant':
        w = np.full(n, draw(FINITE))
    elif kind == 'tiny':
        w = np.asarray(draw(st.lists(st.floats(-1e-300, 1e-300), min_size=n, max_size=n)))
    elif kind == 'huge':
        w = np.asarray(draw(st.lists(st.floats(-1.7e308, 1.7e308), min_size=n, max_size=n)))
    else:
        w = np.asarray(draw(st.lists(FINITE, min_size=n, max_size=n)))
    f = -(2e-4 * np.sign(w) + 5e-7 * w) + draw(st.floats(0.0, 1e-3)) * np.sin(3.7 * k)
    t = 0.1 * k
    w, f, t = w.tolist(), f.tolist(), t.tolist()
    for _ in range(draw(st.integers(0, 6))):
        i = draw(st.integers(0, n - 1))
        which = draw(st.sampled_from(list(parts)))
        value = draw(st.one_of(SPECIAL, ANY))
        {'t': t, 'w': w, 'f': f}[which][i] = value
    return t, w, f


LLR_PARAMS = dict(window=10, k_verif=2, false_alarm_rate=0.2)


@SETTINGS
@given(wheel_streams())
def test_llr_streaming_never_raises_and_counts_every_unused_sample(stream):
    t, w, f = stream
    det = LLRDetector(**LLR_PARAMS)
    events = []
    for a, b, c in zip(t, w, f):
        events.extend(det.update(a, b, c))
    used = det.n_accepted  # in the window or waiting for the noise fit
    assert det.n_samples == len(t)
    assert used + sum(det.counters[k] for k in ('non_finite', 'out_of_range',
                                                'non_increasing_time')) == len(t)
    for e in events:
        assert math.isfinite(e.time) and 0.0 <= e.p_value <= 1.0


@SETTINGS
@given(wheel_streams())
def test_llr_batch_never_raises_and_matches_streaming(stream):
    t, w, f = stream
    events, counters = detect_batch_with_counters(np.asarray(t), np.asarray(w),
                                                  np.asarray(f), **LLR_PARAMS)
    det = LLRDetector(**LLR_PARAMS)
    streamed = []
    for a, b, c in zip(t, w, f):
        streamed.extend(det.update(a, b, c))
    streamed.extend(det.finish())   # the batch has the file's end: the final categorisation
    assert [(e.kind, e.index, e.revision) for e in events] == \
        [(e.kind, e.index, e.revision) for e in streamed]
    for name in ('non_finite', 'out_of_range', 'non_increasing_time'):
        assert counters[name] == det.counters[name]


@st.composite
def gyro_streams(draw, n_max: int = 120):
    """Draw rows (time, gyro, quaternion or None, reference) with arbitrary values."""
    n = draw(st.integers(1, n_max))
    rate = draw(st.floats(-1e-2, 1e-2))
    rows = []
    for k in range(n):
        angle = rate * 0.1 * k
        q = [math.sin(angle / 2.0), 0.0, 0.0, math.cos(angle / 2.0)]
        g = [rate + 1e-6 * math.sin(k), 1e-6 * math.cos(k), 0.0]
        rows.append([0.1 * k, g, q, [0.0, 0.0, 0.0]])
    for _ in range(draw(st.integers(0, 8))):
        row = rows[draw(st.integers(0, n - 1))]
        part = draw(st.sampled_from(['t', 'g', 'q', 'r', 'none']))
        value = draw(st.one_of(SPECIAL, ANY))
        if part == 't':
            row[0] = value
        elif part == 'none':
            row[2] = None
        else:
            target = {'g': row[1], 'q': row[2], 'r': row[3]}[part]
            if target is not None:
                target[draw(st.integers(0, len(target) - 1))] = value
    return rows


@SETTINGS
@given(gyro_streams())
def test_vsadc_never_raises_and_counts_every_row(rows):
    det = VsadcDetector(window=10, sigma_window=10, reference_window=20)
    for t, g, q, r in rows:
        det.update(t, g, q, r)
    c = det.counters
    assert c['rows'] == len(rows)
    assert (c['accepted'] + c['held'] + c['bad_gyro'] + c['non_finite']
            + c['non_increasing_time']) == len(rows)


@st.composite
def fss_windows(draw):
    """Draw a short window of (speed, friction): zero crossings, constant speed, zero."""
    n = draw(st.integers(200, 600))
    k = np.arange(n, dtype=float)
    kind = draw(st.sampled_from(['sine', 'constant', 'zero', 'huge']))
    if kind == 'sine':
        w = draw(st.floats(1e-3, 400.0)) * np.sin(2.0 * np.pi * k / draw(st.integers(5, 300)))
    elif kind == 'constant':
        w = np.full(n, draw(st.floats(-1e3, 1e3)))
    elif kind == 'zero':
        w = np.zeros(n)
    else:
        w = np.full(n, 1e300) * np.sign(np.sin(k / 17.0) + 0.5)
    f = -(2e-4 * np.sign(w) + 5e-7 * w) + 1e-5 * np.sin(7.3 * k)
    for _ in range(draw(st.integers(0, 4))):
        i = draw(st.integers(0, n - 1))
        (w if draw(st.booleans()) else f)[i] = draw(SPECIAL)
    return 0.1 * k, w, f


@settings(max_examples=8, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(fss_windows())
def test_fss_diagnosis_never_raises(window):
    from rwa_monitor.core.fss.pipeline import diagnose, FssConfig
    t, w, f = window
    with np.errstate(all='ignore'):
        result = diagnose(w, f, t, _fss_model(), FssConfig(wglr_window=10, dk_error=2))
    assert set(result['anomalies']) and all(isinstance(v, bool)
                                            for v in result['anomalies'].values())


_MODEL = []


def _fss_model():
    from rwa_monitor.telemetry.fss_model import load_model
    if not _MODEL:
        _MODEL.append(load_model(None))
    return _MODEL[0]


@settings(max_examples=8, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(wheel_streams(n_max=600, parts='twf'))
def test_identify_never_raises_anything_but_its_own_errors(stream):
    """Feed arbitrary times, speeds and frictions (times out of order: dropped, counted)."""
    from rwa_monitor.pipelines.identify import prepare
    from rwa_monitor.core.identify.select import identify
    from rwa_monitor.telemetry import Telemetry
    from rwa_monitor.telemetry.schema import Wheel
    t, w, f = (np.asarray(v, dtype=float) for v in stream)
    tele = Telemetry(time=t, wheels={'rw1': Wheel(speed=w, friction=f)})
    try:
        with np.errstate(all='ignore'):
            data = prepare(tele, 'rw1')
            identify(data, max_effects=1)
    except RwaMonitorError as err:
        assert str(err) and '\n' not in str(err)


def test_identify_refuses_speeds_that_are_not_physical():
    from rwa_monitor.pipelines.identify import prepare
    from rwa_monitor.core.identify.select import identify
    from rwa_monitor.telemetry import Telemetry
    from rwa_monitor.telemetry.schema import Wheel
    t, w, f = oscillating_wheel(50.0, 3, 300.0)
    tele = Telemetry(time=t, wheels={'rw1': Wheel(speed=w * 1e30, friction=f)})
    with pytest.raises(RwaMonitorError, match='not physical'):
        identify(prepare(tele, 'rw1'))


def test_single_huge_friction_spike_is_dropped_not_declared():
    """A 1e5 N m spike is outside the plausibility limit: counted, no 'both' anomaly."""
    t, w, f = oscillating_wheel(50.0, 4, 600.0)
    f = f.copy()
    f[3000] = 1e5
    events, counters = detect_batch_with_counters(t, w, f)
    assert events == [] and counters['out_of_range'] == 1


def test_persistent_implausible_input_is_a_sensor_fault():
    from rwa_monitor.core.streams import SensorFaultMonitor
    monitor = SensorFaultMonitor(min_samples=20, fraction=0.5)
    assert monitor.update(100, 3) is None
    assert 'sensor fault: 60 of the last 100' in monitor.update(200, 63)
    assert monitor.update(205, 63) is not None      # too few new samples: unchanged
    assert monitor.update(305, 63) is None
