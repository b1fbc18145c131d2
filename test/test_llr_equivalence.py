"""Streaming and batch LLR give identical events, field for field, on random streams.

Both run the detector's one implementation (core/llr_kernel.py per sample, declarations in
core/llr_changes.py); this checks it on generated streams that declare, revise, restart and
reject samples: random speed profiles, dry / viscous steps and ramps, noise, NaN, samples
out of range and times that go back, with random window, verification, rate, known or
estimated noise, AR prewhitening, noise growing with speed and a sliding reference.
"""

import math

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np

from rwa_monitor.core.llr import detect_batch_with_counters, LLRDetector

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


@st.composite
def streams(draw):
    """Return ``(t, w, f, params)``: a seeded wheel stream with changes and bad samples."""
    n = draw(st.integers(200, 2500))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    k = np.arange(n)
    shape = draw(st.sampled_from(['sine', 'ramp', 'steps', 'constant']))
    if shape == 'sine':
        w = 30.0 * np.sin(2 * np.pi * k / draw(st.integers(50, 800)))
    elif shape == 'ramp':
        w = np.linspace(-40.0, 60.0, n)
    elif shape == 'steps':
        w = rng.choice([-20.0, 0.0, 5.0, 40.0], n // 50 + 1).repeat(50)[:n]
    else:
        w = np.full(n, 12.0)
    dry = np.ones(n)
    viscous = np.full(n, 0.05)
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, n - 1))
        size = draw(st.floats(-2.0, 2.0))
        growth = np.clip(k - at, 0, None) * draw(st.sampled_from([0.0, 2e-3]))
        step = (k >= at) * size + growth
        if draw(st.booleans()):
            dry = dry + step
        else:
            viscous = viscous + 0.05 * step
    noise = draw(st.sampled_from([0.05, 1.0]))
    level = noise * (1.0 + draw(st.sampled_from([0.0, 0.05])) * np.abs(w))
    f = -dry * np.sign(w) - viscous * w + level * rng.standard_normal(n)
    t = k * 0.1
    for column in (t, w, f):
        bad = rng.random(n) < draw(st.sampled_from([0.0, 0.01]))
        column[bad] = rng.choice([math.nan, math.inf, 1e9, -5.0], int(bad.sum()))
    window = draw(st.integers(10, 60))
    params = dict(window=window, k_verif=draw(st.integers(0, window - 1)),
                  false_alarm_rate=draw(st.sampled_from([1e-2, 1e-4])),
                  reference_max=draw(st.sampled_from([0, 3 * window])),
                  category_revisions=draw(st.integers(0, 4)),
                  refine_change=draw(st.booleans()))
    model = draw(st.sampled_from(['known', 'white', 'ar', 'speed']))
    if model == 'known':
        params['noise_std'] = noise
    else:
        params['noise_ar_max_order'] = 0 if model == 'white' else 2
        params['noise_fit_samples'] = draw(st.integers(30, 300))
        params['noise_speed_model'] = model == 'speed'
    return t, w, f, params


@SETTINGS
@given(streams())
def test_streaming_and_batch_give_identical_events_and_counters(stream):
    t, w, f, params = stream
    det = LLRDetector('rw1', **params)
    streamed = []
    for row in zip(t.tolist(), w.tolist(), f.tolist()):
        streamed.extend(det.update(*row))
    streamed.extend(det.finish())
    batch, counters = detect_batch_with_counters(t, w, f, component='rw1', **params)
    assert [e.to_json() for e in batch] == [e.to_json() for e in streamed]
    assert counters == det.counters


def test_such_streams_declare_and_revise():
    # The property above means something only if such streams give events: a stream of
    # the generator's kind (sine speed, dry step) is declared, then its kind revised.
    rng = np.random.default_rng(5)
    k = np.arange(3000)
    w = 30.0 * np.sin(2 * np.pi * k / 150)
    f = -(1.0 + 0.3 * (k >= 1200)) * np.sign(w) - 0.05 * w + 0.5 * rng.standard_normal(k.size)
    events, _ = detect_batch_with_counters(k * 0.1, w, f, window=40)
    assert [e.revision for e in events] == [0, 1] and events[-1].kind == 'dry'
