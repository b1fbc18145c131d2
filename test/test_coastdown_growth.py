"""The step check on a coast-down: a speed shape the before segment shares is not growth.

bench/coastdown_growth.py measures why pure dry steps on real coast-downs stay
``undecided`` (docs/llr.md "Limits"); these records show the two sides of its argument on
synthetic data with a known answer.
"""

import numpy as np

from bench.coastdown_growth import growth_statistics
from rwa_monitor.core.llr_stats import z_threshold

Z = z_threshold(1.0e-3)
WINDOW = 500
STEP_S = 0.25
NOISE_NM = 0.003


def _coast() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(1200) * STEP_S
    return t, 30.0 * np.exp(-t / 150.0)


def _joined(before_speed, after_speed, extra_after, seed):
    """Return time, speed, residual of two segments 30 s apart with a drag-like misfit."""
    t, _ = _coast()
    time = np.concatenate([t, t + t[-1] + 30.0])
    speed = np.concatenate([before_speed, after_speed])
    misfit = 4.0e-5 * speed * np.abs(speed)
    noise = np.random.default_rng(seed).normal(0.0, NOISE_NM, time.size)
    residual = misfit + noise
    residual[t.size:] += extra_after
    return time, speed, residual, float(time[t.size])


def test_a_dry_step_on_a_coast_grows_alone_and_not_beside_the_shared_speed_shape():
    # Both coasts carry the same speed shape the step model (sign w, w) misses; after the
    # join only a dry step. Alone, the after segment's time shapes fit that speed shape
    # (time and speed are one axis on a coast): the step check rejects the step. With
    # the speed shape shared with the before segment the statistic is a chi2_2 maximum
    # over the time shapes under H0, above the limit with probability <= 1e-3.
    _, w = _coast()
    time, speed, residual, join = _joined(w, w, 0.05 * np.sign(w), seed=3501)
    stats = growth_statistics(time, speed, residual, join, WINDOW, Z)
    assert stats['after_only'] > stats['limit']
    assert stats['shared_speed_shape'][4] <= stats['limit']


def test_a_growth_in_time_survives_the_shared_speed_shape():
    # A dry ramp on a wheel whose speed returns to the same values at other times: the
    # time shape is not a speed shape, so the shared speed shape cannot take it.
    t, _ = _coast()
    w = 20.0 + 10.0 * np.sin(2.0 * np.pi * t / 40.0)
    ramp = 0.02 * t / t[-1] * np.sign(w)
    time, speed, residual, join = _joined(w, w, ramp, seed=3502)
    stats = growth_statistics(time, speed, residual, join, WINDOW, Z)
    assert min(stats['shared_speed_shape'].values()) > stats['limit']
