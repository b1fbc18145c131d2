"""Least-squares solves of small symmetric systems, stacked, compiled (llr_stats.solve_scaled).

Every fit of the LLR detector after a declaration (eq. (2) of the llr-realtime paper on
the before and after segments, the joint fits of the kinds, the growth tests) solves
``m theta = r`` with ``m`` a Gram matrix of 1 to about 8 columns, often for thousands of
candidate change positions at once. The solution is the pseudo-inverse's, after scaling
``m`` to its correlation matrix (diagonal 1), so that a column that is a multiple of
another (constant speed, a wheel at rest) gets the minimum-norm solution instead of a
division by zero: eigenvalues at or below ``RCOND`` x the largest are left out.

The eigenvalues and vectors come from the cyclic Jacobi method (plane rotations, each
zeroing one off-diagonal element, swept until none is left), not from LAPACK's ``syevd``
through numpy's ``pinv``: for matrices this small numpy's wrappers and LAPACK's set-up
cost about 100 us a call and 3 us a matrix in a stack, the rotations a fraction of a
microsecond. Jacobi's eigenvalues of a matrix scaled to unit diagonal are accurate
relative to each eigenvalue (SIAM J. Matrix Anal. Appl. 13(4), 1992, pp. 1204-1245),
LAPACK's relative to the largest, so the two agree to rounding on well-conditioned
systems and differ only in the components of eigenvalues near the cut-off, which neither
resolves well. One behaviour is defined for bad input: a matrix or right-hand side with a NaN or
an infinity gives a NaN solution (numpy's ``pinv`` gives NaN for a NaN matrix).
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core.jit import njit

__all__ = ['RCOND', 'solve_scaled_stack']

# Eigenvalues at or below this fraction of the largest are left out (numpy's ``pinv``
# ``rcond``, as the detector used before).
RCOND = 1e-13
# Sweeps of rotations before giving up (cyclic Jacobi converges quadratically: a 3 x 3
# system takes 3 to 5).
MAX_SWEEPS = 60
EPS = np.finfo(float).eps


@njit('float64[:, ::1](float64[:, :, ::1], float64[:, ::1])', cache=True)
def solve_scaled_stack(m, r):  # pragma: no cover - compiled
    """Return ``x[k] = m[k]^+ r[k]`` with ``m[k]`` scaled to its correlation matrix first.

    ``m``: ``(K, n, n)`` symmetric matrices; ``r``: ``(K, n)``. ``d_i = sqrt(m_ii)``
    (1 where ``m_ii <= 0``); ``x = D^-1 (D^-1 m D^-1)^+ D^-1 r``.
    """
    count, n = r.shape
    out = np.empty((count, n))
    a = np.empty((n, n))
    v = np.empty((n, n))
    d = np.empty(n)
    b = np.empty(n)
    for k in range(count):
        finite = True
        for i in range(n):
            d[i] = math.sqrt(m[k, i, i]) if m[k, i, i] > 0.0 else 1.0
        for i in range(n):
            b[i] = r[k, i] / d[i]
            finite = finite and math.isfinite(b[i])
            for j in range(n):
                a[i, j] = m[k, i, j] / (d[i] * d[j])
                finite = finite and math.isfinite(a[i, j])
                v[i, j] = 1.0 if i == j else 0.0
        if not finite:
            out[k, :] = np.nan
            continue
        _jacobi(a, v)
        largest = 0.0
        for i in range(n):
            largest = max(largest, abs(a[i, i]))
        cutoff = RCOND * largest
        for i in range(n):
            out[k, i] = 0.0
        for e in range(n):
            value = a[e, e]
            if abs(value) <= cutoff:
                continue
            dot = 0.0
            for i in range(n):
                dot += v[i, e] * b[i]
            weight = dot / value
            for i in range(n):
                out[k, i] += v[i, e] * weight
        for i in range(n):
            out[k, i] /= d[i]
    return out


@njit(cache=True)
def _jacobi(a, v):  # pragma: no cover - compiled
    """Diagonalise the symmetric ``a`` in place by rotations, accumulating them in ``v``.

    A rotation in the plane ``(p, q)`` zeroes ``a_pq`` (``tan`` of its angle the smaller
    root of ``t^2 + 2 tau t - 1 = 0``, ``tau = (a_qq - a_pp) / (2 a_pq)``); an
    off-diagonal element at or below ``EPS sqrt(|a_pp a_qq|)`` is negligible and set to
    zero. Sweeps end when one changes nothing.
    """
    n = a.shape[0]
    for _ in range(MAX_SWEEPS):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                if abs(apq) <= EPS * math.sqrt(abs(a[p, p] * a[q, q])):
                    a[p, q] = 0.0
                    a[q, p] = 0.0
                    continue
                rotated = True
                tau = (a[q, q] - a[p, p]) / (2.0 * apq)
                if abs(tau) > 1e150:
                    t = 0.5 / tau
                else:
                    t = 1.0 / (abs(tau) + math.sqrt(1.0 + tau * tau))
                    if tau < 0.0:
                        t = -t
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = t * c
                for i in range(n):
                    aip = a[i, p]
                    aiq = a[i, q]
                    a[i, p] = c * aip - s * aiq
                    a[i, q] = s * aip + c * aiq
                for i in range(n):
                    api = a[p, i]
                    aqi = a[q, i]
                    a[p, i] = c * api - s * aqi
                    a[q, i] = s * api + c * aqi
                a[p, q] = 0.0
                a[q, p] = 0.0
                for i in range(n):
                    vip = v[i, p]
                    viq = v[i, q]
                    v[i, p] = c * vip - s * viq
                    v[i, q] = s * vip + c * viq
        if not rotated:
            return
