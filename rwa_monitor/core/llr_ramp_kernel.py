"""One block of a declared change's ramp sums, from the detector's rings, compiled.

The same floats as core/llr_changes.py forming the six per-sample terms of ``(h1, h2, f)``
with numpy and :func:`llr_growth.ramp_sums` summing them (p = 2, the paper's model (1)):
the products in the same order (``h1 h1, h1 h2, h2 h2, h1 f, h2 f, f f``; ``t u``, then
``(t u) u``) and each column summed in sample order from the first sample, as numpy's sum
along axis 0 of a C-contiguous array adds its rows. A closed change takes in its samples
every ``window`` samples until its last re-check, then every ``tail_stride`` (the rings'
length) for as long as the record lasts (llr_changes ``_take_ramp``), so
on a wheel with an old declaration this block was most of the Python after the kernel:
about 120 us a call in numpy, a few us here (docs/llr.md "Kinds on ramps").
:func:`ring_ramp_taken` also appends the block to the change's blocks, or merges it into
the last one, as llr_changes ``_with_block`` and ``_with_range`` do with numpy: one call
where those took a dozen (a closed change takes a block every ``tail_stride`` samples).
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.jit import njit

__all__ = ['BLOCK_WIDTH', 'ring_ramp_block', 'ring_ramp_taken']

# The ramp-sum row of p = 2 (u_last, then three sums of 6 terms), then |w| min and max.
BLOCK_WIDTH = 1 + 3 * 6


@njit('float64[::1](float64[:, ::1], float64[::1], float64[::1], int64, int64, float64)',
      cache=True)
def ring_ramp_block(term, time, speed, first, last, t0):  # pragma: no cover - compiled
    """Return the ramp-sum row of positions ``first..last`` and their ``|w|`` min, max.

    ``term``: the ring of ``(h1, h2, f)``; ``time``, ``speed``: the rings of the sample
    time (s) and ``|w|`` (rad/s); positions are taken modulo the ring's length; ``t0``: the
    estimated change time (s), ``u = time - t0``. Returns ``BLOCK_WIDTH + 2`` floats: the
    row of :func:`llr_growth.ramp_sums`, then the lowest and highest speed (NaN if any
    speed is NaN, as numpy's min and max).
    """
    return _block(term, time, speed, first, last, t0)


@njit('Tuple((float64[:, ::1], float64[:, ::1]))(float64[:, ::1], float64[::1], float64[::1], '
      'int64, int64, float64, float64[:, ::1], float64[:, ::1], boolean)', cache=True)
def ring_ramp_taken(term, time, speed, first, last, t0, ramp, speeds,
                    tail):  # pragma: no cover - compiled
    """Return a change's ramp blocks and speed ranges with positions ``first..last`` taken.

    The block of :func:`ring_ramp_block` appended to ``ramp`` (``(k, BLOCK_WIDTH)``) and its
    speed range to ``speeds`` (``(k, 2)``), or, with ``tail``, merged into their last rows:
    the sums added, the knot ``u`` the new block's, the range widened (``min`` and ``max``
    taken as Python's builtins take them, so a NaN on either side stays as it did). New
    arrays; the inputs are not changed.
    """
    block = _block(term, time, speed, first, last, t0)
    rows = ramp.shape[0]
    if tail and rows == 0:
        raise ValueError('a tail block needs a block to merge into')
    keep = rows - 1 if tail else rows
    new_ramp = np.empty((keep + 1, BLOCK_WIDTH))
    new_speeds = np.empty((keep + 1, 2))
    new_ramp[:keep] = ramp[:keep]
    new_speeds[:keep] = speeds[:keep]
    new_ramp[keep, 0] = block[0]
    low = block[BLOCK_WIDTH]
    high = block[BLOCK_WIDTH + 1]
    if tail:
        for c in range(1, BLOCK_WIDTH):
            new_ramp[keep, c] = ramp[keep, c] + block[c]
        old_low = speeds[keep, 0]
        old_high = speeds[keep, 1]
        low = low if low < old_low else old_low
        high = high if high > old_high else old_high
    else:
        for c in range(1, BLOCK_WIDTH):
            new_ramp[keep, c] = block[c]
    new_speeds[keep, 0] = low
    new_speeds[keep, 1] = high
    return new_ramp, new_speeds


@njit(cache=True)
def _block(term, time, speed, first, last, t0):  # pragma: no cover - compiled
    """Return the floats of :func:`ring_ramp_block` (shared with :func:`ring_ramp_taken`)."""
    length = time.shape[0]
    out = np.zeros(BLOCK_WIDTH + 2)
    lo = np.inf
    hi = -np.inf
    nan = False
    u = 0.0
    for j in range(first, last + 1):
        i = j % length
        h1 = term[i, 0]
        h2 = term[i, 1]
        f = term[i, 2]
        u = time[i] - t0
        t = (h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f)
        for c in range(6):
            once = t[c] * u
            if j == first:
                out[1 + c] = t[c]
                out[7 + c] = once
                out[13 + c] = once * u
            else:
                out[1 + c] += t[c]
                out[7 + c] += once
                out[13 + c] += once * u
        s = speed[i]
        if s != s:
            nan = True
        else:
            lo = min(lo, s)
            hi = max(hi, s)
    out[0] = u
    out[BLOCK_WIDTH] = np.nan if nan else lo
    out[BLOCK_WIDTH + 1] = np.nan if nan else hi
    return out
