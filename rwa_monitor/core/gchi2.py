"""Tail probability of a generalised chi-square variable (llr-realtime paper, Lemma 1, eq. (7)).

``Q = sum_i w_i (Z_i + m_i)^2`` with ``Z_i`` iid N(0, 1) and ``w_i > 0``.

Two-term central case (the paper's nominal LLR): exact one-dimensional integral. With
``w1 >= w2``, polar coordinates ``Z = R (cos t, sin t)`` (``R^2`` ~ chi2_2, ``t`` uniform)
and the change of angle ``tan t = sqrt(w1 / w2) tan psi`` give::

    P(Q > x) = exp(-b) * (2/pi) * int_0^{pi/2} exp(-a sin^2 psi / (cos^2 psi + rho sin^2 psi)) dpsi
    b = x / (2 w1),   rho = w2 / w1,   a = b (1 - rho).

The factor ``exp(-b)`` carries the whole scale of the tail (so the logarithm never
underflows) and the integrand lies in (0, 1] with a peak of width ``~1/sqrt(a)`` at 0. The
integral is cut where the integrand falls below ``exp(-CUT)`` (``a sin^2 psi >= CUT``) and
evaluated with a fixed Gauss-Legendre rule on the remaining interval, whose length scales
with the peak: the rule sees the same shape for every ``a``. Accuracy (relative error
<= 1e-9 against a high-precision reference for tails from 0.5 down to 1e-12 over weight
ratios 1 to 1e12) is checked in test/test_gchi2.py.

General case (more terms and/or non-zero means): Gil-Pelaez / Laplace inversion along the
vertical line through the saddle point of ``K(s) - s x - log s``, with ``K`` the cumulant
generating function; the integrand is normalised by its value at the saddle and the
integral is evaluated by adaptive quadrature (``scipy.integrate.quad``, relative tolerance
1e-10; its error estimate is returned by :func:`gchi2_logsf_general`).

Cheap bounds for the streaming detector: with ``w_max`` the largest weight,
``P(w_max Z^2 > x) <= P(Q > x) <= P(w_max chi2_p > x)`` (central case). For p = 2 the
upper bound is ``exp(-b)``. :func:`log_lower_bound` gives a closed-form lower bound of
``log erfc(sqrt(b))`` and :func:`skip_threshold` inverts it, so that a caller holding the
smallest tail seen so far can skip the exact evaluation of any statistic that cannot beat
it (``b_hi < skip_threshold(log_p_min)`` implies ``P > p_min``).

scipy is imported by the general functions when they run: the detector's compiled tail
needs none of it, and scipy's integrate, optimize and special took about 0.5 s of a fleet
worker's CPU at its first task.
"""

from __future__ import annotations

import cmath
import math
from typing import Sequence

import numpy as np
from numpy.polynomial.legendre import leggauss

from rwa_monitor.core.jit import njit

CUT = 40.0
_GL_ORDER = 32
_x, _w = leggauss(_GL_ORDER)
_NODES = tuple(float(v) for v in (_x + 1.0) / 2.0)
_WEIGHTS = tuple(float(v) for v in _w / 2.0)
_NODES_ARR = (_x + 1.0) / 2.0
_WEIGHTS_ARR = _w / 2.0
_LOG_2_OVER_PI = math.log(2.0 / math.pi)
_LOG_2_OVER_SQRT_PI = math.log(2.0 / math.sqrt(math.pi))
_HALF_PI = math.pi / 2.0


