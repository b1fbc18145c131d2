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
# A kind named by the growth tests (:func:`ramp_kind`) needs the other kind's growth not
# significant even at this level (the growth analogue of Z_ABSENT).
RAMP_ABSENT_LEVEL = 0.05
SHAPES = ('step', 'ramp')
# Collinearity of the alternatives on the after segment (docs/llr.md "Kinds that survive
# collinearity"): a growth column whose information left after the step offsets and the
# other growth column is below this fraction of its own cannot be told from them.
MIN_SEPARATION = 1.0e-3
# Why a kind stays undecided (the event's ``kind_reason``).
REASONS = {
    'small': 'neither single-component change is rejected: the data fit either',
    'speed': 'speed variation too small to separate dry from viscous for a change of this '
             'size',
    'ambiguous': 'the other component lies between the 5 % and the category level',
    'grows': 'the change grows: the step model is rejected and no growth kind is named',
}


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
    ``shape``: ``ramp`` when the kind was named by the ramp models (:func:`ramp_fits`),
    else ``step``.
    """

    kind: str
    dx: np.ndarray
    z: tuple[float, float]
    noise_var: float
    confirmed: bool
    guess: str = ''
    detectable: tuple[float, float] = (math.inf, math.inf)
    shape: str = SHAPES[0]
    reason: str = ''   # why ``undecided`` (a key of REASONS), else ''


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
               noise_var: float | None, z_threshold: float,
               ramp: np.ndarray | None = None) -> Category:
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

    ``ramp``: the block rows (:func:`ramp_sums`) of the after segment. Given, the growth
    tests (:func:`ramp_kind` on the best time shape of each hypothesis,
    :func:`ramp_shapes`; docs/llr.md "Kinds on ramps") may name the kind in which the
    change grows; if it differs from the step outcome and a growth of the other kind of
    the same torque rate would have been found (:func:`ramp_growth`, the guard of
    :func:`separable`), it replaces it, with ``shape`` ``ramp`` and the step estimate
    ``dx`` of that kind; a confirmed single step kind refuted by a significant growth of
    the other kind is withdrawn (:func:`refuted`). A step verdict that stands is not
    confirmed when the after segment grows (:func:`grows`): the step model it rests on is
    rejected, and a step fit of a growing level shares the rise between the directions
    (``undecided``, guess the better single kind). A step has no growth: a true single
    step is named the other kind, or loses its confirmation, only through a false
    significance at the category level.
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
    pi_a = unpack(after, p)[0]
    mean_speed = float(pi_a[0, 1] / pi_a[0, 0]) if pi_a[0, 0] > 0.0 else 0.0
    reason = ''
    if no_dry_only and no_viscous_only:
        step = Category(KINDS[2], dx[2].copy(), (z_d, z_v), s2, True, KINDS[2], detectable)
    else:
        if no_dry_only or no_viscous_only:
            h = 1 if no_dry_only else 0
            absent = abs((z_d, z_v)[1 - h]) <= Z_ABSENT
            split = separable(dx, h, detectable, mean_speed)
            confirmed = absent and split
            kind = KINDS[h] if confirmed else UNDECIDED
            reason = '' if confirmed else ('speed' if not split else 'ambiguous')
        else:
            h = 0 if explained[0] >= explained[1] else 1
            confirmed, kind = False, UNDECIDED
            reason = 'small' if separable(dx, h, detectable, mean_speed) else 'speed'
        step = Category(kind, dx[h].copy(), (z_d, z_v), s2, confirmed, KINDS[h], detectable,
                        reason=reason)
    if ramp is None:
        return step
    shapes = ramp_shapes(ramp, p)
    fits = ramp_fits(before, after, shapes, p)
    best = fits.max(axis=0)
    gram = _ramp_after(after, shapes, p)[0][int(np.argmax(fits[:, 0]))]
    if min(growth_separation(gram, p)) < MIN_SEPARATION:
        # The growth alternatives cannot be told from a step and a speed term here (a
        # monotone spin-down, a wheel that keeps one speed): the simpler explanation, the
        # step outcome, stands (undecided: with its own reason); a confirmed step verdict
        # cannot be checked for growth.
        return step
    named = ramp_kind(best, s2, z_threshold)
    if named is not None and step.kind == KINDS[named]:
        return step
    if named is not None and separable(dx, named, detectable, mean_speed):
        return Category(KINDS[named], dx[named].copy(), (z_d, z_v), s2, True, KINDS[named],
                        detectable, SHAPES[1])
    if named is None:
        # The statistics are the best of the candidate time shapes: Bonferroni over them,
        # as the step check (grows) does.
        level = math.erfc(z_threshold / math.sqrt(2.0)) / shapes.shape[0]
        step = refuted(step, ramp_statistics(best, s2), _chi2_1(level), dx)
    growing = step.confirmed and step.shape == SHAPES[0] and grows(
        after, shapes, s2, p, z_threshold)
    if growing:
        h = 0 if explained[0] >= explained[1] else 1
        return step._replace(kind=UNDECIDED, dx=dx[h].copy(), confirmed=False,
                             guess=KINDS[h], reason='grows')
    if step.kind == UNDECIDED and not step.reason:
        step = step._replace(reason='grows')
    return step


def growth_separation(gram: np.ndarray, p: int) -> tuple[float, float]:
    """Return, per growth column (dry, viscous), the fraction of its information left.

    Not in the paper (docs/llr.md "Kinds that survive collinearity"). ``gram``: the
    Gram matrix of the after segment's columns ``(h, r h_dry, r h_viscous)``
    (:func:`_ramp_after`, one time shape). For growth column ``g`` it is ``(G_gg -
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
        left = own - float(cross @ solve_scaled(_sub(gram, others), cross))
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
    gram, rhs = _ramp_after(after, shapes, p)
    full = _explained(gram, rhs)
    offsets = _explained(gram[..., :p, :p], rhs[..., :p])
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
    from scipy import special
    level = math.erfc(z_threshold / math.sqrt(2.0)) / shapes.shape[0]
    return growth_statistic(after, shapes, noise_var, p) > float(special.chdtri(2, level))


def refuted(step: Category, chi: tuple[float, float], reject: float, dx: np.ndarray
            ) -> Category:
    """Return the step category, unless the ramp tests refute its single kind.

    Not in the paper (docs/llr.md "Kinds on ramps"). ``chi[h]``: the significance of the
    growth of the kind other than ``h`` beside ``h``'s own (:func:`ramp_statistics`).
    When the change grows in the other kind's direction at the category level (``chi >
    reject``), a confirmed step of kind ``h`` alone is refuted: ``both`` (confirmed) if
    it grows in both directions, else ``undecided`` with the other kind as guess.
    """
    if not step.confirmed or step.kind not in KINDS[:2]:
        return step
    h = KINDS.index(step.kind)
    if chi[h] <= reject:
        return step
    if chi[1 - h] > reject:
        return step._replace(kind=KINDS[2], dx=dx[2].copy(), guess=KINDS[2],
                             shape=SHAPES[1])
    return step._replace(kind=UNDECIDED, dx=dx[1 - h].copy(), confirmed=False,
                         guess=KINDS[1 - h], shape=SHAPES[1])


def separable(dx: np.ndarray, h: int, detectable: tuple[float, float], mean_speed: float
              ) -> bool:
    """Return True if a change of kind ``h`` (0 dry, 1 viscous) of this size is separable.

    Not in the paper (docs/llr.md "Categorisation", condition 1): the torque of the
    change under the single-kind fit ``dx[h]`` is at least the smallest step of the other
    kind its test finds with 90 % power (:func:`detectable_steps`), both at the
    post-change mean speed ``mean_speed`` (a dry step ``a`` = a viscous step ``a / |w|_a``
    there).
    """
    scale = (1.0, mean_speed)
    return detectable[1 - h] * scale[1 - h] <= abs(float(dx[h, h])) * scale[h]


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
    gram, rhs = _ramp_after(after, ramp, p)
    base = float(solve_scaled(pi_b, q_b) @ q_b)
    explained = np.empty(gram.shape[:-2] + (3,))
    explained[..., 0] = base + _explained(gram, rhs)
    for i in (0, 1):
        cols = list(range(p)) + [p + i]
        explained[..., 1 + i] = base + _explained(_sub(gram, cols), rhs[..., cols])
    return explained


def _ramp_after(after: np.ndarray, ramp: np.ndarray, p: int
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


def _explained(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Return ``theta . v`` of the least-squares fits ``m theta = v`` (stacked)."""
    return np.einsum('...i,...i->...', solve_scaled(m, v), v)


def _sub(m: np.ndarray, cols: list[int]) -> np.ndarray:
    """Return the rows and columns ``cols`` of stacked square matrices."""
    return m[..., cols, :][..., :, cols]


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
    ``chi2_p`` at the category level (each hypothesis at its best time shape); else it
    is the same change, as its own ramp explains the samples that triggered it.
    """
    shapes = ramp_shapes(blocks, p)
    knots = np.atleast_2d(np.asarray(blocks, dtype=float))[:, 0]
    pi_b, q_b, e_b = unpack(before, p)
    if noise_var is None:
        rss = float(e_b) - float(solve_scaled(pi_b, q_b) @ q_b)
        floor = NOISE_FLOOR_REL * float(e_b) / n_before + NOISE_FLOOR_ABS
        noise_var = max(rss / (n_before - p), floor)
    tail = np.ascontiguousarray(tail, dtype=float)
    u = np.ascontiguousarray(tail_offsets, dtype=float)
    pi_t, q_t, _ = unpack(tail.sum(axis=0), p)
    if kind in KINDS[:2]:
        h = KINDS.index(kind)
        change = [h, p + h]
    else:
        change = list(range(p + 2))
    step = list(range(p + 2, 2 * p + 2))
    gram, rhs = _ramp_after(after, shapes, p)
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
    best = []
    for cols in (change, change + step):
        # x (before and after) first, then the after-only change columns.
        idx = list(range(p)) + cols
        joint, v = _sub(big, idx), full_rhs[:, idx]
        joint[:, :p, :p] += pi_b
        v[:, :p] += q_b
        best.append(float(np.max(_explained(joint, v))))
    return (best[1] - best[0]) / noise_var <= ramp_limits(p, z_threshold)[0]


def _chi2_1(level: float) -> float:
    """Return the upper ``level`` quantile of chi2 with one degree of freedom."""
    from scipy import special
    return float(special.chdtri(1, level))


def ramp_limits(dof: int, z_threshold: float) -> tuple[float, float]:
    """Return the chi-square limits ``(reject, absent)`` with ``dof`` degrees of freedom.

    ``reject``: the upper quantile at the category level (the level whose two-sided
    normal quantile is ``z_threshold``); ``absent``: at :data:`RAMP_ABSENT_LEVEL`.
    """
    from scipy import special
    level = math.erfc(z_threshold / math.sqrt(2.0))
    return (float(special.chdtri(dof, level)),
            float(special.chdtri(dof, RAMP_ABSENT_LEVEL)))


def ramp_statistics(explained: np.ndarray, noise_var: float) -> tuple[float, float]:
    """Return ``(chi_dry_ramp, chi_viscous_ramp)``: ``(RSS_h - RSS_full) / sigma^2``."""
    return (max(float(explained[0] - explained[1]), 0.0) / noise_var,
            max(float(explained[0] - explained[2]), 0.0) / noise_var)


def ramp_kind(explained: np.ndarray, noise_var: float, z_threshold: float) -> int | None:
    """Return the kind (0 dry, 1 viscous) the growth tests name, or None.

    Not in the paper (docs/llr.md "Kinds on ramps"). Nested likelihood-ratio tests of
    each single-kind growth model against the full one (:func:`ramp_fits`), one degree of
    freedom each (the other kind's growth column): a kind is named when the other kind's
    growth is not significant even at :data:`RAMP_ABSENT_LEVEL` and its own growth is,
    at the category level (:func:`ramp_limits`); None otherwise.
    """
    chi = ramp_statistics(explained, noise_var)
    reject, absent = ramp_limits(1, z_threshold)
    for h in (0, 1):
        if chi[h] <= absent and chi[1 - h] > reject:
            return h
    return None


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
