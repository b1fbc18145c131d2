"""Compiled per-sample path of the LLR detector, paper's model (1) (p = 2).

One sample (:func:`sample`: acceptance, regressors, noise level growing with speed, AR
prewhitening, prefix sums, ring, the test of Algorithm 1 lines 9-18 with eq. (5)) on the
detector's two state arrays (their layout: core/llr_layout.py). Entry points: :func:`step`
(one sample from Python, the streaming path), :func:`run` (the same over whole arrays,
loop compiled, the batch path), :func:`accept_run` (the samples waiting for the noise
fit), :func:`ingest_run` (their replay once it is fitted), :func:`ingest` and
:func:`test_row` (one replayed sample, one test of a restart's catch-up). The values only
Python changes are read once per call (``llr_layout.Setup``). They return flags at the
rare samples that need Python: a declaration, a revision point; categorisation and
declarations are core/llr_changes.py. The exact tail of eq. (7), where the skip bounds do
not rule a candidate out, is computed compiled too (:func:`settle`), outside the
per-sample loop. The calibrated path (nominal lookup, then :func:`sample`) is
core/llr_calibrated_step.py.

Compiled by :mod:`rwa_monitor.core.jit` (numba, no fast-math: the same IEEE operations in
the same order whatever the caller; docs/architecture.md "Compiled kernels"), the
per-sample functions inlined into the entry points; plain Python functions when numba is
absent or disabled. The loops over arrays (:func:`run`, :func:`accept_run`,
:func:`ingest_run`) are compiled without numba's reference counting (``_nrt=False``, an
option of numba's own): they allocate nothing, and the atomic counts of the arrays handed
to the inlined functions, which its pruning leaves in a loop with branches, were a third
of the loop's time.
"""

from __future__ import annotations

import math

from rwa_monitor.core.gchi2 import skip_threshold
from rwa_monitor.core.jit import njit
from rwa_monitor.core.llr_layout import (
    DECLARE, EXACT, F_DM, F_LAST_T, F_LOGPMIN, F_LOGR, F_MAX_F, F_MAX_W, F_PREF, F_SPEED_A,
    F_SPEED_B, F_SPEED_FLOOR, F_TR, F_Y, F_YSTAR, I_C_ROW, I_DOF, I_FLAGS, I_ILL, I_K,
    I_KMIN, I_KVERIF, I_L, I_NLAGS, I_NON_FINITE, I_NON_INCREASING, I_O_AR, I_O_LAGS,
    I_O_RTIME, I_OUT_OF_RANGE, I_POS, I_ROWS, I_SCALARS, NON_NEGATIVE, REVISE, ring_row,
    setup)
from rwa_monitor.core.llr_skip import below_skip, exact_log_p2, lower_bound, SKIP_REL

# The AR filter runs over consecutive samples (docs/llr.md "Noise beyond white", *Breaks*):
# its memory is cleared when an accepted sample does not follow the previous one, that is
# when a sample between them was rejected, or when the time step grows more than this
# factor over the step before it (a gap: between passes, between joined records).
GAP_FACTOR = 4.0


