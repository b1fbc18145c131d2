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
from typing import NamedTuple

import numpy as np

# Relative floor of the estimated noise variance (std >= 1e-10 x rms friction): a
# noise-free reference gives a huge but finite statistic instead of a division by zero.
NOISE_FLOOR_REL = 1e-20
NOISE_FLOOR_ABS = 1e-300
KINDS = ('dry', 'viscous', 'both')
# The data cannot tell dry from viscous (docs/llr.md "Categorisation"): an event kind.
UNDECIDED = 'undecided'
# A single-component kind is confirmed only if the other component is not significant
# even at 5 % (two-sided): between this and the category level the data are ambiguous.
Z_ABSENT = 1.959963984540054
POWER_Z = 1.2815515655446004   # one-sided normal quantile of 0.9 (detectable steps)


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


def solve_scaled(m: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Return ``m^+ r`` for stacked symmetric matrices (Jacobi-scaled pseudo-inverse).

    Scaling by the diagonal first makes the cut-off relative to the correlation matrix;
    an exactly collinear segment (constant speed, wheel at rest) gets the minimum-norm
    solution, whose fitted values (and so residual) are still the least-squares ones.
    """
    diag = np.diagonal(m, axis1=-2, axis2=-1)
    d = np.sqrt(np.where(diag > 0.0, diag, 1.0))
    ms = m / (d[..., :, None] * d[..., None, :])
    with np.errstate(all='ignore'):
        inv = np.linalg.pinv(ms, rcond=1e-13, hermitian=True)
    return np.einsum('...ij,...j->...i', inv, r / d) / d


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


class Category(NamedTuple):
    """Kind of one change, its estimate, the component z values and the noise variance.

    ``kind`` is ``undecided`` when the data cannot tell dry from viscous; ``guess`` is then
    the single-component kind that fits better (else ``guess == kind``); ``dx`` is the
    estimate under ``guess``. ``detectable`` = smallest dry step (N m) and viscous step
    (N m s) the after segment would reveal with 90 % power at the category level.
    """

    kind: str
    dx: np.ndarray
    z: tuple[float, float]
    noise_var: float
    confirmed: bool
    guess: str = ''
    detectable: tuple[float, float] = (math.inf, math.inf)


def component_information(before: np.ndarray, after: np.ndarray, p: int
                          ) -> tuple[float, float]:
    """Return the information ``(I_dry, I_viscous)`` of the joint fit on the change ``dx``.

    Not in the paper. In the joint fit (``x`` before, ``x + dx`` after) the information
    on ``dx`` is the Schur complement ``S = Pi_a - Pi_a (Pi_b + Pi_a)^+ Pi_a`` (its
    inverse is ``Pi_b^-1 + Pi_a^-1`` when both exist); on one component with the others
    free it is ``I_i = S_ii - S_ir S_rr^+ S_ri``, so that ``var(dx_i) = sigma^2 / I_i``.
    0 when the segments cannot separate the component from the others (constant speed
    after the change, wheel at rest).
    """
    pi_b, _, _ = unpack(before, p)
    pi_a, _, _ = unpack(after, p)
    total = pi_b + pi_a
    s_mat = pi_a - pi_a @ np.column_stack([solve_scaled(total, col) for col in pi_a.T])
    s_mat = 0.5 * (s_mat + s_mat.T)
    out = []
    for i in (0, 1):
        rest = [j for j in range(p) if j != i]
        s_rr = s_mat[np.ix_(rest, rest)]
        s_ri = s_mat[rest, i]
        info = float(s_mat[i, i] - s_ri @ solve_scaled(s_rr, s_ri))
        scale = max(float(s_mat[i, i]), 1e-300)
        out.append(info if info > 1e-9 * scale else 0.0)
    return out[0], out[1]


def detectable_steps(info: tuple[float, float], noise_var: float, z_threshold: float
                     ) -> tuple[float, float]:
    """Return the dry and viscous steps found with 90 % power by the component tests.

    Not in the paper. The likelihood-ratio test of one component (information ``I``,
    :func:`component_information`) at level ``z_threshold`` has power 0.9 for a step of
    ``(z* + z_0.9) sigma / sqrt(I)``: infinite when the post-change speed range cannot
    separate the two.
    """
    return tuple(math.inf if i <= 0.0 else (z_threshold + POWER_Z) * math.sqrt(noise_var / i)
                 for i in info)


def categorise(before: np.ndarray, n_before: int, after: np.ndarray, p: int,
               noise_var: float | None, z_threshold: float) -> Category:
    """Return the :class:`Category` (kind, dx, z, sigma^2, confirmed) of one change.

    Not in the paper (which promises a categorisation but gives none); the design and its
    error bounds are in docs/llr.md "Categorisation". Nested likelihood-ratio tests on the
    joint fit of :func:`change_fits`, ``sigma^2`` from the before fit, each of level
    ``z_threshold`` (two-sided normal quantile): ``chi_v = (RSS_dry - RSS_both) /
    sigma^2`` rejects the dry-only change when ``> z*^2``, ``chi_d = (RSS_viscous -
    RSS_both) / sigma^2`` the viscous-only change (1 degree of freedom each; the squared
    marginal z of ``dx`` when the after segment is identifiable). ``z_dry = sign(dx_dry)
    sqrt(chi_d)``, ``z_viscous`` likewise. Both rejected -> ``both``. One rejected, say
    viscous-only, -> ``dry`` if besides the viscous component is not significant even at
    5 % (``|z_viscous| <= Z_ABSENT``) and a pure viscous change of the same torque at the
    post-change mean speed ``|w|_a`` would have been found with 90 % power
    (:func:`detectable_steps`); ``viscous`` symmetrically. These
    are *confirmed*. Otherwise :data:`UNDECIDED` with ``guess`` the single-component kind
    that fits better. ``dx`` is always the estimate of the hypothesis of ``guess``
    (constrained fit for a single component), never the free fit of an unidentifiable
    segment.
    """
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    explained, dx = change_fits(before, after, p)
    if noise_var is None:
        pi_b, q_b, e_b = unpack(before, p)
        rss = float(e_b) - float(solve_scaled(pi_b, q_b) @ q_b)
        floor = NOISE_FLOOR_REL * float(e_b) / n_before + NOISE_FLOOR_ABS
        s2 = max(rss / (n_before - p), floor)
    else:
        s2 = float(noise_var)
    chi_v = max(float(explained[2] - explained[0]), 0.0) / s2
    chi_d = max(float(explained[2] - explained[1]), 0.0) / s2
    z_d = math.copysign(math.sqrt(chi_d), float(dx[2, 0]))
    z_v = math.copysign(math.sqrt(chi_v), float(dx[2, 1]))
    limit = z_threshold * z_threshold
    no_dry_only = chi_v > limit
    no_viscous_only = chi_d > limit
    info = component_information(before, after, p)
    detectable = detectable_steps(info, s2, z_threshold)
    if no_dry_only and no_viscous_only:
        return Category(KINDS[2], dx[2].copy(), (z_d, z_v), s2, True, KINDS[2], detectable)
    if no_dry_only or no_viscous_only:
        h = 1 if no_dry_only else 0
        other = 1 - h
        z_other = (z_d, z_v)[other]
        pi_a = unpack(after, p)[0]
        mean_speed = float(pi_a[0, 1] / pi_a[0, 0]) if pi_a[0, 0] > 0.0 else 0.0
        # Torque of the change under the single-kind fit, and the smallest step of the
        # other kind its test finds with 90 % power, both at the post-change mean speed (a
        # dry step a = a viscous step a / |w|_a there): the speed variation separates the
        # two directions for a change of this size.
        scale = (1.0, mean_speed)
        torque = abs(float(dx[h, h])) * scale[h]
        if abs(z_other) <= Z_ABSENT and detectable[other] * scale[other] <= torque:
            return Category(KINDS[h], dx[h].copy(), (z_d, z_v), s2, True, KINDS[h],
                            detectable)
    else:
        h = 0 if explained[0] >= explained[1] else 1
    return Category(UNDECIDED, dx[h].copy(), (z_d, z_v), s2, False, KINDS[h], detectable)


def refine_change(prefix: np.ndarray, first: int, c: int, n: int, lo: int, hi: int, p: int,
                  noise_var: float | None, z_threshold: float, fallback: int) -> int:
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
    return int(taus[int(best[h])])


def z_threshold(level: float) -> float:
    """Return the two-sided normal quantile ``z`` with ``P(|Z| > z) = level``."""
    from scipy import special
    return float(math.sqrt(2.0) * special.erfcinv(level))