@njit('float64(float64, float64, float64)', cache=True)
def log_sf2(x: float, w1: float, w2: float) -> float:
    """Return log P(w1 Z1^2 + w2 Z2^2 > x) for the central two-term case (compiled).

    Lemma 1 / Algorithm 2 line 5 of the llr-realtime paper. Exact up to the quadrature
    error (see the module docstring). ``w1``, ``w2`` >= 0 in any order; ``x <= 0`` gives 0
    (probability one); all-zero weights give ``-inf`` for ``x > 0``.
    """
    if not x > 0.0:
        return 0.0
    if w1 < w2:
        w1, w2 = w2, w1
    if not w1 > 0.0:
        return -math.inf
    b = x / (2.0 * w1)
    rho = w2 / w1 if w2 > 0.0 else 0.0
    a = b * (1.0 - rho)
    excess = a - CUT * rho
    end = math.atan(math.sqrt(CUT / excess)) if excess > 0.0 else _HALF_PI
    total = 0.0
    for i in range(_GL_ORDER):
        psi = end * _NODES[i]
        s = math.sin(psi)
        c = math.cos(psi)
        s2 = s * s
        total += _WEIGHTS[i] * math.exp(-a * s2 / (c * c + rho * s2))
    return -b + math.log(total * end) + _LOG_2_OVER_PI


@njit('float64(float64, float64, float64, float64)', cache=True)
def log_sf2_t(x: float, w1: float, w2: float, dof: float) -> float:
    """Return log P(w1 Z1^2 + w2 Z2^2 > x S), S ~ chi2_dof / dof independent (compiled).

    The studentised tail of Lemma 1 when the noise variance is estimated with ``dof``
    residual degrees of freedom independently of the statistic. Averaging the integrand
    ``exp(-x S k(psi))`` of :func:`log_sf2` over ``S`` gives ``(1 + 2 x k(psi) / dof)^(-dof /
    2)``; as there, the value at ``psi = 0``, ``(1 + 2 b / dof)^(-dof / 2)``, is factored
    out, the rest ``(1 + a' h(psi))^(-dof / 2)`` with ``a' = 2 a / (dof + 2 b)`` and ``h =
    sin^2 / (cos^2 + rho sin^2)`` is cut where it falls below ``exp(-CUT)`` and integrated
    with the same rule. Tends to :func:`log_sf2` as ``dof`` grows.
    """
    if not x > 0.0:
        return 0.0
    if w1 < w2:
        w1, w2 = w2, w1
    if not w1 > 0.0:
        return -math.inf
    b = x / (2.0 * w1)
    rho = w2 / w1 if w2 > 0.0 else 0.0
    a = b * (1.0 - rho)
    half = 0.5 * dof
    lead = -half * math.log1p(2.0 * b / dof)
    ap = 2.0 * a / (dof + 2.0 * b)
    end = _HALF_PI
    if ap > 0.0:
        big = math.expm1(CUT / half) / ap
        if rho * big < 1.0:
            end = math.atan(math.sqrt(big / (1.0 - rho * big)))
    total = 0.0
    for i in range(_GL_ORDER):
        psi = end * _NODES[i]
        s = math.sin(psi)
        c = math.cos(psi)
        s2 = s * s
        total += _WEIGHTS[i] * math.exp(-half * math.log1p(ap * s2 / (c * c + rho * s2)))
    return lead + math.log(total * end) + _LOG_2_OVER_PI


def _log_sf2_array(x: np.ndarray, w1: float, w2: float) -> np.ndarray:
    """Vectorised :func:`log_sf2` over ``x`` for fixed weights (w1 >= w2 >= 0, w1 > 0)."""
    x = np.asarray(x, dtype=float)
    out = np.zeros(x.shape)
    pos = x > 0.0
    if not np.any(pos):
        return out
    xp = x[pos]
    b = xp / (2.0 * w1)
    rho = w2 / w1
    a = b * (1.0 - rho)
    excess = a - CUT * rho
    end = np.where(excess > 0.0, np.arctan(np.sqrt(CUT / np.where(excess > 0.0, excess, 1.0))),
                   _HALF_PI)
    psi = end[:, None] * _NODES_ARR[None, :]
    s2 = np.sin(psi) ** 2
    c2 = np.cos(psi) ** 2
    vals = np.exp(-a[:, None] * s2 / (c2 + rho * s2)) @ _WEIGHTS_ARR
    out[pos] = -b + np.log(vals * end) + _LOG_2_OVER_PI
    return out