@njit(cache=True, error_model='numpy', inline='always')
def test(fs, ints, cfg, k, at, bt, ct, ut, vt):
    """Algorithm 1 lines 9-18 at candidate ``k`` (p = 2); return EXACT, DECLARE or 0.

    ``(at, bt, ct, ut, vt)`` is the prefix row at ``k + w`` (T_k), the one at ``k`` (P_k)
    is in the ring. Statistic: eq. (5) as ``d^T Pi_P d / sigma^2`` with ``d = x_T - x_P =
    Pi_T^-1 (q_W - Pi_W x_P)`` (the window's residual against the reference fit: no
    difference of two nearly equal estimates). Skips (counted) when ``Pi_P`` is
    ill-conditioned. When the skip bound ``y / tr < y*`` (Algorithm 2) does not rule the
    candidate out, returns EXACT with ``y``, ``tr = trace(Pi_T^-1 Pi_W)``, ``dm = det(Pi_T^-1
    Pi_W)`` and the degrees of freedom stored: :func:`settle` computes the tail, records a
    new minimum and decides.
    """
    o = cfg.o_rpref + 6 * (k & cfg.mask)
    a, b, c, u, v, e = ring_row(fs, o)
    r = cfg.r
    if r >= 0 and k - r > cfg.c:
        # Sliding reference: P_k = [k - R, k - 1] (docs/llr.md, "Slow drifts").
        o = cfg.o_rpref + 6 * ((k - r) & cfg.mask)
        b0, b1, b2, b3, b4, b5 = ring_row(fs, o)
        a, b, c, u, v, e = a - b0, b - b1, c - b2, u - b3, v - b4, e - b5
        at, bt, ct, ut, vt = at - b0, bt - b1, ct - b2, ut - b3, vt - b4
        n_p = r
    else:
        n_p = k - cfg.c
    ac = a * c
    det = ac - b * b
    dett = at * ct - bt * bt
    if det > cfg.min_exc * ac and dett > 0.0:
        x1 = (c * u - b * v) / det
        x2 = (a * v - b * u) / det
        aw = at - a
        bw = bt - b
        cw = ct - c
        g1 = (ut - u) - (aw * x1 + bw * x2)
        g2 = (vt - v) - (bw * x1 + cw * x2)
        d1 = (ct * g1 - bt * g2) / dett
        d2 = (at * g2 - bt * g1) / dett
        q = a * d1 * d1 + 2.0 * b * d1 * d2 + c * d2 * d2    # y = q / s2
        tn = ct * aw - 2.0 * bt * bw + at * cw             # tr = tn / dett
        if cfg.estimated:
            rss = e - (x1 * u + x2 * v)                     # s2 >= rss / (n_p - 2)
            if below_skip(q, dett, float(n_p - 2), rss, tn, cfg.ystar):
                return declare_flag(fs, ints, k)
            s2 = rss / (n_p - 2)
            floor = cfg.floor_rel * e / n_p + cfg.floor_abs
            if not s2 > floor:
                s2 = floor
            dof = n_p - 2
        else:
            s2 = cfg.noise_var
            if below_skip(q, dett, 1.0, s2, tn, cfg.ystar):
                return declare_flag(fs, ints, k)
            dof = -1
        y = q / s2
        tr = tn / dett
        if tr > 0.0 and y > 0.0 and not y / tr < cfg.ystar:
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
    return declare_flag(fs, ints, k)


@njit(cache=True, inline='always')
def settle(fs, ints, flags):
    """Return ``flags`` with EXACT resolved: Algorithm 1 lines 12-18 at candidate ``ints[I_K]``.

    The exact tail of eq. (7) from the ``y``, ``tr``, ``dm`` and degrees of freedom
    :func:`test` stored (core/llr_skip.py ``exact_log_p2``, which Python's
    ``llr_common.candidate_log_p2`` calls too); a tail below p_min is the new minimum,
    with its skip threshold (lines 13-15); then DECLARE if line 18 holds. Called where the
    flags leave a sample, not inside :func:`test`: the per-sample loops stay without a
    call (a call in them made ``detect`` 1.5x slower), and they stop at an EXACT so
    that they go on with the new skip threshold (``Setup.ystar`` is read once per call).
    """
    if not flags & EXACT:
        return flags
    k = ints[I_K]
    logpmin = fs[F_LOGPMIN]
    logp = exact_log_p2(fs[F_Y], fs[F_TR], fs[F_DM], logpmin, float(ints[I_DOF]))
    if logp < logpmin:
        fs[F_LOGPMIN] = logp
        ints[I_KMIN] = k
        fs[F_YSTAR] = skip_threshold(logp)
    return (flags & ~EXACT) | declare_flag(fs, ints, k)


@njit(cache=True, inline='always')
def declare_flag(fs, ints, k):
    """Return DECLARE if p_min is at or below r and ``k`` past the verification, else 0."""
    if fs[F_LOGPMIN] <= fs[F_LOGR] and k > ints[I_KMIN] + ints[I_KVERIF]:
        return DECLARE
    return 0


@njit('int64(float64[::1], int64[::1], int64, float64[::1])', cache=True)
def test_row(fs, ints, k, row):
    """:func:`test` with T_k's prefix row given as an array (a restart's catch-up)."""
    return settle(fs, ints, test(fs, ints, setup(fs, ints), k, row[0], row[1], row[2], row[3],
                                 row[4]))


@njit(cache=True, error_model='numpy', inline='always')
def ingest(fs, ints, row, t, f, h1, h2):
    """:func:`ingest_sample` called from Python (the samples replayed after the noise fit)."""
    return settle(fs, ints, ingest_sample(fs, ints, setup(fs, ints), row, t, f, h1, h2))


