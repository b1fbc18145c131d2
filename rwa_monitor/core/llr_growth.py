"""After-segment growth statistics: ramps, the step check, collinearity, continuation.

Not in the llr-realtime paper, whose model change is a step (docs/llr.md "Kinds on
ramps" and "Kinds that survive collinearity"). The after segment of a declared change is
fitted on its own with its offsets and growths ``r(u) h_dry``, ``r(u) h_viscous`` (``u``
the time since the change, ``r`` a candidate time shape); from the time-weighted block
sums of :func:`ramp_sums`, so that the streaming and the batch detector, which pass the
same blocks, get the same floats. :mod:`rwa_monitor.core.llr_kinds` names the kind from
these statistics and the step tests.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.llr_stats import (before_noise_var, chi2_upper, explained_sum, KINDS,
                                        level_of, solve_scaled, submatrix, unpack, width)

# A kind named by the growth tests (:func:`ramp_kind`) needs the other kind's growth not
# significant even at this level (the growth analogue of llr_kinds.Z_ABSENT).
RAMP_ABSENT_LEVEL = 0.05
# Collinearity of the alternatives on the after segment (docs/llr.md "Kinds that survive
# collinearity"): a growth column whose information left after the step offsets and the
# other growth column is below this fraction of its own cannot be told from them.
MIN_SEPARATION = 1.0e-3


def ramp_sums(terms: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Return one block row ``(u_last, sum t, sum u t, sum u^2 t)`` over samples.

    ``terms``: the per-sample prefix-sum terms ``(n, width(p))`` (module docstring) of
    consecutive samples; ``offsets``: ``u`` = time since the estimated change (s) of each.
    ``u_last`` = the last offset (the knot candidate of :func:`ramp_shapes`). Summed in
    sample order along axis 0 of C-contiguous arrays, so that the streaming and the batch
    path, which pass the same blocks, get the same floats.
    """
    plain = np.ascontiguousarray(terms, dtype=float)
    u = np.ascontiguousarray(offsets, dtype=float)[:, None]
    first = plain * u
    second = first * u
    return np.concatenate([u[-1], plain.sum(axis=0), first.sum(axis=0), second.sum(axis=0)])


def ramp_shapes(blocks: np.ndarray, p: int) -> np.ndarray:
    """Return the sums ``(sum r t, sum r^2 t)`` of each candidate time shape ``r(u)``.

    Not in the paper (docs/llr.md "Kinds on ramps"). ``blocks``: the :func:`ramp_sums`
    rows of consecutive blocks of the after segment, in time order. Candidate ``i``: a
    ramp that stops growing at the end of block ``i``, ``r(u) = min(u, u_i)`` (the last
    candidate grows to the end: a straight ramp); so a ramp that ended during the after
    segment is fitted as such. Row ``i``: ``2 width(p)`` floats for :func:`ramp_fits`.
    """
    blocks = np.atleast_2d(np.asarray(blocks, dtype=float))
    n = width(p)
    knots = blocks[:, 0]
    plain, first, second = (blocks[:, 1 + i * n:1 + (i + 1) * n] for i in range(3))
    rows = np.empty((blocks.shape[0], 2 * n))
    for i, u in enumerate(knots):
        rest = plain[i + 1:].sum(axis=0)
        rows[i, :n] = first[:i + 1].sum(axis=0) + u * rest
        rows[i, n:] = second[:i + 1].sum(axis=0) + (u * u) * rest
    return rows