@njit('float64(float64)', cache=True)
def log_lower_bound(b: float) -> float:
    """Return a lower bound of ``log erfc(sqrt(b))`` (closed form, b >= 0).

    Uses ``erfc(z) > 2 exp(-z^2) / (sqrt(pi) (z + sqrt(z^2 + 2)))``. With ``b = x / (2
    w_max)`` this bounds ``log P(Q > x)`` from below for any weights. A ``b`` below 0
    (rounding) is taken as 0, where the bound is largest (it is decreasing in ``b``).
    """
    if not b > 0.0:
        b = 0.0
    z = math.sqrt(b)
    return -b + _LOG_2_OVER_SQRT_PI - math.log(z + math.sqrt(b + 2.0))


def log_lower_bound_array(b: np.ndarray) -> np.ndarray:
    """Vectorised :func:`log_lower_bound`."""
    b = np.maximum(np.asarray(b, dtype=float), 0.0)
    return -b + _LOG_2_OVER_SQRT_PI - np.log(np.sqrt(b) + np.sqrt(b + 2.0))


@njit('float64(float64)', cache=True)
def skip_threshold(log_p: float) -> float:
    """Return ``y`` >= 0 such that ``b < y`` implies ``log_lower_bound(b) > log_p``.

    :func:`log_lower_bound` is decreasing and convex; Newton's method from the left
    converges monotonically to the root, and the returned value is moved to the safe
    (smaller) side. ``log_p >= log_lower_bound(0)`` gives 0 (nothing can be skipped).
    """
    if not log_p < log_lower_bound(0.0):
        return 0.0
    # Start left of the root: y* <= -log_p, hence y* >= -log_p + log(2/sqrt(pi)) -
    # log(2 sqrt(2 - log_p)).
    y = max(1e-300, -log_p + _LOG_2_OVER_SQRT_PI - math.log(2.0 * math.sqrt(2.0 - log_p)))
    for _ in range(60):
        g = log_lower_bound(y) - log_p
        if g <= 0.0:
            break
        step = g / (1.0 + 0.5 / math.sqrt(y * (y + 2.0)))
        y += step
        if step <= 1e-13 * y:
            break
    while y > 0.0 and not log_lower_bound(y) > log_p:
        y = max(0.0, y - 1e-12 * (1.0 + y))
    return y


def _cgf(s: complex, terms: Sequence[tuple[float, float, float]]) -> complex:
    """Cumulant generating function ``sum -k log(1 - 2 w s) + m2 w s / (1 - 2 w s)``.

    ``terms`` holds ``(w, m2, k)``: weight, squared mean, half the degrees of freedom.
    """
    total = 0j
    for w, m2, k in terms:
        one = 1.0 - 2.0 * w * s
        total += -k * cmath.log(one) + m2 * w * s / one
    return total


