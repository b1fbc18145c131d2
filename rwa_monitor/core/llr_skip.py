"""The bounds that decide where the LLR kernel needs the exact tail (llr-realtime paper).

Algorithm 2 computes the exact tail of eq. (7) only for a candidate that may beat p_min.
Two cheap tests rule the others out in the compiled test (core/llr_kernel.py ``test``),
each proven to rule out nothing the exact path would keep: :func:`below_skip`, the skip
bound ``y / tr < y*`` decided without its divisions, and :func:`lower_bound`, the closed
form lower bound of log p_k that ``llr_common.candidate_log_p2`` also tests.
"""

from __future__ import annotations

import math

from rwa_monitor.core.gchi2 import log_lower_bound
from rwa_monitor.core.jit import njit

# A candidate goes to the exact tail only if its lower bound of log p_k is within this
# relative margin above p_min (candidate_log_p2 tests 1e-9; rounding is ~1e-15).
SKIP_REL = 1e-7

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
