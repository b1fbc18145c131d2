"""State layout of the LLR detector's compiled per-sample path (core/llr_kernel.py).

The detector's per-sample state lives in two preallocated arrays (:func:`allocate`):
``fs`` (floats: the named scalars ``F_*``, then the rings of prefix rows, terms, times and
speeds, the AR coefficients and lags) and ``ints`` (the named scalars ``I_*``: counters,
positions, offsets of the rings, then the ring of row indices). Python code reads and
writes them by these names; the kernels read the values only Python changes once per call
(:class:`Setup`, :func:`setup`). Also the flags of the kernels (``REVISE``, ``EXACT``,
``DECLARE``; the last ones in ``ints[I_FLAGS]``; ``EXACT`` is settled compiled and never
reaches Python) and the ring accessors shared by them.

The kernels are compiled with ``cache=True`` and numba takes these constants and the
inlined :func:`setup` / :func:`ring_row` into their machine code, but its cache only sees
edits of the kernel's own file: after editing this one, delete the cached kernels
(``rwa_monitor/core/__pycache__/*.nbi``, ``*.nbc``) so they are compiled again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rwa_monitor.core.jit import njit

# Float scalars of ``fs``.
F_LAST_T = 0
F_LOGPMIN = 1
F_YSTAR = 2
F_LOGR = 3
F_MIN_EXC = 4
F_NOISE_VAR = 5
F_MAX_W = 6
F_MAX_F = 7
F_FLOOR_REL = 8
F_FLOOR_ABS = 9
F_Y = 10
F_TR = 11
F_DM = 12
F_PREF = 13   # six prefix sums (A, B, C, U, V, E) of the reference
F_SPEED_A = 19   # noise level a + b |w| floored (llr_common.speed_scale; I_SPEED_MODEL)
F_SPEED_B = 20
F_SPEED_FLOOR = 21
F_SCALARS = 22

# Int scalars of ``ints``.
I_ROWS = 0
I_POS = 1
I_C = 2
I_C_ROW = 3
I_KMIN = 4
I_CHECKPOINT = 5
I_W = 6
I_KVERIF = 7
I_R = 8           # sliding reference length, -1: growing reference
I_L = 9
I_ESTIMATED = 10  # 1: noise variance estimated on the reference
I_AR_ORDER = 11
I_NLAGS = 12
I_ILL = 13        # tests skipped for an ill-conditioned Pi_P
I_K = 14          # candidate of the last EXACT flag
I_DOF = 15        # its degrees of freedom (-1: known noise)
I_O_RPREF = 16
I_O_RTERM = 17
I_O_RTIME = 18
I_O_AR = 19
I_O_LAGS = 20
I_NON_FINITE = 21      # rejected samples by the first check they fail
I_OUT_OF_RANGE = 22
I_NON_INCREASING = 23
I_SPEED_MODEL = 24    # 1: samples divided by the modelled noise level before the sums
I_FLAGS = 25          # flags of the sample where llr_kernel.run stopped
I_O_RSPEED = 26
I_SCALARS = 27

# Flags returned by llr_kernel's step / ingest / test (0: nothing to do, the usual case).
REVISE = 2    # the position is a revision point of the last declared change
EXACT = 4     # the exact tail is needed at candidate ints[I_K] (y, tr, dm in fs)
DECLARE = 8   # Algorithm 1 line 18: declare


def take_flags(ints: np.ndarray) -> int:
    """Return the flags a loop over arrays stopped at, and clear them (0 between calls)."""
    flags = int(ints[I_FLAGS])
    ints[I_FLAGS] = 0
    return flags


def allocate(length: int, width: int, term_width: int, ar_max: int
             ) -> tuple[np.ndarray, np.ndarray]:
    """Return zeroed ``(fs, ints)`` for a ring of ``length`` and AR order up to ``ar_max``.

    ``width``: prefix-row width; ``term_width``: per-sample ring width (3 for p = 2).
    """
    o_rpref = F_SCALARS
    o_rterm = o_rpref + length * width
    o_rtime = o_rterm + length * term_width
    o_rspeed = o_rtime + length
    o_ar = o_rspeed + length
    o_lags = o_ar + ar_max
    fs = np.zeros(o_lags + 3 * ar_max)
    ints = np.zeros(I_SCALARS + length, dtype=np.int64)
    ints[I_L] = length
    ints[I_O_RPREF] = o_rpref
    ints[I_O_RTERM] = o_rterm
    ints[I_O_RTIME] = o_rtime
    ints[I_O_RSPEED] = o_rspeed
    ints[I_O_AR] = o_ar
    ints[I_O_LAGS] = o_lags
    return fs, ints


class Setup(NamedTuple):
    """The values of the state arrays that only Python changes, read once per call.

    Between two returns of ``llr_kernel.run`` (or within one ``step``) the kernel never
    writes them: read once before the loop, they stay in registers instead of being read
    again after every store into the arrays.
    """

    mask: int          # ring length - 1
    o_rpref: int
    o_rterm: int
    o_rtime: int
    o_rspeed: int
    w: int
    r: int
    c: int
    estimated: int
    ar_order: int
    speed_model: int
    checkpoint: int
    min_exc: float
    ystar: float
    floor_rel: float
    floor_abs: float
    noise_var: float


@njit(cache=True, inline='always')
def setup(fs, ints):
    """Return the :class:`Setup` of the state arrays."""
    return Setup(ints[I_L] - 1, ints[I_O_RPREF], ints[I_O_RTERM], ints[I_O_RTIME],
                 ints[I_O_RSPEED], ints[I_W],
                 ints[I_R], ints[I_C], ints[I_ESTIMATED], ints[I_AR_ORDER],
                 ints[I_SPEED_MODEL], ints[I_CHECKPOINT], fs[F_MIN_EXC], fs[F_YSTAR],
                 fs[F_FLOOR_REL], fs[F_FLOOR_ABS], fs[F_NOISE_VAR])


# Ring offsets and array positions are never negative; masking the sign bit tells the
# compiler so, and spares each ring access numba's fix-up of negative indices (its
# instructions were an eighth of the per-sample loop).
NON_NEGATIVE = (1 << 63) - 1


@njit(cache=True, inline='always')
def ring_row(fs, o):
    """Return the six floats of ``fs`` from offset ``o`` (a prefix row of the ring)."""
    return (fs[(o + 0) & NON_NEGATIVE], fs[(o + 1) & NON_NEGATIVE], fs[(o + 2) & NON_NEGATIVE],
            fs[(o + 3) & NON_NEGATIVE], fs[(o + 4) & NON_NEGATIVE], fs[(o + 5) & NON_NEGATIVE])