@njit(cache=True, error_model='numpy', inline='always')
def ingest_sample(fs, ints, cfg, row, t, f, h1, h2):
    """Prewhiten an accepted sample, add it to the sums and ring, test; return flags.

    AR filter ``v_l - sum_i a_i v_(l-1-i)`` (missing lags omitted; the operations of
    :func:`llr_common.whiten`), then the six products in the order of ``llr_batch._Terms``.
    The ring of speeds keeps ``|w| = h2 / h1`` of the regressors before the filter (the
    same for a noise level dividing both; 0 at rest), for the kind rules' speed order
    (core/llr_kinds.py ``speed_ordered``).
    """
    speed = h2 / h1 if h1 != 0.0 else 0.0
    order = cfg.ar_order
    if order > 0:
        o_ar = ints[I_O_AR]
        o_lag = ints[I_O_LAGS]
        n_lags = ints[I_NLAGS]
        if n_lags > 0 and breaks(fs, ints, ints[I_POS], row, t):
            n_lags = 0
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
    s = j & cfg.mask
    o = cfg.o_rterm + 3 * s
    fs[(o + 0) & NON_NEGATIVE] = h1
    fs[(o + 1) & NON_NEGATIVE] = h2
    fs[(o + 2) & NON_NEGATIVE] = f
    fs[(cfg.o_rtime + s) & NON_NEGATIVE] = t
    fs[(cfg.o_rspeed + s) & NON_NEGATIVE] = speed
    ints[(I_SCALARS + s) & NON_NEGATIVE] = row
    o = cfg.o_rpref + 6 * ((j + 1) & cfg.mask)
    fs[(o + 0) & NON_NEGATIVE] = p0
    fs[(o + 1) & NON_NEGATIVE] = p1
    fs[(o + 2) & NON_NEGATIVE] = p2
    fs[(o + 3) & NON_NEGATIVE] = p3
    fs[(o + 4) & NON_NEGATIVE] = p4
    fs[(o + 5) & NON_NEGATIVE] = p5
    flags = REVISE if j == cfg.checkpoint else 0
    w = cfg.w
    k = j - w + 1
    if k > cfg.c + w:
        flags |= test(fs, ints, cfg, k, p0, p1, p2, p3, p4)
    return flags


@njit(cache=True, inline='always')
def breaks(fs, ints, j, row, t):
    """Return True if the sample (``row``, time ``t``) at position ``j`` breaks the sequence.

    Not in the paper, whose noise model is a stationary sequence without gaps. Compared
    with the accepted samples at positions ``j - 1`` and ``j - 2`` in the ring: a row
    index that is not the next one (a sample between them was rejected: not finite, out
    of range, or outside the calibrated speeds), or a time step more than
    :data:`GAP_FACTOR` times the previous one. Then the AR filter's memory holds samples
    whose noise is not the one this sample's lags describe, and a level that changed
    across the gap would leak into the whitened regressors of the first samples after it.
    """
    if j < 1:
        return False
    mask = ints[I_L] - 1
    o_time = ints[I_O_RTIME]
    prev = (j - 1) & mask
    if ints[(I_SCALARS + prev) & NON_NEGATIVE] != row - 1:
        return True
    if j < 2:
        return False
    t1 = fs[(o_time + prev) & NON_NEGATIVE]
    t2 = fs[(o_time + ((j - 2) & mask)) & NON_NEGATIVE]
    return t - t1 > GAP_FACTOR * (t1 - t2)


@njit('boolean(float64[::1], int64[::1], int64, int64, float64)', cache=True)
def sequence_breaks(fs, ints, j, row, t):
    """:func:`breaks` called from Python (the p > 2 path's AR filter)."""
    return breaks(fs, ints, j, row, t)


@njit(cache=True, inline='always')
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
        ints[I_NON_FINITE] += 1
    elif not (-max_w < w < max_w and -max_f < f < max_f):
        ints[I_OUT_OF_RANGE] += 1
    else:
        ints[I_NON_INCREASING] += 1
    return -1


