"""Statistics shared by the streaming and the batch LLR detector (llr-realtime paper).

Both paths hold *prefix sums* over the reference segment that starts at position ``c``:
``S_j = sum_{l=c}^{j-1} t_l`` accumulated one sample at a time, where ``t_l`` are the
per-sample terms. Two layouts:

- ``p = 2`` (the paper's model, or any two-column model): ``t = (h1 h1, h1 h2, h2 h2,
  h1 f, h2 f, f f)``, six floats;
- ``p > 2``: ``t = (vec(h^T h), h^T f, f f)``, ``p * p + p + 1`` floats.

Everything that decides an event is computed from those sums with the same operations in
both paths (and, for p = 2, with the same scalar functions), so the two give the same
events bit for bit. The functions here run once per declaration or per revision
checkpoint, never per sample.
"""

from __future__ import annotations

import math

import numpy as np

# Relative floor of the estimated noise variance (std >= 1e-10 x rms friction): a
# noise-free reference gives a huge but finite statistic instead of a division by zero.
NOISE_FLOOR_REL = 1e-20
NOISE_FLOOR_ABS = 1e-300
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


def categorise(before: np.ndarray, n_before: int, after: np.ndarray, n_after: int, p: int,
               noise_var: float | None, z_threshold: float, min_excitation: float
               ) -> tuple[str, np.ndarray, tuple[float, float], float]:
    """Return ``(kind, x_after - x_before, (z_dry, z_viscous), sigma^2)`` for one change.

    Not in the paper (which promises a categorisation but gives none); the design is in
    docs/llr.md. ``dx = x_after - x_before`` has covariance ``sigma^2 (Pi_before^-1 +
    Pi_after^-1)`` (independent segments, noise variance from the reference fit before the
    change). ``z_i = dx_i / sd_i`` for i = dry, viscous. The dry-only model (``dx_viscous =
    0``) is rejected when ``|z_viscous| > z_threshold`` and the viscous-only model when
    ``|z_dry| > z_threshold`` (two-sided marginal tests at ``category_level``):
    both rejected -> ``both``; one rejected -> the other kind; none rejected -> the kind
    with the larger ``|z|`` (the single-component model that fits better). An
    after-segment that cannot separate dry from viscous (speed barely varying) gives
    ``both`` with the joint estimate undetermined (z = nan).
    """
    x_b, pi_b, s2 = segment_fit(before, n_before, p, noise_var)
    pi_a, q_a, _ = unpack(after, p)
    if not bool(well_conditioned(pi_a, min_excitation)):
        nan = float('nan')
        return 'both', np.full(p, nan), (nan, nan), s2
    x_a = np.linalg.solve(pi_a, q_a)
    dx = x_a - x_b
    cov = s2 * (np.linalg.inv(pi_b) + np.linalg.inv(pi_a))
    z_d = float(dx[0] / math.sqrt(cov[0, 0]))
    z_v = float(dx[1] / math.sqrt(cov[1, 1]))
    sig_d = abs(z_d) > z_threshold
    sig_v = abs(z_v) > z_threshold
    if sig_d and sig_v:
        kind = 'both'
    elif sig_d or sig_v:
        kind = 'dry' if sig_d else 'viscous'
    else:
        kind = 'dry' if abs(z_d) >= abs(z_v) else 'viscous'
    return kind, dx, (z_d, z_v), s2


def segment_rss(rows: np.ndarray, counts: np.ndarray, p: int, min_excitation: float
                ) -> np.ndarray:
    """Return the least-squares residual sum of squares of each segment (inf if singular)."""
    pi, q, e = unpack(rows, p)
    ok = well_conditioned(pi, min_excitation) & (counts > p)
    out = np.full(rows.shape[0], np.inf)
    if np.any(ok):
        x = np.linalg.solve(pi[ok], q[ok][..., None])[..., 0]
        out[ok] = e[ok] - np.einsum('ij,ij->i', x, q[ok])
    return out


def refine_change(prefix: np.ndarray, first: int, c: int, n: int, lo: int, hi: int, p: int,
                  min_excitation: float, fallback: int) -> int:
    """Return the maximum-likelihood single change position in ``[lo, hi]``.

    Not in the paper: after a declaration, the data of the reference segment ``[c, n]``
    (old reference, window and verification samples) are split at every ``tau`` in ``[lo,
    hi]`` into ``[c, tau)`` and ``[tau, n]``, each fitted by least squares; the split with
    the smallest total residual is the maximum-likelihood change point under one change
    and Gaussian noise of common variance. ``prefix[i]`` is the prefix-sum row at position
    ``first + i`` and must cover ``[lo, n + 1]``. O(hi - lo) once per declaration;
    ``fallback`` (the argmin of p_k) is returned when no split is identifiable.
    """
    lo = max(lo, c + p + 1)
    hi = min(hi, n - p)
    if hi < lo:
        return fallback
    taus = np.arange(lo, hi + 1)
    before = prefix[taus - first]
    total = prefix[n + 1 - first]
    after = total[None, :] - before
    rss = (segment_rss(before, taus - c, p, min_excitation)
           + segment_rss(after, n + 1 - taus, p, min_excitation))
    if not np.any(np.isfinite(rss)):
        return fallback
    return int(taus[int(np.argmin(rss))])


def z_threshold(level: float) -> float:
    """Return the two-sided normal quantile ``z`` with ``P(|Z| > z) = level``."""
    from scipy import special
    return float(math.sqrt(2.0) * special.erfcinv(level))
