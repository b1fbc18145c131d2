"""Prefix sums, fits and quantiles shared by the streaming and the batch LLR detector.

llr-realtime paper, eq. (2) (the least-squares fit of a segment). Both paths hold *prefix
sums* over the reference segment that starts at position ``c``: ``S_j = sum_{l=c}^{j-1}
t_l`` accumulated one sample at a time, where ``t_l`` are the per-sample terms. Two
layouts:

- ``p = 2`` (the paper's model, or any two-column model): ``t = (h1 h1, h1 h2, h2 h2,
  h1 f, h2 f, f f)``, six floats;
- ``p > 2``: ``t = (vec(h^T h), h^T f, f f)``, ``p * p + p + 1`` floats.

Everything that decides an event is computed from those sums with the same operations in
both paths (and, for p = 2, with the same scalar functions), so the two give the same
events bit for bit. The functions here run once per declaration or per revision
checkpoint, never per sample. The kind of a change is named in
:mod:`rwa_monitor.core.llr_kinds` (the step tests) with the after-segment growth
statistics of :mod:`rwa_monitor.core.llr_growth`.
"""

from __future__ import annotations

import math

from typing import Callable

import numpy as np

from rwa_monitor.core.jit import kernel_array
from rwa_monitor.core.scaled_solve import solve_scaled_stack

# Relative floor of the estimated noise variance (std >= 1e-10 x rms friction): a
# noise-free reference gives a huge but finite statistic instead of a division by zero.
NOISE_FLOOR_REL = 1e-20
NOISE_FLOOR_ABS = 1e-300
# The change hypotheses of :func:`change_fits`, in this order (and the confirmed kinds).
KINDS = ('dry', 'viscous', 'both')


def width(p: int) -> int:
    """Return the number of floats in one prefix-sum row for ``p`` regressors."""
    return 6 if p == 2 else p * p + p + 1


