"""The kind of a declared change: dry, viscous, both or undecided.

Not in the llr-realtime paper, which promises a categorisation but gives none; the design
and its error bounds are in docs/llr.md "Categorisation dry / viscous / both", "Kinds on
ramps" and "Kinds that survive collinearity". Nested likelihood-ratio tests of the step
hypotheses (:func:`rwa_monitor.core.llr_stats.change_fits`), the information each
component has (:func:`component_information`) and the after-segment growth statistics of
:mod:`rwa_monitor.core.llr_growth`. Runs once per declaration or revision, never per
sample.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from rwa_monitor.core.llr_growth import (after_gram, grows, growth_separation,
                                         MIN_SEPARATION, ramp_fits, ramp_kind, ramp_limits,
                                         ramp_shapes, ramp_statistics, steps_beside_growth)
from rwa_monitor.core.llr_stats import (before_noise_var, change_fits, KINDS, solve_scaled,
                                        unpack)

# The data cannot tell dry from viscous (docs/llr.md "Categorisation"): an event kind.
UNDECIDED = 'undecided'
# A single-component kind is confirmed only if the other component is not significant
# even at 5 % (two-sided): between this and the category level the data are ambiguous.
Z_ABSENT = 1.959963984540054
POWER_Z = 1.2815515655446004   # one-sided normal quantile of 0.9 (detectable steps)
SHAPES = ('step', 'ramp')
# Why a kind stays undecided (the event's ``kind_reason``).
REASONS = {
    'small': 'neither single-component change is rejected: the data fit either',
    'speed': 'speed variation too small to separate dry from viscous for a change of this '
             'size',
    'ambiguous': 'the other component lies between the 5 % and the category level',
    'grows': 'the change grows: the step model is rejected and no growth kind is named',
}


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


def categorise(before: np.ndarray, n_before: int, after: np.ndarray, p: int,
               noise_var: float | None, z_threshold: float,
               ramp: np.ndarray | None = None, speeds: np.ndarray | None = None
               ) -> Category:
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
    the same torque rate would have been found (the guard of :func:`separable`), it
    replaces it, with ``shape`` ``ramp`` and the step estimate ``dx`` of that kind; a
    confirmed single step kind refuted by a significant growth of the other kind is
    withdrawn to ``undecided`` (:func:`refuted`; never ``both``, which only the step tests
    confirm), and so is a confirmed ``both`` one of whose step components is not
    significant beside the other kind's step and growth (:func:`unsupported_both`). Each
    growth test compares the best of the ``m`` time shapes with its limit at
    ``category_level / m`` (:func:`ramp_limits`). When the growth columns cannot be told
    from the step offsets and each other (:func:`growth_separation` below
    :data:`MIN_SEPARATION`) the growth tests are not used and the step outcome stands;
    nor are they when ``speeds`` (each block's lowest and highest ``|w|``, or None) are
    in one order (:func:`speed_ordered`) and the step tests confirmed a single kind. A
    step verdict that stands is not confirmed when the after segment grows
    (:func:`grows`): the step model it rests on is rejected, and a step fit of a growing
    level shares the rise between the directions (``undecided``, guess the better single
    kind), unless the kind stands beside the other kind's growth
    (:func:`stands_beside_growth`; also for an ``ambiguous`` step verdict on a growing
    segment): then it is confirmed with shape ``ramp``. A step has no growth: a true
    single step is named the other kind, or loses its confirmation, only through a false
    significance at the category level.
    """
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    explained, dx = change_fits(before, after, p)
    s2 = before_noise_var(before, n_before, p) if noise_var is None else float(noise_var)
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
    gram = after_gram(after, shapes, p)[0][int(np.argmax(fits[:, 0]))]
    if min(growth_separation(gram, p)) < MIN_SEPARATION:
        # The growth alternatives cannot be told from a step and a speed term here (a
        # monotone spin-down, a wheel that keeps one speed): the simpler explanation, the
        # step outcome, stands (undecided: with its own reason); a confirmed step verdict
        # cannot be checked for growth.
        return step
    if step.confirmed and step.kind in KINDS[:2] and speeds is not None \
            and speed_ordered(speeds):
        # Every candidate time shape is a function of the speed here: a growth cannot be
        # told from a speed shape the nominal misses, and the step tests found one kind
        # alone (docs/llr.md "Kinds that survive collinearity", *Speed in one order*).
        return step
    m = shapes.shape[0]
    named = ramp_kind(best, s2, z_threshold, m)
    if named is not None and step.kind == KINDS[named]:
        return step
    if named is not None and separable(dx, named, detectable, mean_speed):
        return Category(KINDS[named], dx[named].copy(), (z_d, z_v), s2, True, KINDS[named],
                        detectable, SHAPES[1])
    if named is None:
        # The statistics are the best of the candidate time shapes: Bonferroni over them,
        # as every growth test (ramp_limits).
        step = refuted(step, ramp_statistics(best, s2), ramp_limits(1, z_threshold, m)[0],
                       dx)
    if step.confirmed and step.kind == KINDS[2]:
        beside = steps_beside_growth(before, after, shapes, p)
        step = unsupported_both(step, (beside[0] / s2, beside[1] / s2), limit, dx,
                                explained)
    growing = step.confirmed and step.shape == SHAPES[0] and grows(
        after, shapes, s2, p, z_threshold)
    single = step.guess in KINDS[:2] and (growing or (
        step.reason == 'ambiguous' and grows(after, shapes, s2, p, z_threshold)))
    if single:
        # A single kind the step tests found, or nearly (the other component between the
        # 5 % and the category level), on an after segment that grows.
        h = KINDS.index(step.guess)
        beside = steps_beside_growth(before, after, shapes, p)
        if stands_beside_growth((beside[0] / s2, beside[1] / s2), h, limit, dx,
                                detectable, mean_speed):
            return Category(KINDS[h], dx[h].copy(), (z_d, z_v), s2, True, KINDS[h],
                            detectable, SHAPES[1])
    if growing:
        h = 0 if explained[0] >= explained[1] else 1
        return step._replace(kind=UNDECIDED, dx=dx[h].copy(), confirmed=False,
                             guess=KINDS[h], reason='grows')
    if step.kind == UNDECIDED and not step.reason:
        step = step._replace(reason='grows')
    return step


