"""The compiled ramp block equals numpy's terms, ramp sums and block merging, float for float."""

import numpy as np
import pytest

from rwa_monitor.core import llr_changes, llr_growth
from rwa_monitor.core.llr_ramp_kernel import BLOCK_WIDTH, ring_ramp_block, ring_ramp_taken


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


@pytest.mark.parametrize('seed', range(100))
def test_taken_block_is_numpy_appended_or_merged_float_for_float(seed):
    rng = np.random.default_rng(1000 + seed)
    length = int(rng.integers(20, 500))
    term = rng.standard_normal((length, 3)) * 10.0 ** rng.uniform(-6, 2, 3)
    time = np.cumsum(rng.uniform(0.05, 0.2, length))
    speed = np.abs(rng.standard_normal(length)) * 100.0
    if seed % 4 == 0:
        speed[int(rng.integers(0, length))] = np.nan
    rows = int(rng.integers(1, 5))
    ramp = rng.standard_normal((rows, BLOCK_WIDTH))
    speeds = np.sort(np.abs(rng.standard_normal((rows, 2))) * 100.0, axis=1)
    if seed % 5 == 0:
        speeds[-1, 0] = np.nan
    first = int(rng.integers(0, 3 * length))
    last = first + int(rng.integers(0, length))
    tail = bool(seed % 2)
    block = ring_ramp_block(term, time, speed, first, last, 0.0)
    got_ramp, got_speeds = ring_ramp_taken(term, time, speed, first, last, 0.0,
                                           ramp, speeds, tail)
    assert np.array_equal(got_ramp, llr_changes._with_block(ramp, block[:BLOCK_WIDTH], tail))
    assert np.array_equal(got_speeds, llr_changes._with_range(speeds, block[BLOCK_WIDTH:], tail),
                          equal_nan=True)


def test_taken_block_leaves_its_inputs_and_refuses_a_tail_without_a_block():
    term, time, speed = np.ones((8, 3)), np.arange(8.0), np.arange(8.0)
    ramp, speeds = np.ones((1, BLOCK_WIDTH)), np.array([[1.0, 2.0]])
    ring_ramp_taken(term, time, speed, 1, 4, 0.0, ramp, speeds, True)
    assert np.array_equal(ramp, np.ones((1, BLOCK_WIDTH)))
    assert np.array_equal(speeds, [[1.0, 2.0]])
    with pytest.raises(ValueError):
        ring_ramp_taken(term, time, speed, 1, 4, 0.0, np.empty((0, BLOCK_WIDTH)),
                        np.empty((0, 2)), True)