def gchi2_logsf_general(x: float, weights: Sequence[float],
                        means: Sequence[float] | None = None,
                        dof: float | None = None) -> tuple[float, float]:
    """Return ``(log P(Q > x S), relative error estimate)`` for any weights and means.

    ``Q = sum w_i (Z_i + m_i)^2``; ``S = 1`` if ``dof`` is None, else an independent
    ``chi2_dof / dof`` (studentised case: the noise variance estimated with ``dof`` degrees
    of freedom). Laplace inversion of ``X = Q - x S`` at 0: ``P(X > 0) = (1/pi) int_0^inf
    Re[M(c + i t) / (c + i t)] dt`` with ``M`` the moment generating function of ``X`` and
    ``c`` in ``(0, 1/(2 w_max))`` the saddle point of ``K(s) - log s``. The integrand is
    divided by its value at ``t = 0`` (no underflow). For ``S = 1`` the factor ``exp(-i t
    x)`` is split off and the cosine and sine Fourier integrals of the slowly varying rest
    use QUADPACK's QAWF. The error estimate is the quadrature's, relative to the integral.
    """
    from scipy import integrate, optimize
    w = np.asarray(weights, dtype=float).ravel()
    m2 = np.zeros_like(w) if means is None else np.asarray(means, dtype=float).ravel() ** 2
    keep = w > 0.0
    w, m2 = w[keep], m2[keep]
    if not x > 0.0:
        return 0.0, 0.0
    if w.size == 0:
        return -math.inf, 0.0
    terms = [(wi, mi, 0.5) for wi, mi in zip(w.tolist(), m2.tolist())]
    shift = x
    if dof is not None:
        terms.append((-x / dof, 0.0, 0.5 * dof))
        shift = 0.0
    s_max = 1.0 / (2.0 * w.max())

    def dphi(s: float) -> float:
        total = -shift - 1.0 / s
        for wi, mi, k in terms:
            one = 1.0 - 2.0 * wi * s
            total += 2.0 * k * wi / one + mi * wi / (one * one)
        return total

    lo, hi = s_max * 1e-15, s_max * (1.0 - 1e-15)
    if dphi(lo) > 0.0:
        c = lo
    elif dphi(hi) < 0.0:
        c = hi
    else:
        c = optimize.brentq(dphi, lo, hi, xtol=1e-300, rtol=1e-14, maxiter=500)
    k0 = _cgf(c, terms).real - c * shift - math.log(c)
    d2 = 1.0 / (c * c)
    for wi, mi, k in terms:
        one = 1.0 - 2.0 * wi * c
        d2 += 4.0 * k * wi * wi / (one * one) + 4.0 * mi * wi * wi / one ** 3
    scale = 1.0 / math.sqrt(d2)

    # The integrand is Re[A(t) exp(-i t x)] with A slowly varying (for S = 1, A excludes
    # the factor exp(-i t x) of M; in the studentised case with many degrees of freedom
    # the phase of the S term is close to -t x and is given back): cosine and sine
    # Fourier integrals (QAWF). Few degrees of freedom: the integrand decays fast and a
    # plain adaptive quadrature is used.
    fourier = dof is None or dof >= 100.0
    back = 0.0 if dof is None or not fourier else x

    seen: dict[float, complex] = {}

    def amplitude(u: float) -> complex:
        # The cosine and sine integrals sample the same points: evaluate each once.
        value = seen.get(u)
        if value is None:
            t = u * scale
            s = complex(c, t)
            value = cmath.exp(_cgf(s, terms) - c * shift + complex(0.0, t * back)
                              - cmath.log(s) - k0)
            seen[u] = value
        return value

    if fourier:
        freq = x * scale
        cos_part, err_c = integrate.quad(lambda u: amplitude(u).real, 0.0, np.inf,
                                         weight='cos', wvar=freq, epsabs=1e-11, limlst=200)
        sin_part, err_s = integrate.quad(lambda u: amplitude(u).imag, 0.0, np.inf,
                                         weight='sin', wvar=freq, epsabs=1e-11, limlst=200)
        val, err = cos_part + sin_part, err_c + err_s
    else:
        val, err = integrate.quad(lambda u: amplitude(u).real, 0.0, np.inf, epsabs=1e-12,
                                  epsrel=1e-11, limit=500)
    val *= scale / math.pi
    err *= scale / math.pi
    if not val > 0.0:
        return -math.inf, math.inf
    return k0 + math.log(val), err / val


