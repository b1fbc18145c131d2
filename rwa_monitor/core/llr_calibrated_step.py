"""The calibrated nominal lookup of the LLR detector, compiled (core/nominal.py table).

:func:`pack_table` packs a wheel's ``NominalWheel`` (core/calibrate.py) into one float
array; :func:`nominal_residual` returns ``f - nominal(w)`` from it, counting the samples
not tested by reason; :func:`step_calibrated` is that residual and the kernel's
:func:`rwa_monitor.core.llr_kernel.sample` (its exact tail settled,
``llr_kernel.settle``) in one call per sample (the calibrated streaming path of
``LLRDetector.update_nominal``). Compiled like the kernels (:mod:`rwa_monitor.core.jit`).
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core.jit import njit
from rwa_monitor.core.llr_kernel import sample, settle
from rwa_monitor.core.llr_layout import setup

# Calibrated nominal lookup (core/calibrate.py NominalWheel): one table array per wheel.
T_REASON = 0      # out: why the last sample was not tested (0: tested or no reason)
T_BAND = 1
T_LO = 2
T_HI = 3
T_AT_ZERO = 4
T_SCALE = 5
T_ABOVE = 6       # (offset of grid, its length, offset of bucket index) of w > 0
T_BELOW = 9       # the same for w < 0
T_COUNTS = 12     # samples not tested, by reason code 1 and 2 (T_COUNTS + code - 1)
T_HEADER = 14
LOW_SPEED_BAND = 1
OUTSIDE_RANGE = 2


def pack_table(band: float, speed_range: tuple[float, float], at_zero: float, scale: float,
               above: tuple, below: tuple) -> np.ndarray:
    """Return the table of :func:`nominal_residual`.

    ``above`` / ``below``: ``(grid, values, slope, first)`` of each side of zero (``first``:
    the bucket index of ``NominalWheel``); ``scale``: buckets per rad/s.
    """
    head = np.zeros(T_HEADER)
    head[T_BAND:T_SCALE + 1] = (band, speed_range[0], speed_range[1], at_zero, scale)
    parts = [head]
    offset = T_HEADER
    for at, (grid, values, slope, first) in ((T_ABOVE, above), (T_BELOW, below)):
        head[at:at + 3] = (offset, len(grid), offset + 3 * len(grid))
        parts.extend(np.asarray(a, dtype=float) for a in (grid, values, slope, first))
        offset += 3 * len(grid) + len(first)
    return np.concatenate(parts)


@njit('float64(float64[::1], float64, float64, float64)', cache=True)
def nominal_residual(table, t, w, f):
    """Return ``f - nominal(w)`` from the table; NaN if not tested (reason counted).

    Not tested: non-finite input, ``|w|`` inside the low-speed band (reason 1), ``w``
    outside the calibrated range, off the side's grid or between its tested intervals
    (NaN points of the table; reason 2). The interval of
    ``|w|`` is found by ``numpy.searchsorted`` between its bucket's bounds, then
    ``nominal_j + (|w| - grid_j) slope_j`` (the floats of ``NominalWheel.residual``).
    """
    table[T_REASON] = 0.0
    if not (-math.inf < w < math.inf and -math.inf < f < math.inf
            and -math.inf < t < math.inf):
        return math.nan
    mag = abs(w)
    if mag < table[T_BAND]:
        table[T_REASON] = LOW_SPEED_BAND
    elif w < table[T_LO] or w > table[T_HI]:
        table[T_REASON] = OUTSIDE_RANGE
    if table[T_REASON] != 0.0:
        table[T_COUNTS + int(table[T_REASON]) - 1] += 1.0
        return math.nan
    nominal = math.nan
    if w == 0.0:
        nominal = table[T_AT_ZERO]
    else:
        head = T_ABOVE if w > 0.0 else T_BELOW
        o = int(table[head])
        n = int(table[head + 1])
        grid = table[o:o + n]
        if grid[0] <= mag <= grid[n - 1]:
            bucket = int(table[head + 2]) + int((mag - grid[0]) * table[T_SCALE])
            lo = int(table[bucket])
            j = lo + np.searchsorted(grid[lo:int(table[bucket + 3])], mag, side='right') - 1
            nominal = table[o + n + j]
            if mag != grid[j]:
                nominal += (mag - grid[j]) * table[o + 2 * n + j]
    if nominal != nominal:
        # Off the side's grid or between its tested intervals (NaN points).
        table[T_REASON] = OUTSIDE_RANGE
        table[T_COUNTS + OUTSIDE_RANGE - 1] += 1.0
        return math.nan
    return f - nominal


@njit('int64(float64[::1], int64[::1], float64[::1], float64, float64, float64)', cache=True)
def step_calibrated(fs, ints, table, t, w, f):
    """``llr_kernel.step`` of ``(t, w, nominal_residual(table, t, w, f))``: one call per sample."""
    return settle(fs, ints, sample(fs, ints, setup(fs, ints), t, w,
                                   nominal_residual(table, t, w, f)))
