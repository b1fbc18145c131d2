"""Compiled per-sample path of the streaming LLR detector, paper's model (1) (p = 2).

One call per sample (:func:`step`: acceptance, regressors, AR prewhitening, prefix sums,
ring, the test of Algorithm 1 lines 9-18 with eq. (5)) on the detector's state, held in
two preallocated arrays (:func:`allocate`): ``fs`` (floats: scalars, then the rings of
prefix rows, terms and times, the AR coefficients and lags) and ``ints`` (counters,
positions, then the ring of row indices). The exact tail of eq. (7) (rare: a sample whose
skip bound does not rule it out) and all categorisation stay in Python: the kernel returns
flags and leaves ``y``, ``tr``, ``dm`` in ``fs``.

Compiled by :mod:`rwa_monitor.core.jit` (numba, no fast-math: the same IEEE operations in
the same order as the batch path and the golden files; docs/llr.md "Compiled per-sample
path"); plain Python functions when numba is absent or disabled.
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core.gchi2 import log_lower_bound
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
F_SCALARS = 19

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
I_NONFINITE = 21      # rejected samples by the first check they fail
I_OUT_OF_RANGE = 22
I_NON_INCREASING = 23
I_SCALARS = 24

# A candidate goes to the exact tail only if its lower bound of log p_k is within this
# relative margin above p_min (candidate_log_p2 tests 1e-9; rounding is ~1e-15).
SKIP_REL = 1e-7

# Flags returned by step / ingest / test (0: nothing to do, the usual case).
REVISE = 2    # the position is a revision point of the last declared change
EXACT = 4     # the exact tail is needed at candidate ints[I_K] (y, tr, dm in fs)
DECLARE = 8   # Algorithm 1 line 18: declare


def allocate(length: int, width: int, term_width: int, ar_max: int
             ) -> tuple[np.ndarray, np.ndarray]:
    """Return zeroed ``(fs, ints)`` for a ring of ``length`` and AR order up to ``ar_max``.

    ``width``: prefix-row width; ``term_width``: per-sample ring width (3 for p = 2).
    """
    o_rpref = F_SCALARS
    o_rterm = o_rpref + length * width
    o_rtime = o_rterm + length * term_width
    o_ar = o_rtime + length
    o_lags = o_ar + ar_max
    fs = np.zeros(o_lags + 3 * ar_max)
    ints = np.zeros(I_SCALARS + length, dtype=np.int64)
    ints[I_L] = length
    ints[I_O_RPREF] = o_rpref
    ints[I_O_RTERM] = o_rterm
    ints[I_O_RTIME] = o_rtime
    ints[I_O_AR] = o_ar
    ints[I_O_LAGS] = o_lags
    return fs, ints


@njit(cache=True)
def test(fs, ints, k, at, bt, ct, ut, vt):
    """Algorithm 1 lines 9-18 at candidate ``k`` (p = 2); return EXACT, DECLARE or 0.

    ``(at, bt, ct, ut, vt)`` is the prefix row at ``k + w`` (T_k), the one at ``k`` (P_k)
    is in the ring. Statistic: eq. (5) as ``d^T Pi_P d / sigma^2`` with ``d = x_T - x_P =
    Pi_T^-1 (q_W - Pi_W x_P)`` (the window's residual against the reference fit: no
    difference of two nearly equal estimates). Skips (counted) when ``Pi_P`` is
    ill-conditioned. When the skip bound ``y / tr < y*`` (Algorithm 2) does not rule the
    candidate out, returns EXACT with ``y``, ``tr = trace(Pi_T^-1 Pi_W)``, ``dm = det(Pi_T^-1
    Pi_W)`` and the degrees of freedom stored: the caller computes the tail
    (``llr_common.candidate_log_p2``), records a new minimum and decides.
    """
    length = ints[I_L]
    o = ints[I_O_RPREF] + 6 * (k % length)
    a = fs[o]
    b = fs[o + 1]
    c = fs[o + 2]
    u = fs[o + 3]
    v = fs[o + 4]
    e = fs[o + 5]
    r = ints[I_R]
    if r >= 0 and k - r > ints[I_C]:
        # Sliding reference: P_k = [k - R, k - 1] (docs/llr.md, "Slow drifts").
        o = ints[I_O_RPREF] + 6 * ((k - r) % length)
        b0 = fs[o]
        b1 = fs[o + 1]
        b2 = fs[o + 2]
        b3 = fs[o + 3]
        b4 = fs[o + 4]
        b5 = fs[o + 5]
        a, b, c, u, v, e = a - b0, b - b1, c - b2, u - b3, v - b4, e - b5
        at, bt, ct, ut, vt = at - b0, bt - b1, ct - b2, ut - b3, vt - b4
        n_p = r
    else:
        n_p = k - ints[I_C]
    ac = a * c
    det = ac - b * b
    dett = at * ct - bt * bt
    if det > fs[F_MIN_EXC] * ac and dett > 0.0:
        x1 = (c * u - b * v) / det
        x2 = (a * v - b * u) / det
        dof = -1
        if ints[I_ESTIMATED]:
            s2 = (e - (x1 * u + x2 * v)) / (n_p - 2)
            floor = fs[F_FLOOR_REL] * e / n_p + fs[F_FLOOR_ABS]
            if not s2 > floor:
                s2 = floor
            dof = n_p - 2
        else:
            s2 = fs[F_NOISE_VAR]
        aw = at - a
        bw = bt - b
        cw = ct - c
        g1 = (ut - u) - (aw * x1 + bw * x2)
        g2 = (vt - v) - (bw * x1 + cw * x2)
        d1 = (ct * g1 - bt * g2) / dett
        d2 = (at * g2 - bt * g1) / dett
        y = (a * d1 * d1 + 2.0 * b * d1 * d2 + c * d2 * d2) / s2
        tr = (ct * aw - 2.0 * bt * bw + at * cw) / dett
        if tr > 0.0 and y > 0.0 and not y / tr < fs[F_YSTAR]:
            dm = (aw * cw - bw * bw) / dett
            logpmin = fs[F_LOGPMIN]
            if not lower_bound(y, tr, dm, float(dof)) > logpmin + SKIP_REL * (1.0 - logpmin):
                fs[F_Y] = y
                fs[F_TR] = tr
                fs[F_DM] = dm
                ints[I_K] = k
                ints[I_DOF] = dof
                return EXACT
    else:
        ints[I_ILL] += 1
    if fs[F_LOGPMIN] <= fs[F_LOGR] and k > ints[I_KMIN] + ints[I_KVERIF]:
        return DECLARE
    return 0


@njit(cache=True, error_model='numpy')
def lower_bound(y, tr, dm, dof):
    """Return the lower bound of log p_k that ``llr_common.candidate_log_p2`` tests.

    Same formula (eigenvalues of ``Pi_T^-1 Pi_W`` from trace and determinant, clamped;
    Gaussian bound :func:`gchi2.log_lower_bound` or, for ``dof >= 0``, the studentised one):
    equal to it up to rounding, far below the margin SKIP_REL with which it is used.
    """
    half = 0.5 * tr
    lam1 = half + math.sqrt(max(half * half - dm, 0.0))
    lam2 = min(max(dm / lam1, 0.0), lam1)
    b = y / (2.0 * lam1)
    rho = lam2 / lam1
    a = b * (1.0 - rho)
    if dof < 0.0:
        return log_lower_bound(a) - b * rho
    big_a = dof * a / (dof + 2.0 * b)
    return -0.5 * dof * math.log1p(2.0 * b / dof) + big_a + log_lower_bound(big_a)


@njit('float64[::1](float64[::1], float64[::1], float64[::1], float64[::1])', cache=True)
def lower_bounds(y, tr, dm, dof):
    """Return :func:`lower_bound` of each candidate (``dof < 0``: known noise)."""
    out = np.empty(y.size)
    for i in range(y.size):
        out[i] = lower_bound(y[i], tr[i], dm[i], dof[i])
    return out


@njit('int64(float64[::1], int64[::1], int64, float64[::1])', cache=True)
def test_row(fs, ints, k, row):
    """:func:`test` with T_k's prefix row given as an array (a restart's catch-up)."""
    return test(fs, ints, k, row[0], row[1], row[2], row[3], row[4])


@njit('int64(float64[::1], int64[::1], int64, float64, float64, float64, float64)',
      cache=True)
def ingest(fs, ints, row, t, f, h1, h2):
    """Prewhiten an accepted sample, add it to the sums and ring, test; return flags.

    AR filter ``v_l - sum_i a_i v_(l-1-i)`` (missing lags omitted; the operations of
    :func:`llr_common.whiten`), then the six products in the order of ``llr_batch._Terms``.
    """
    order = ints[I_AR_ORDER]
    if order > 0:
        o_ar = ints[I_O_AR]
        o_lag = ints[I_O_LAGS]
        n_lags = ints[I_NLAGS]
        fw = f
        g1 = h1
        g2 = h2
        for i in range(min(n_lags, order)):
            a = fs[o_ar + i]
            fw = fw - a * fs[o_lag + 3 * i]
            g1 = g1 - a * fs[o_lag + 3 * i + 1]
            g2 = g2 - a * fs[o_lag + 3 * i + 2]
        kept = min(n_lags + 1, order)
        for i in range(kept - 1, 0, -1):
            fs[o_lag + 3 * i] = fs[o_lag + 3 * i - 3]
            fs[o_lag + 3 * i + 1] = fs[o_lag + 3 * i - 2]
            fs[o_lag + 3 * i + 2] = fs[o_lag + 3 * i - 1]
        fs[o_lag] = f
        fs[o_lag + 1] = h1
        fs[o_lag + 2] = h2
        ints[I_NLAGS] = kept
        f = fw
        h1 = g1
        h2 = g2
    p0 = fs[F_PREF] + h1 * h1
    p1 = fs[F_PREF + 1] + h1 * h2
    p2 = fs[F_PREF + 2] + h2 * h2
    p3 = fs[F_PREF + 3] + h1 * f
    p4 = fs[F_PREF + 4] + h2 * f
    p5 = fs[F_PREF + 5] + f * f
    fs[F_PREF] = p0
    fs[F_PREF + 1] = p1
    fs[F_PREF + 2] = p2
    fs[F_PREF + 3] = p3
    fs[F_PREF + 4] = p4
    fs[F_PREF + 5] = p5
    j = ints[I_POS]
    ints[I_POS] = j + 1
    if j == 0:
        ints[I_C_ROW] = row
    length = ints[I_L]
    s = j % length
    o = ints[I_O_RTERM] + 3 * s
    fs[o] = h1
    fs[o + 1] = h2
    fs[o + 2] = f
    fs[ints[I_O_RTIME] + s] = t
    ints[I_SCALARS + s] = row
    o = ints[I_O_RPREF] + 6 * ((j + 1) % length)
    fs[o] = p0
    fs[o + 1] = p1
    fs[o + 2] = p2
    fs[o + 3] = p3
    fs[o + 4] = p4
    fs[o + 5] = p5
    flags = REVISE if j == ints[I_CHECKPOINT] else 0
    w = ints[I_W]
    k = j - w + 1
    if k > ints[I_C] + w:
        flags |= test(fs, ints, k, p0, p1, p2, p3, p4)
    return flags


@njit('int64(float64[::1], int64[::1], float64, float64, float64)', cache=True)
def accept(fs, ints, t, w, f):
    """Count the row; return its index if the sample is accepted, else count why and -1.

    Accepted: finite, ``|w| < max_abs_speed``, ``|f| < max_abs_friction``, time after
    the last accepted one; a rejected sample is counted by the first check it fails.
    """
    row = ints[I_ROWS]
    ints[I_ROWS] = row + 1
    max_w = fs[F_MAX_W]
    max_f = fs[F_MAX_F]
    if -max_w < w < max_w and -max_f < f < max_f and fs[F_LAST_T] < t < math.inf:
        return row
    if (t - t) + (w - w) + (f - f) != 0.0:
        ints[I_NONFINITE] += 1
    elif not (-max_w < w < max_w and -max_f < f < max_f):
        ints[I_OUT_OF_RANGE] += 1
    else:
        ints[I_NON_INCREASING] += 1
    return -1


@njit('int64(float64[::1], int64[::1], float64, float64, float64)', cache=True)
def step(fs, ints, t, w, f):
    """Process one sample of model (1): accept, form ``h = (-sign w, -w)``, ingest."""
    row = accept(fs, ints, t, w, f)
    if row < 0:
        return 0
    fs[F_LAST_T] = t
    h1 = -1.0 if w > 0.0 else (1.0 if w < 0.0 else 0.0)
    return ingest(fs, ints, row, t, f, h1, -w)