def after_gram(after: np.ndarray, ramp: np.ndarray, p: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Return the Gram matrices and right-hand sides of the after rows ``(h, r h_0, r h_1)``.

    ``ramp``: one or more rows of :func:`ramp_shapes` (leading axes kept).
    """
    ramp = np.asarray(ramp, dtype=float)
    lead = ramp.shape[:-1]
    pi_a, q_a, _ = unpack(after, p)
    n = width(p)
    u1, uq, _ = unpack(ramp[..., :n], p)
    u2 = unpack(ramp[..., n:], p)[0]
    gram = np.empty(lead + (p + 2, p + 2))
    gram[..., :p, :p] = pi_a
    gram[..., :p, p:] = u1[..., :, :2]
    gram[..., p:, :p] = u1[..., :2, :]
    gram[..., p:, p:] = u2[..., :2, :2]
    rhs = np.concatenate([np.broadcast_to(q_a, lead + (p,)), uq[..., :2]], axis=-1)
    return gram, rhs


def ramp_fits(before: np.ndarray, after: np.ndarray, ramp: np.ndarray, p: int
              ) -> np.ndarray:
    """Return ``explained`` of the growth hypotheses ``(full, dry growth, viscous growth)``.

    Not in the paper (docs/llr.md "Kinds on ramps"). The after segment is fitted on its
    own (offsets in every direction free, so a change that began before the estimated
    change time and leaks into the before fit does not bias it) with the regressors
    ``h`` plus a growth ``r(u) h_dry`` and / or ``r(u) h_viscous`` (``r`` the time shape
    of ``ramp``, rows of :func:`ramp_shapes`, leading axes kept): ``full`` both growth
    columns, ``dry
    growth`` the dry one, ``viscous growth`` the viscous one. ``explained_h`` includes
    the before fit, so that ``RSS_h = E_before + E_after - explained_h`` as in
    :func:`change_fits`.
    """
    pi_b, q_b, _ = unpack(before, p)
    gram, rhs = after_gram(after, ramp, p)
    base = float(solve_scaled(pi_b, q_b) @ q_b)
    explained = np.empty(gram.shape[:-2] + (3,))
    explained[..., 0] = base + explained_sum(gram, rhs)
    for i in (0, 1):
        cols = list(range(p)) + [p + i]
        explained[..., 1 + i] = base + explained_sum(submatrix(gram, cols), rhs[..., cols])
    return explained


def ramp_limits(dof: int, z_threshold: float, shapes: int = 1) -> tuple[float, float]:
    """Return the chi-square limits ``(reject, absent)`` with ``dof`` degrees of freedom.

    ``reject``: the upper quantile at the category level (the level whose two-sided
    normal quantile is ``z_threshold``) divided by ``shapes``, the number of candidate
    time shapes whose best statistic is compared (Bonferroni; docs/llr.md "Kinds on
    ramps", *one rule for the time shapes*); ``absent``: at :data:`RAMP_ABSENT_LEVEL`,
    one shape (a condition for naming a kind: the stricter limit).
    """
    return (chi2_upper(dof, level_of(z_threshold) / shapes),
            chi2_upper(dof, RAMP_ABSENT_LEVEL))


def ramp_statistics(explained: np.ndarray, noise_var: float) -> tuple[float, float]:
    """Return ``(chi_dry_ramp, chi_viscous_ramp)``: ``(RSS_h - RSS_full) / sigma^2``."""
    return (max(float(explained[0] - explained[1]), 0.0) / noise_var,
            max(float(explained[0] - explained[2]), 0.0) / noise_var)


def ramp_kind(explained: np.ndarray, noise_var: float, z_threshold: float, shapes: int = 1
              ) -> int | None:
    """Return the kind (0 dry, 1 viscous) the growth tests name, or None.

    Not in the paper (docs/llr.md "Kinds on ramps"). Nested likelihood-ratio tests of
    each single-kind growth model against the full one (:func:`ramp_fits`), one degree of
    freedom each (the other kind's growth column): a kind is named when the other kind's
    growth is not significant even at :data:`RAMP_ABSENT_LEVEL` and its own growth is,
    at the category level over the ``shapes`` candidate time shapes whose best fits
    ``explained`` holds (:func:`ramp_limits`); None otherwise.
    """
    chi = ramp_statistics(explained, noise_var)
    reject, absent = ramp_limits(1, z_threshold, shapes)
    for h in (0, 1):
        if chi[h] <= absent and chi[1 - h] > reject:
            return h
    return None


def steps_beside_growth(before: np.ndarray, after: np.ndarray, shapes: np.ndarray, p: int
                        ) -> tuple[float, float]:
    """Return ``(E_dry, E_viscous)``: each step component beside the other kind growing.

    Not in the paper (docs/llr.md "Kinds that survive collinearity", *A `both` needs both
    components*). The joint fit of :func:`llr_stats.change_fits` (``x`` before, ``x +
    dx`` after) with, besides, a growth ``r(u) h_o`` of the other kind ``o`` (time shape
    ``r``, rows of :func:`ramp_shapes`): ``E_dry`` = what the dry step explains beside
    the viscous step and the viscous growth, at the shape where that growing viscous
    change fits best (the most favourable shape for the explanation without a dry
    component); ``E_viscous`` likewise. Divided by ``sigma^2``: the step test of
    :func:`llr_kinds.categorise` with the other kind allowed to grow.
    """
    pi_b, q_b, _ = unpack(before, p)
    gram, rhs = after_gram(after, np.atleast_2d(shapes), p)
    m = gram.shape[0]
    # Columns: x (p), then the after-only columns dx (p), r h_dry, r h_viscous.
    joint = np.empty((m, 2 * p + 2, 2 * p + 2))
    joint[:, p:, p:] = gram
    joint[:, :p, p:] = gram[:, :p, :]
    joint[:, p:, :p] = gram[:, :, :p]
    joint[:, :p, :p] = gram[:, :p, :p] + pi_b
    v = np.concatenate([rhs[:, :p] + q_b, rhs], axis=-1)
    out = []
    for h in (0, 1):
        other = 1 - h
        null = list(range(p)) + [p + other, 2 * p + other]
        fit = explained_sum(submatrix(joint, null), v[:, null])
        best = int(np.argmax(fit))
        cols = null + [p + h]
        full = float(explained_sum(submatrix(joint[best], cols), v[best, cols]))
        out.append(max(full - float(fit[best]), 0.0))
    return out[0], out[1]


def growth_separation(gram: np.ndarray, p: int) -> tuple[float, float]:
    """Return, per growth column (dry, viscous), the fraction of its information left.

    Not in the paper (docs/llr.md "Kinds that survive collinearity"). ``gram``: the
    Gram matrix of the after segment's columns ``(h, r h_dry, r h_viscous)``
    (:func:`after_gram`, one time shape). For growth column ``g`` it is ``(G_gg -
    G_go G_oo^+ G_og) / G_gg``, ``o`` = the step offsets and the other growth column:
    ``1 - R^2`` of the column on its alternatives, the inverse of its variance inflation.
    0 when the speed and the time since the change move together (a coasting wheel) or
    the speed keeps one value: the growth and step alternatives are then one direction.
    """
    out = []
    for i in (0, 1):
        g = p + i
        others = list(range(p)) + [p + 1 - i]
        own = float(gram[g, g])
        if own <= 0.0:
            out.append(0.0)
            continue
        cross = gram[others, g]
        left = own - float(cross @ solve_scaled(submatrix(gram, others), cross))
        out.append(max(left, 0.0) / own)
    return out[0], out[1]


def growth_statistic(after: np.ndarray, shapes: np.ndarray, noise_var: float, p: int
                     ) -> float:
    """Return ``max`` over the time shapes of ``(RSS_step - RSS_growth) / sigma^2``.

    Not in the paper (docs/llr.md "Kinds on ramps", the step check). The after segment
    fitted on its own with its offsets only (a step: constant level after the change)
    against the offsets plus a growth ``r(u) h_dry + r(u) h_viscous`` (two more columns)
    for each candidate shape ``r`` (rows of :func:`ramp_shapes`).
    """
    gram, rhs = after_gram(after, shapes, p)
    full = explained_sum(gram, rhs)
    offsets = explained_sum(gram[..., :p, :p], rhs[..., :p])
    return max(float(np.max(full - offsets)), 0.0) / noise_var


def grows(after: np.ndarray, shapes: np.ndarray, noise_var: float, p: int,
          z_threshold: float) -> bool:
    """Return True if the step model of the after segment is rejected (the change grows).

    Not in the paper (docs/llr.md "Kinds on ramps"). :func:`growth_statistic` against the
    ``chi2_2`` quantile at the category level divided by the number of candidate shapes
    (Bonferroni: a step, whatever the shape tried, is called growing with probability at
    most the category level). The step categorisation assumes a constant level after the
    change: when it grows, a step fit shares the rise between the two directions wherever
    ``|w|`` trends, so its single-kind or ``both`` verdict is not confirmed.
    """
    shapes = np.atleast_2d(shapes)
    limit = ramp_limits(2, z_threshold, shapes.shape[0])[0]
    return growth_statistic(after, shapes, noise_var, p) > limit


def continues(before: np.ndarray, n_before: int, after: np.ndarray, blocks: np.ndarray,
              tail: np.ndarray, tail_offsets: np.ndarray, kind: str, p: int,
              noise_var: float | None, z_threshold: float) -> bool:
    """Return True if a new declaration is the previous change still growing.

    Not in the paper (docs/llr.md "Kinds on ramps"). ``before``/``n_before``: the before
    segment of the previous change; ``after``: sums of its after segment up to the new
    declaration, ``blocks`` its :func:`ramp_sums` rows; ``tail`` (per-sample terms) and
    ``tail_offsets`` (``u`` of the previous change): the samples from the new change
    position to the new declaration. H0: the previous change of kind ``kind`` grows
    (its single-kind ramp, or the full ramp for ``both`` / ``undecided``, over every time
    shape of :func:`ramp_shapes`); H1: H0 plus a free step (``p`` parameters) at the new
    change position. The new declaration is a new change when H1 explains more by
    ``chi2_p`` at the category level, both at the time shape that fits H0 best (the
    growth profiled under H0); else it is the same change, as its own ramp explains the
    samples that triggered it. Each hypothesis at its own best shape (before 2026-11-28)
    let H1 pair an earlier knot with a step that took up the rest of the growth: a ramp
    that stopped between two knots was declared again at its end.
    """
    shapes = ramp_shapes(blocks, p)
    knots = np.atleast_2d(np.asarray(blocks, dtype=float))[:, 0]
    pi_b, q_b, _ = unpack(before, p)
    if noise_var is None:
        noise_var = before_noise_var(before, n_before, p)
    tail = np.ascontiguousarray(tail, dtype=float)
    u = np.ascontiguousarray(tail_offsets, dtype=float)
    pi_t, q_t, _ = unpack(tail.sum(axis=0), p)
    if kind in KINDS[:2]:
        h = KINDS.index(kind)
        change = [h, p + h]
    else:
        change = list(range(p + 2))
    step = list(range(p + 2, 2 * p + 2))
    gram, rhs = after_gram(after, shapes, p)
    m = shapes.shape[0]
    r = np.minimum(u[None, :], knots[:, None])
    r_pi = unpack((tail[None, :, :] * r[:, :, None]).sum(axis=1), p)[0]
    big = np.empty((m, 2 * p + 2, 2 * p + 2))
    big[:, :p + 2, :p + 2] = gram
    big[:, :p, p + 2:] = pi_t
    big[:, p:p + 2, p + 2:] = r_pi[:, :2, :]
    big[:, p + 2:, :p + 2] = np.swapaxes(big[:, :p + 2, p + 2:], 1, 2)
    big[:, p + 2:, p + 2:] = pi_t
    full_rhs = np.concatenate([rhs, np.broadcast_to(q_t, (m, p))], axis=-1)
    explained = []
    for cols in (change, change + step):
        # x (before and after) first, then the after-only change columns.
        idx = list(range(p)) + cols
        joint, v = submatrix(big, idx), full_rhs[:, idx]
        joint[:, :p, :p] += pi_b
        v[:, :p] += q_b
        explained.append(explained_sum(joint, v))
    i = int(np.argmax(explained[0]))
    return (float(explained[1][i]) - float(explained[0][i])) / noise_var \
        <= ramp_limits(p, z_threshold)[0]
