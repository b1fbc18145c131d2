"""A change that falls in a gap between passes is dated by the gap (docs/llr.md).

The change position is refined with a prior uniform in time (core/llr_stats.py
``refine_change``): a split across a gap of an hour holds 36,000 times the time of a
split between two samples 0.1 s apart, log 36,000 = 10.5 nats. With a dry step of 3e-4
N m in noise of 5e-5 N m (|h| = 1), a split k samples away from the true one has a
log-likelihood lower by 18 k nats on average with a standard deviation of 6 sqrt(k): it
beats the gap with probability below 1e-6 (k = 1, z = 4.75), so 20 seeds all dated at
the gap fail by chance with probability below 1e-4. Between evenly spaced samples the
prior is flat and the position is the maximum-likelihood one (the golden files).
"""

import numpy as np
import pytest

from rwa_monitor.core import keys
from rwa_monitor.core.llr import detect_batch, LLRDetector

GAP_S = 3600.0


def _record(seed, step_at, nan_after_gap=0):
    rng = np.random.default_rng(seed)
    first = np.arange(0.0, 600.0, 0.1)
    t = np.concatenate([first, GAP_S + first])
    w = 200.0 + 150.0 * np.sin(t / 40.0)
    noise = rng.normal(0.0, 5e-5, t.size)
    f = -(2e-4 + 3e-4 * (t >= step_at)) * np.sign(w) - 5e-7 * w + noise
    f[first.size:first.size + nan_after_gap] = np.nan
    return t, w, f, first.size


@pytest.mark.parametrize('seed', range(20))
def test_a_step_in_the_gap_is_dated_at_the_first_sample_after_it(seed):
    t, w, f, after = _record(seed, 2000.0)
    events = detect_batch(t, w, f, window=500)
    first = events[0]
    assert first.index == after and first.time == t[after]
    assert first.details[keys.AFTER_GAP] == pytest.approx(t[after] - t[after - 1])
    assert all(e.details[keys.AFTER_GAP] == first.details[keys.AFTER_GAP] for e in events)


def test_the_first_tested_sample_after_the_gap_shows_it():
    """Untested (NaN) rows at the start of the next pass: the first tested one dates it."""
    t, w, f, after = _record(3, 2000.0, nan_after_gap=40)
    first = detect_batch(t, w, f, window=500)[0]
    assert first.index == after + 40
    assert first.details[keys.AFTER_GAP] == pytest.approx(t[after + 40] - t[after - 1])


def test_a_step_inside_a_pass_has_no_gap_and_streaming_equals_batch():
    t, w, f, after = _record(4, 4000.0)
    events = detect_batch(t, w, f, window=500)
    assert abs(events[0].time - 4000.0) < 1.0 and keys.AFTER_GAP not in events[0].details
    det = LLRDetector('rw1', window=500)
    streamed = [e for row in zip(t, w, f) for e in det.update(*row)] + det.finish()
    assert [e.to_json() for e in streamed] == [e.to_json() for e in events]