def gchi2_logsf(x, weights: Sequence[float], means: Sequence[float] | None = None,
                dof: float | None = None):
    """Return ``log P(sum_i w_i (Z_i + m_i)^2 > x S)``, vectorised over ``x``.

    ``S = 1`` (``dof`` None) or ``chi2_dof / dof`` (studentised). Central case with at most
    two terms: :func:`log_sf2` / :func:`log_sf2_t` (exact integral, fixed Gauss-Legendre
    rule). Otherwise :func:`gchi2_logsf_general` per element.
    """
    if dof is not None and not (isinstance(dof, (int, float)) and dof > 0.0):
        raise ValueError(f'dof must be a number in (0, inf) or None, got {dof!r}')
    w = np.asarray(weights, dtype=float).ravel()
    if w.size == 0 or np.any(~np.isfinite(w)) or np.any(w < 0.0) or not np.any(w > 0.0):
        raise ValueError(f'weights must be finite, >= 0 and not all zero; got {weights!r}')
    if means is not None:
        mu = np.asarray(means, dtype=float).ravel()
        if mu.shape != w.shape or np.any(~np.isfinite(mu)):
            raise ValueError('means must be finite and have one entry per weight')
    else:
        mu = None
    x_arr = np.asarray(x, dtype=float)
    central = mu is None or not np.any(mu[w > 0.0])
    wp = np.sort(w[w > 0.0])[::-1]
    if central and wp.size <= 2:
        w1 = float(wp[0])
        w2 = float(wp[1]) if wp.size == 2 else 0.0
        if dof is None:
            out = _log_sf2_array(x_arr.ravel(), w1, w2).reshape(x_arr.shape)
        else:
            out = np.asarray([log_sf2_t(float(v), w1, w2, float(dof)) for v in x_arr.ravel()],
                             dtype=float).reshape(x_arr.shape)
    else:
        flat = [gchi2_logsf_general(float(v), w, mu, dof)[0] for v in x_arr.ravel()]
        out = np.asarray(flat, dtype=float).reshape(x_arr.shape)
    return float(out) if out.ndim == 0 else out


def gchi2_sf(x, weights: Sequence[float], means: Sequence[float] | None = None,
             dof: float | None = None):
    """Return ``P(sum_i w_i (Z_i + m_i)^2 > x S)`` (Lemma 1 of the llr-realtime paper).

    ``weights`` are the ``w_i >= 0`` (the eigenvalues ``lambda_i`` of Lemma 1), ``means``
    the optional ``m_i`` (non-central case: detection probability under a change), ``dof``
    the optional degrees of freedom of an independent variance estimate (``S ~ chi2_dof /
    dof``; None: ``S = 1``). Vectorised over ``x``; ``x <= 0`` gives 1.
    """
    out = np.exp(gchi2_logsf(x, weights, means, dof))
    return float(out) if np.ndim(out) == 0 else out


def gchi2_isf(p: float, weights: Sequence[float], dof: float | None = None) -> float:
    """Return the ``x`` with ``P(sum_i w_i Z_i^2 > x S) = p`` (central case), p in (0, 1).

    Root of ``log sf(x) = log p`` bracketed by ``w_max chi2_1.isf(p)`` (lower bound of
    the tail) and ``w_max chi2_p.isf(p)`` (upper bound); with ``dof`` the upper end is
    doubled until it brackets.
    """
    if not 0.0 < p < 1.0:
        raise ValueError(f'p must be a number in (0, 1), got {p!r}')
    w = np.asarray(weights, dtype=float).ravel()
    if w.size == 0 or np.any(~np.isfinite(w)) or np.any(w < 0.0) or not np.any(w > 0.0):
        raise ValueError(f'weights must be finite, >= 0 and not all zero; got {weights!r}')
    from scipy import optimize, special
    wmax = float(w.max())
    npos = int(np.count_nonzero(w > 0.0))
    lo = wmax * 2.0 * float(special.erfcinv(p)) ** 2
    hi = wmax * float(special.chdtri(npos, p))
    if dof is None and (npos == 1 or hi <= lo):
        return lo
    target = math.log(p)

    def f(v: float) -> float:
        return float(gchi2_logsf(v, w, None, dof)) - target

    if f(lo) <= 0.0:
        return lo
    while f(hi) >= 0.0:
        hi *= 2.0
    return float(optimize.brentq(f, lo, hi, xtol=1e-300, rtol=1e-13, maxiter=200))
