"""The kernel's division-free skip (core/llr_skip.py ``below_skip``) never skips a test.

``below_skip`` may rule a candidate out only where the test as written (the division
chain ``s2 = rss / m`` floored, ``y = q / s2``, ``tr = tn / dett``, ``y / tr < y*``) would
rule it out too; otherwise a new minimum of p_k, hence an event, could be lost. Checked
at the boundary itself: thresholds one ulp around the chain's own ``y / tr``, on the
statistics of a real stream and on random magnitudes over the whole guarded range.
"""

import math

import numpy as np
from test_llr import friction_signal

from rwa_monitor.core.llr_skip import below_skip
from rwa_monitor.core.llr_stats import NOISE_FLOOR_ABS, NOISE_FLOOR_REL


def chain_skips(q, dett, m, rss, tn, ystar, floor):
    """Return the test's own decision (True: no exact tail), its operations in its order."""
    s2 = rss / m
    if not s2 > floor:
        s2 = floor
    y = q / s2
    tr = tn / dett
    return not (tr > 0.0 and y > 0.0 and not y / tr < ystar)


def chain_ratio(q, dett, m, rss, tn, floor):
    s2 = rss / m
    if not s2 > floor:
        s2 = floor
    return (q / s2) / (tn / dett)


def thresholds_around(ratio):
    """Thresholds from far below to far above ``ratio``, and one ulp either side of it."""
    return [ratio * f for f in (0.25, 0.999999, 1.0 - 2.0 ** -29, 1.000001, 4.0)] + [
        math.nextafter(ratio, 0.0), ratio, math.nextafter(ratio, math.inf)]


def stream_statistics():
    """Return ``(q, dett, m, rss, tn, floor)`` of every candidate of a stream (estimated s2)."""
    t, w, f = friction_signal(6000, 71, ((3000, 0.6, 0.0),), profile='crossing')
    h1, h2 = -np.sign(w), -w
    terms = np.column_stack((h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f))
    pref = np.vstack((np.zeros(6), np.cumsum(terms, axis=0)))
    window = 300
    k = np.arange(window + 1, t.size - window)
    a, b, c, u, v, e = pref[k].T
    at, bt, ct, ut, vt = pref[k + window, :5].T
    det = a * c - b * b
    dett = at * ct - bt * bt
    x1 = (c * u - b * v) / det
    x2 = (a * v - b * u) / det
    aw, bw, cw = at - a, bt - b, ct - c
    g1 = (ut - u) - (aw * x1 + bw * x2)
    g2 = (vt - v) - (bw * x1 + cw * x2)
    d1 = (ct * g1 - bt * g2) / dett
    d2 = (at * g2 - bt * g1) / dett
    q = a * d1 * d1 + 2.0 * b * d1 * d2 + c * d2 * d2
    tn = ct * aw - 2.0 * bt * bw + at * cw
    rss = e - (x1 * u + x2 * v)
    floor = NOISE_FLOOR_REL * e / k + NOISE_FLOOR_ABS
    return q, dett, (k - 2).astype(float), rss, tn, floor


def test_skip_only_where_the_division_chain_skips_on_a_stream():
    decided = undecided = 0
    for q, dett, m, rss, tn, floor in zip(*stream_statistics()):
        ratio = chain_ratio(q, dett, m, rss, tn, floor)
        for ystar in thresholds_around(ratio):
            if below_skip(q, dett, m, rss, tn, ystar):
                assert chain_skips(q, dett, m, rss, tn, ystar, floor)
                decided += 1
            elif ystar > ratio * (1.0 + 1e-6):
                undecided += 1
    # The bound is useful: it decides every candidate clearly below the threshold.
    assert decided > 0 and undecided == 0


def test_skip_only_where_the_division_chain_skips_on_random_magnitudes():
    rng = np.random.default_rng(72)
    n = 20000
    q, dett, rss, tn = (2.0 ** rng.uniform(-250.0, 250.0, n) for _ in range(4))
    m = np.floor(2.0 ** rng.uniform(0.0, 40.0, n))
    # A floor below, near or above rss / m (it only raises s2).
    floor = rss / m * rng.choice([0.0, 0.5, 1.0, 2.0], n)
    for i in range(n):
        args = (float(q[i]), float(dett[i]), float(m[i]), float(rss[i]), float(tn[i]))
        ratio = chain_ratio(*args, float(floor[i]))
        for ystar in thresholds_around(ratio):
            if 2.0 ** -250 <= ystar <= 2.0 ** 250 and below_skip(*args, ystar):
                assert chain_skips(*args, ystar, float(floor[i]))


def test_skip_declines_outside_its_range_and_on_non_finite_values():
    ok = (1e-3, 1e12, 500.0, 1e-4, 1e12)
    assert below_skip(*ok, 1e9)
    for i, bad in [(0, 0.0), (0, -1e-3), (1, math.inf), (3, -1e-4), (3, math.nan),
                   (4, 0.0), (4, 2.0 ** 251), (0, 2.0 ** -251)]:
        args = list(ok)
        args[i] = bad
        assert not below_skip(*args, 1e9)
    for ystar in (0.0, math.nan, math.inf, 2.0 ** 251):
        assert not below_skip(*ok, ystar)