@njit(cache=True, error_model='numpy', inline='always')
def sample(fs, ints, cfg, t, w, f):
    """Process one sample of model (1): accept, form ``h = (-sign w, -w)``, ingest.

    With a noise level growing with speed (``ints[I_SPEED_MODEL]``), ``h`` and ``f`` are
    first divided by ``max(a + b |w|, floor)`` (:func:`llr_common.speed_scale`).
    """
    row = accept(fs, ints, t, w, f)
    if row < 0:
        return 0
    fs[F_LAST_T] = t
    h1 = -1.0 if w > 0.0 else (1.0 if w < 0.0 else 0.0)
    h2 = -w
    if cfg.speed_model:
        level = fs[F_SPEED_A] + fs[F_SPEED_B] * abs(w)
        if not level > fs[F_SPEED_FLOOR]:
            level = fs[F_SPEED_FLOOR]
        f = f / level
        h1 = h1 / level
        h2 = h2 / level
    return ingest_sample(fs, ints, cfg, row, t, f, h1, h2)


@njit('int64(float64[::1], int64[::1], float64, float64, float64)', cache=True)
def step(fs, ints, t, w, f):
    """:func:`sample` called from Python: the streaming path, one call per sample."""
    return settle(fs, ints, sample(fs, ints, setup(fs, ints), t, w, f))


@njit('int64(float64[::1], int64[::1], float64[::1], float64[::1], float64[::1], int64)',
      cache=True, _nrt=False)
def run(fs, ints, t, w, f, start):
    """:func:`step` over the samples ``start, start + 1, ...`` of whole arrays.

    Returns the index of the first sample whose flags are not 0 (the flags in
    ``ints[I_FLAGS]``: the caller acts on them, then resumes at the next index), or the
    array length when all were processed. The batch path: the per-sample loop of the
    streaming detector, compiled, with Python only at those rare samples; an exact tail
    is settled here (:func:`settle`) and the loop goes on.
    """
    i = start & NON_NEGATIVE
    while i < t.size:
        i = _samples(fs, ints, setup(fs, ints), t, w, f, i)
        if _stops(fs, ints, i, t.size):
            return i
        i += 1
    return t.size


@njit(cache=True, inline='always')
def _stops(fs, ints, i, size):
    """Return True where a loop over arrays returns at ``i``: the end, or flags to act on.

    Flags are in ``ints[I_FLAGS]``; an EXACT among them is settled first (:func:`settle`).
    """
    if i >= size:
        return True
    flags = settle(fs, ints, ints[I_FLAGS])
    ints[I_FLAGS] = flags
    return flags != 0


@njit(cache=True, inline='always')
def _samples(fs, ints, cfg, t, w, f, start):
    """:func:`sample` from ``start`` on: the first index with flags (in ``ints[I_FLAGS]``)."""
    for i in range(start, t.size):
        flags = sample(fs, ints, cfg, t[i], w[i], f[i])
        if flags:
            ints[I_FLAGS] = flags
            return i
    return t.size


@njit('int64(float64[::1], int64[::1], float64[::1], float64[::1], float64[::1], int64, '
      'int64[::1])', cache=True, _nrt=False)
def accept_run(fs, ints, t, w, f, start, rows):
    """:func:`accept` over the samples ``start, start + 1, ...`` until ``rows`` is full.

    Writes the row index of each accepted sample into ``rows`` (the rest stays as it was)
    and returns the index of the next sample: the samples that wait for the noise fit,
    taken as the streaming path takes them one by one.
    """
    m = 0
    i = start
    while i < t.size and m < rows.size:
        row = accept(fs, ints, t[i], w[i], f[i])
        if row >= 0:
            fs[F_LAST_T] = t[i]
            rows[m] = row
            m += 1
        i += 1
    return i


@njit('int64(float64[::1], int64[::1], int64[::1], float64[::1], float64[::1], float64[::1], '
      'float64[::1], int64)', cache=True, _nrt=False)
def ingest_run(fs, ints, rows, t, f, h1, h2, start):
    """:func:`ingest` over accepted samples ``start, start + 1, ...`` given as arrays.

    The replay of the samples that waited for the noise fit (already divided by the noise
    level); returns as :func:`run` does (flags in ``ints[I_FLAGS]``).
    """
    i = start & NON_NEGATIVE
    while i < t.size:
        i = _ingested(fs, ints, setup(fs, ints), rows, t, f, h1, h2, i)
        if _stops(fs, ints, i, t.size):
            return i
        i += 1
    return t.size


@njit(cache=True, inline='always')
def _ingested(fs, ints, cfg, rows, t, f, h1, h2, start):
    """:func:`ingest_sample` from ``start`` on: as :func:`_samples`."""
    for i in range(start, t.size):
        flags = ingest_sample(fs, ints, cfg, rows[i], t[i], f[i], h1[i], h2[i])
        if flags:
            ints[I_FLAGS] = flags
            return i
    return t.size
