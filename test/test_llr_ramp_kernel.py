"""The compiled ramp block equals numpy's terms and ramp sums, float for float."""

import numpy as np
import pytest

from rwa_monitor.core import llr_growth
from rwa_monitor.core.llr_ramp_kernel import BLOCK_WIDTH, ring_ramp_block


def _numpy_block(term, time, speed, first, last, t0):
    positions = np.arange(first, last + 1) % len(time)
    h1, h2, f = term[positions, 0], term[positions, 1], term[positions, 2]
    terms = np.column_stack((h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f))
    speeds = speed[positions]
    return llr_growth.ramp_sums(terms, time[positions] - t0), speeds.min(), speeds.max()


@pytest.mark.parametrize('seed', range(200))
def test_block_is_numpy_float_for_float(seed):
    rng = np.random.default_rng(seed)
    length = int(rng.integers(20, 2000))
    term = rng.standard_normal((length, 3)) * 10.0 ** rng.uniform(-6, 2, 3)
    time = np.cumsum(rng.uniform(0.05, 0.2, length)) + rng.uniform(0, 1e6)
    speed = np.abs(rng.standard_normal(length)) * 100.0
    first = int(rng.integers(0, 5 * length))       # positions wrap around the ring
    last = first + int(rng.integers(0, length))
    t0 = time[first % length] - rng.uniform(0, 1000)
    sums, low, high = _numpy_block(term, time, speed, first, last, t0)
    got = ring_ramp_block(term, time, speed, first, last, t0)
    assert got.shape == (BLOCK_WIDTH + 2,)
    assert np.array_equal(got[:BLOCK_WIDTH], sums)
    assert (got[BLOCK_WIDTH], got[BLOCK_WIDTH + 1]) == (low, high)


def test_a_nan_speed_gives_nan_range_as_numpy():
    term = np.ones((8, 3))
    time = np.arange(8.0)
    speed = np.array([1.0, 2.0, np.nan, 4.0, 5.0, 6.0, 7.0, 8.0])
    got = ring_ramp_block(term, time, speed, 1, 4, 0.0)
    assert np.isnan(got[BLOCK_WIDTH]) and np.isnan(got[BLOCK_WIDTH + 1])
    assert np.array_equal(got[:BLOCK_WIDTH], _numpy_block(term, time, speed, 1, 4, 0.0)[0])