def speed_ordered(speeds: np.ndarray) -> bool:
    """Return True if the blocks' speed ranges follow each other without overlap.

    Not in the paper (docs/llr.md "Kinds that survive collinearity", *Speed in one
    order*). ``speeds``: per block of the after segment, in time order, its lowest and
    highest ``|w|``. At least two blocks, each one's range wholly above the next one's
    (a wheel slowing down through the segment) or wholly below it (speeding up). Then
    each candidate time shape of :func:`ramp_shapes`, whose knots are the blocks' ends,
    is a function of ``|w|`` on the after segment: its growth columns are a speed shape,
    and a speed shape of the residual that the nominal model misses fits them as well.
    """
    speeds = np.asarray(speeds, dtype=float)
    if speeds.ndim != 2 or speeds.shape[0] < 2 or not np.all(np.isfinite(speeds)):
        return False
    low, high = speeds[:, 0], speeds[:, 1]
    return bool(np.all(low[:-1] > high[1:]) or np.all(high[:-1] < low[1:]))


def stands_beside_growth(chi: tuple[float, float], h: int, limit: float, dx: np.ndarray,
                         detectable: tuple[float, float], mean_speed: float) -> bool:
    """Return True if the step tests' kind ``h`` (0 dry, 1 viscous) stands beside growth.

    Not in the paper (docs/llr.md "Kinds that survive collinearity", *A kind beside the
    other kind's growth*). Used when the after segment grows (the step model is
    rejected), so that the step tests cannot confirm their kind ``h``, and the growth
    tests named none. ``chi[i]``: step component ``i`` beside the other kind's step and
    growth, at the time shape most favourable to that other kind
    (:func:`steps_beside_growth` / sigma^2). True when ``h``'s component is significant at
    the category level there (``> limit = z*^2``: no change of the other kind, stepping or
    growing in any candidate shape, explains it), the other kind's component is not
    significant even at 5 % beside ``h``'s step and growth (``|z| <= Z_ABSENT``), and a
    change of kind ``h`` of this size is separable (:func:`separable`): the step rule with
    the other kind allowed to grow. It confirms the kind the step tests found, never
    another: where time and speed move together (a coast-down) a growth of one kind can
    mimic a step of the other, and these statistics alone then point the wrong way.
    """
    return (chi[h] > limit and chi[1 - h] <= Z_ABSENT * Z_ABSENT
            and separable(dx, h, detectable, mean_speed))


