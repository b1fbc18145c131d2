"""The bounds that decide where the LLR kernel needs the exact tail (llr-realtime paper).

Algorithm 2 computes the exact tail of eq. (7) only for a candidate that may beat p_min.
Two cheap tests rule the others out in the compiled test (core/llr_kernel.py ``test``),
each proven to rule out nothing the exact path would keep: :func:`below_skip`, the skip
bound ``y / tr < y*`` decided without its divisions, and :func:`lower_bound`, the closed
form lower bound of log p_k. A candidate neither rules out gets :func:`exact_log_p2`, the
exact tail (Algorithm 2 line 5), in the same compiled call: the kernel records a new
minimum itself and leaves for Python only to declare.
"""

from __future__ import annotations

import math

from rwa_monitor.core.gchi2 import log_lower_bound, log_sf2, log_sf2_t
from rwa_monitor.core.jit import njit

# A candidate goes to the exact tail only if its lower bound of log p_k is within this
# relative margin above p_min (exact_log_p2 tests EXACT_REL; rounding is ~1e-15).
SKIP_REL = 1e-7
# exact_log_p2 computes the tail only if the bound is within this margin above p_min.
EXACT_REL = 1e-9

# Range of the factors within which below_skip decides (2^-250 to 2^250): every product
# it forms and every quotient of the test it stands for is then a normal float.
SKIP_TINY = 2.0 ** -250
SKIP_HUGE = 2.0 ** 250
# Relative margin of below_skip, far above the few roundings it must cover (~1e-15).
SKIP_MARGIN = 1.0 - 2.0 ** -30


@njit(cache=True, inline='always')
def below_skip(q, dett, m, rss, tn, ystar):
    """Return True if the division chain of ``llr_kernel.test`` finds ``y / tr < y*`` (no tail).

    ``y = fl(q / s2)`` with ``s2 >= fl(rss / m)`` (the floor only raises it; ``m = n_p - 2``,
    or 1 with ``s2 = rss`` the known variance), ``tr = fl(tn / dett)``, ``dett > 0``: the
    test skips the candidate when ``tr <= 0``, ``y <= 0`` or ``fl(y / tr) < y*``. This
    decides the same without its five divisions, for the ~98 % of samples far below the
    threshold: True only if ``fl(fl(q dett) m) < fl(fl(fl(y* rss) tn) K)``, ``K = 1 -
    2^-30``, with ``q, dett, rss, tn, y*`` in ``[2^-250, 2^250]`` and ``1 <= m < 2^53``.
    Proof: every product and quotient involved then lies in the normal range, each
    operation has a relative error below ``u = 2^-53``; ``1 / s2 <= m / (rss (1 - u))``,
    so ``fl(y / tr) <= q dett m / (rss tn) (1 + u)^2 / (1 - u)^2``, and the condition gives
    ``q dett m / (rss tn) < y* K (1 + u)^3 / (1 - u)^2``; together ``fl(y / tr) < y* K (1 +
    u)^5 / (1 - u)^4 < y*``. A ``y`` that underflows makes ``y / tr`` (``tr >= 2^-500``)
    smaller than ``2^-500 < y*``: skipped as well. False means: run the test as written
    (the same floats; test/test_llr_skip.py checks both against each other).
    """
    return (SKIP_TINY <= q <= SKIP_HUGE and SKIP_TINY <= dett <= SKIP_HUGE
            and SKIP_TINY <= rss <= SKIP_HUGE and SKIP_TINY <= tn <= SKIP_HUGE
            and SKIP_TINY <= ystar <= SKIP_HUGE
            and q * dett * m < ystar * rss * tn * SKIP_MARGIN)


@njit(cache=True, inline='always')
def _eigenvalues(tr, dm):
    """Return ``l1 >= l2 >= 0``, the eigenvalues of ``Pi_T^-1 Pi_W`` from trace and determinant.

    Clamped to ``0 <= l2 <= l1``: with two nearly equal eigenvalues rounding gives a
    negative discriminant and ``l2 > l1`` (a correlation ``rho`` above 1, hence ``a < 0``
    and a square root of a negative number in the tail bound); the exact ones satisfy it.
    """
    half = 0.5 * tr
    disc = half * half - dm
    lam1 = half + math.sqrt(disc) if disc > 0.0 else half
    lam2 = dm / lam1
    if lam2 < 0.0:
        lam2 = 0.0
    elif lam2 > lam1:
        lam2 = lam1
    return lam1, lam2


@njit(cache=True, inline='always')
def _bound(y, lam1, lam2, dof):
    """Return the closed-form lower bound of log p_k (``dof < 0``: known noise level).

    With ``b = y / (2 l1)``, ``rho = l2 / l1`` and ``a = b (1 - rho)``, ``p_k >= exp(-b rho)
    erfc(sqrt(a))`` (drop ``rho sin^2`` in the integral of :mod:`rwa_monitor.core.gchi2`);
    studentised, ``h <= tan^2`` and ``(1 + u)^-m >= exp(-m u)`` give ``p_k >= (1 + 2 b /
    dof)^(-dof/2) exp(A) erfc(sqrt(A))``, ``A = dof a / (dof + 2 b)`` (tighter than the
    Gaussian bound, which also holds).
    """
    b = y / (2.0 * lam1)
    rho = lam2 / lam1
    a = b * (1.0 - rho)
    if dof < 0.0:
        return -b * rho + log_lower_bound(a)
    big_a = dof * a / (dof + 2.0 * b)
    return -0.5 * dof * math.log1p(2.0 * b / dof) + big_a + log_lower_bound(big_a)


@njit(cache=True, error_model='numpy')
def lower_bound(y, tr, dm, dof):
    """Return the lower bound of log p_k that :func:`exact_log_p2` tests (``dof < 0``: known).

    Eigenvalues of ``Pi_T^-1 Pi_W`` from trace and determinant, clamped; Gaussian bound
    :func:`gchi2.log_lower_bound` or, for ``dof >= 0``, the studentised one.
    """
    lam1, lam2 = _eigenvalues(tr, dm)
    return _bound(y, lam1, lam2, dof)


@njit('float64(float64, float64, float64, float64, float64)', cache=True,
      error_model='numpy')
def exact_log_p2(y, tr, dm, log_p_min, dof):
    """Return log p_k (eq. (7), Algorithm 2 line 5) if it may be below ``log_p_min``, else NaN.

    ``y = LLR_k / sigma^2``; ``tr`` and ``dm`` are the trace and determinant of ``Pi_T^-1
    Pi_W`` (``Pi_W = Pi_T - Pi_P``), whose eigenvalues are those of Lemma 1's ``I -
    Pi_P^1/2 Pi_T^-1 Pi_P^1/2`` (similar matrices). ``dof``: residual degrees of freedom of
    the estimated noise variance (studentised tail, :func:`gchi2.log_sf2_t`), below 0 when
    the noise level is given (Lemma 1's tail, :func:`gchi2.log_sf2`). When the bound
    (:func:`_bound`) already exceeds ``p_min`` by EXACT_REL the sample cannot be a new
    minimum and the tail is not computed. The one implementation of Algorithm 2's exact
    step: the kernel (core/llr_kernel.py ``test``) calls it, and Python through
    ``llr_common.candidate_log_p2``.
    """
    lam1, lam2 = _eigenvalues(tr, dm)
    if _bound(y, lam1, lam2, dof) > log_p_min + EXACT_REL * (1.0 - log_p_min):
        return math.nan
    if dof < 0.0:
        return log_sf2(y, lam1, lam2)
    return log_sf2_t(y, lam1, lam2, dof)