def unpack(row: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(Pi, q, E)`` (arrays, leading axes kept) from prefix-sum rows."""
    row = np.asarray(row, dtype=float)
    if p == 2:
        a, b, c, u, v, e = (row[..., i] for i in range(6))
        pi = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
        return pi, np.stack([u, v], -1), e
    pp = p * p
    pi = row[..., :pp].reshape(row.shape[:-1] + (p, p))
    return pi, row[..., pp:pp + p], row[..., pp + p]


def well_conditioned(pi: np.ndarray, min_excitation: float) -> np.ndarray:
    """Return True where ``det(corr(Pi)) > min_excitation`` (dry and viscous separable).

    For p = 2 this is ``(A C - B^2) > min_excitation * A C``, the test of the streaming
    path. For p > 2 the determinant of the correlation-normalised matrix.
    """
    pi = np.asarray(pi, dtype=float)
    diag = np.diagonal(pi, axis1=-2, axis2=-1)
    if pi.shape[-1] == 2:
        ac = pi[..., 0, 0] * pi[..., 1, 1]
        det = ac - pi[..., 0, 1] * pi[..., 0, 1]
        return det > min_excitation * ac
    ok = np.all(diag > 0.0, axis=-1)
    scale = 1.0 / np.sqrt(np.where(diag > 0.0, diag, 1.0))
    corr = pi * scale[..., :, None] * scale[..., None, :]
    with np.errstate(all='ignore'):
        det = np.linalg.det(corr)
    return ok & (det > min_excitation)


def segment_fit(row: np.ndarray, n: int, p: int, noise_var: float | None
                ) -> tuple[np.ndarray, np.ndarray, float]:
    """Return ``(x, Pi, sigma^2)`` of the least-squares fit (eq. (2)) of one segment.

    ``sigma^2`` is ``noise_var`` when given, else the residual variance ``RSS / (n - p)``
    floored at :data:`NOISE_FLOOR_REL` x mean square friction.
    """
    pi, q, e = unpack(row, p)
    x = np.linalg.solve(pi, q)
    if noise_var is not None:
        return x, pi, float(noise_var)
    rss = float(e) - float(x @ q)
    s2 = rss / (n - p)
    floor = NOISE_FLOOR_REL * float(e) / n + NOISE_FLOOR_ABS
    return x, pi, s2 if s2 > floor else floor


def before_noise_var(before: np.ndarray, n_before: int, p: int) -> float:
    """Return ``sigma^2`` of the before segment's own fit (eq. (2)), floored.

    ``RSS / (n_before - p)``, at least :data:`NOISE_FLOOR_REL` x its mean square friction:
    the noise variance of the categorisation and continuation tests when none is given.
    """
    pi_b, q_b, e_b = unpack(before, p)
    rss = float(e_b) - float(solve_scaled(pi_b, q_b) @ q_b)
    floor = NOISE_FLOOR_REL * float(e_b) / n_before + NOISE_FLOOR_ABS
    return max(rss / (n_before - p), floor)


def solve_scaled(m: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Return ``m^+ r`` for stacked symmetric matrices (Jacobi-scaled pseudo-inverse).

    Scaling by the diagonal first makes the cut-off relative to the correlation matrix;
    an exactly collinear segment (constant speed, wheel at rest) gets the minimum-norm
    solution, whose fitted values (and so residual) are still the least-squares ones.
    Compiled, for any leading axes (core/scaled_solve.py); NaN where ``m`` or ``r`` is
    not finite.
    """
    m, r = np.asarray(m, dtype=float), np.asarray(r, dtype=float)
    n = m.shape[-1]
    lead = np.broadcast_shapes(m.shape[:-2], r.shape[:-1])
    x = solve_scaled_stack(kernel_array(np.broadcast_to(m, lead + (n, n)).reshape(-1, n, n)),
                           kernel_array(np.broadcast_to(r, lead + (n,)).reshape(-1, n)))
    return x.reshape(lead + (n,))


def explained_sum(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Return ``theta . v`` of the least-squares fits ``m theta = v`` (stacked)."""
    return np.einsum('...i,...i->...', solve_scaled(m, v), v)


def submatrix(m: np.ndarray, cols: list[int]) -> np.ndarray:
    """Return the rows and columns ``cols`` of stacked square matrices."""
    return m[..., cols, :][..., :, cols]


def change_fits(before: np.ndarray, after: np.ndarray, p: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(explained, dx)`` of the three change hypotheses dry, viscous, both.

    Not in the paper (categorisation, docs/llr.md). One least-squares fit of the before
    segment (sums ``before``) and the after segment (``after``) together, with ``x``
    before and ``x + dx`` after: ``dx = a e_0`` (dry only), ``dx = a e_1`` (viscous only)
    or ``dx`` free (both: two separate fits). The reference estimate and its covariance
    enter exactly through the joint fit. ``explained[..., h] = theta . r``, so that
    ``RSS_h = E_before + E_after - explained_h`` (differences between hypotheses never
    subtract the large ``E``); ``dx[..., h, :]`` is the estimated change. Leading axes are
    kept (vectorised over candidate change positions).
    """
    pi_b, q_b, _ = unpack(before, p)
    pi_a, q_a, _ = unpack(after, p)
    lead = pi_b.shape[:-2]
    x_b = solve_scaled(pi_b, q_b)
    x_a = solve_scaled(pi_a, q_a)
    explained = np.empty(lead + (3,))
    dx = np.zeros(lead + (3, p))
    explained[..., 2] = (np.einsum('...i,...i->...', x_b, q_b)
                         + np.einsum('...i,...i->...', x_a, q_a))
    dx[..., 2, :] = x_a - x_b
    m = np.empty(lead + (p + 1, p + 1))
    m[..., :p, :p] = pi_b + pi_a
    r = np.empty(lead + (p + 1,))
    r[..., :p] = q_b + q_a
    for i in (0, 1):
        m[..., :p, p] = pi_a[..., :, i]
        m[..., p, :p] = pi_a[..., i, :]
        m[..., p, p] = pi_a[..., i, i]
        r[..., p] = q_a[..., i]
        theta = solve_scaled(m, r)
        explained[..., i] = np.einsum('...i,...i->...', theta, r)
        dx[..., i, i] = theta[..., p]
    return explained, dx


def refine_change(prefix: np.ndarray, first: int, c: int, n: int, lo: int, hi: int, p: int,
                  noise_var: float | None, z_threshold: float, fallback: int,
                  log_prior: Callable[[np.ndarray], np.ndarray] | None = None) -> int:
    """Return the maximum-likelihood single change position in ``[lo, hi]``.

    Not in the paper: after a declaration, the data of the reference segment ``[c, n]``
    (old reference, window and verification samples) are split at every ``tau`` in ``[lo,
    hi]`` into ``[c, tau)`` and ``[tau, n]`` and fitted jointly under each change
    hypothesis of :func:`change_fits` (dry only, viscous only, both). Each hypothesis has
    its ML position (largest explained sum); ``both`` is kept only if it beats the better
    single-component hypothesis by more than ``z_threshold^2 sigma^2`` (nested test,
    ``sigma^2`` the residual variance of the best ``both`` split, or ``noise_var``).
    Constraining the change matters when the after segment spans few speeds: a free
    after-fit then absorbs pre-change samples (two speed levels are fitted exactly by two
    parameters) and the position is not identifiable. ``prefix[i]`` is the prefix-sum row
    (from ``c``) at position ``first + i`` and must cover ``[lo, n + 1]``. O(hi - lo) once
    per declaration; ``fallback`` (the argmin of p_k) is returned when no split exists.

    ``log_prior(taus)``: a log prior of each position, added to its log-likelihood
    ``explained / (2 sigma^2)`` once the hypothesis is chosen (maximum a posteriori). The
    detector gives the log of the time between a position's sample and the one before:
    a change equally likely at any time, so a split across a gap of hours, which holds
    that much more time, is preferred unless the data favour another split by as much
    (docs/llr.md "Changes in a gap"); with evenly spaced samples the position is the ML one.
    """
    lo = max(lo, c + p + 1)
    hi = min(hi, n - p)
    if hi < lo:
        return fallback
    taus = np.arange(lo, hi + 1)
    before = prefix[taus - first]
    total = prefix[n + 1 - first]
    explained, _ = change_fits(before, total[None, :] - before, p)
    explained = np.where(np.isfinite(explained), explained, -np.inf)
    best = np.argmax(explained, axis=0)
    top = explained[best, np.arange(3)]
    if not np.all(np.isfinite(top)):
        return fallback
    if noise_var is None:
        e_total = float(unpack(total, p)[2])
        noise_var = max((e_total - float(top[2])) / (n + 1 - c - 2 * p),
                        NOISE_FLOOR_REL * e_total / (n + 1 - c) + NOISE_FLOOR_ABS)
    single = 0 if top[0] >= top[1] else 1
    h = 2 if (top[2] - top[single]) / noise_var > z_threshold * z_threshold else single
    if log_prior is None:
        return int(taus[int(best[h])])
    return int(taus[int(np.argmax(explained[:, h] / (2.0 * noise_var) + log_prior(taus)))])


def z_threshold(level: float) -> float:
    """Return the two-sided normal quantile ``z`` with ``P(|Z| > z) = level``."""
    from scipy import special
    return float(math.sqrt(2.0) * special.erfcinv(level))


def level_of(z_threshold: float) -> float:
    """Return the level ``P(|Z| > z_threshold)`` whose two-sided normal quantile is given."""
    return math.erfc(z_threshold / math.sqrt(2.0))


def chi2_upper(dof: int, level: float) -> float:
    """Return the upper ``level`` quantile of the chi-square law with ``dof`` degrees."""
    from scipy import special
    return float(special.chdtri(dof, level))