def refuted(step: Category, chi: tuple[float, float], reject: float, dx: np.ndarray
            ) -> Category:
    """Return the step category, unless the growth tests refute its single kind.

    Not in the paper (docs/llr.md "Kinds on ramps", "Kinds that survive collinearity").
    ``chi[h]``: the significance of the growth of the kind other than ``h`` beside
    ``h``'s own (:func:`ramp_statistics`). When the change grows in the other kind's
    direction (``chi[h] > reject``), a confirmed step of kind ``h`` alone is withdrawn:
    ``undecided`` (reason ``grows``), with the other kind as guess, or ``h`` if it grows
    in both directions. Never ``both``: a confirmed ``both`` states that each component
    is significant given the other at the category level (the step tests), and here the
    other kind's step is not significant even at 5 % (a condition of ``h``'s
    confirmation); two growth statistics whose columns nearly coincide are one piece of
    evidence, on the step model's fit, not on a second component.
    """
    if not step.confirmed or step.kind not in KINDS[:2]:
        return step
    h = KINDS.index(step.kind)
    if chi[h] <= reject:
        return step
    guess = h if chi[1 - h] > reject else 1 - h
    return step._replace(kind=UNDECIDED, dx=dx[guess].copy(), confirmed=False,
                         guess=KINDS[guess], shape=SHAPES[1], reason='grows')


def unsupported_both(step: Category, chi: tuple[float, float], limit: float,
                     dx: np.ndarray, explained: np.ndarray) -> Category:
    """Return the step category, unless a component of its ``both`` is a growth's share.

    Not in the paper (docs/llr.md "Kinds that survive collinearity", *A `both` needs both
    components*). ``chi[i]``: the significance of step component ``i`` beside the other
    kind's step and growth (:func:`steps_beside_growth` / sigma^2). A confirmed ``both``
    states that each component is non-zero; when one of them is not significant at the
    category level (``chi <= limit = z*^2``) once the other kind may grow, the data are
    explained by a single growing kind (a step fit of a growing level shares the rise
    between the directions): withdrawn to ``undecided`` (reason ``grows``), guess the
    kind that explains them alone (the better single step kind if either could).
    """
    if not step.confirmed or step.kind != KINDS[2] or min(chi) > limit:
        return step
    if (chi[0] > limit) != (chi[1] > limit):
        h = 0 if chi[0] > limit else 1
    else:
        h = 0 if explained[0] >= explained[1] else 1
    return step._replace(kind=UNDECIDED, dx=dx[h].copy(), confirmed=False,
                         guess=KINDS[h], shape=SHAPES[1], reason='grows')


def supports(category: Category, kind: str, z_threshold: float) -> bool:
    """Return True if the step tests of ``category`` find each component of ``kind``.

    Not in the paper (docs/llr.md "End of record"). ``kind`` (dry, viscous or both)
    claims that its components are non-zero; each is found when its test given the other
    component rejects at the category level (``|z| > z_threshold``, the z of
    :func:`categorise`). The end of record keeps an earlier confirmed kind only where the
    final evaluation, on every sample after the change, still supports it.
    """
    components = {KINDS[0]: (0,), KINDS[1]: (1,), KINDS[2]: (0, 1)}[kind]
    return all(abs(category.z[i]) > z_threshold for i in components)


def adds_component(kind: str, new: str) -> bool:
    """Return True if the kind ``new`` claims a component that the kind ``kind`` does not.

    ``both`` after ``dry`` or ``viscous``. The end of record of a closed change (docs/llr.md
    "End of record", *Closed changes*) does not add one to a confirmed kind.
    """
    return new == KINDS[2] and kind in KINDS[:2]
