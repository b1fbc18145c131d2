"""Why a pure dry step on a real coast-down stays ``undecided``: the growth test's null.

Part of ``python -m bench coastdown_kinds`` (issue 35 item 3; docs/llr.md "Limits").
The detector's step check (core/llr_growth.py ``grows``) fits the after segment alone,
with its offsets ``h = (sign w, w)`` free, against the offsets plus a growth ``r(u) h``
over the candidate time shapes ``r(u) = min(u, u_i)`` (knots every ``window`` samples,
and the straight ramp). On a coast-down the speed falls monotonically after the change,
so every time shape is also a function of speed there, and a speed shape of the residual
that the nominal misses (and that the before segment shows just as well) is taken for a
growth.

:func:`growth_statistics` measures that on a record, off line, by white-noise least
squares on the nominal residual (the detector whitens with its AR model; the numbers are
its analogue, not its floats), against the detector's own limit
(``llr_growth.ramp_limits``): the statistic of the after segment alone, and the same with
a smooth speed shape ``S(w)`` in the null that the before and the after segment share
(fitted on both). A growth in time survives the shared shape wherever the speeds after
the change were also seen before it at another time; a shape the before segment holds at
the same speeds does not.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rwa_monitor.core.llr_growth import ramp_limits


def speed_shape(speed: np.ndarray, knots: int) -> np.ndarray:
    """Return odd speed shapes ``sign(w) max(|w| - q, 0)`` and ``sign(w) w^2``.

    ``q``: ``knots`` quantiles of ``|w|`` at equal steps (a piecewise-linear shape in the
    speed with a curvature term; the friction of both rotation directions is odd in w).
    """
    mag = np.abs(speed)
    levels = np.quantile(mag, np.linspace(0.0, 1.0, knots + 2)[1:-1])
    sign = np.sign(speed)
    return np.column_stack([sign * np.maximum(mag - q, 0.0) for q in levels]
                           + [sign * mag * mag])


def _rss(design: np.ndarray, y: np.ndarray) -> float:
    beta = np.linalg.lstsq(design, y, rcond=None)[0]
    r = y - design @ beta
    return float(r @ r)


def growth_statistics(time: np.ndarray, speed: np.ndarray, residual: np.ndarray,
                      change_time: float, window: int, z_threshold: float,
                      knots: tuple[int, ...] = (2, 4, 8)) -> dict[str, Any]:
    """Return the step-check statistics of one change (white-noise analogue, see module).

    ``residual``: friction less the nominal, NaN where not tested; before = tested
    samples before ``change_time``, after = from it. ``after_only``: ``max_r (RSS_step -
    RSS_growth) / sigma^2`` on the after segment alone (the detector's ``grows``);
    ``shared_speed_shape[k]``: the same with a speed shape of ``k`` knots
    (:func:`speed_shape`) shared by the two segments in both fits; ``limit``: the
    detector's ``chi2_2`` limit at the category level over the ``m`` time shapes.
    ``sigma^2`` from the before segment's step-model fit.
    """
    t, w, e = (np.asarray(a, dtype=float) for a in (time, speed, residual))
    ok = np.isfinite(e) & np.isfinite(w)
    before, after = ok & (t < change_time), ok & (t >= change_time)
    if before.sum() < 10 or after.sum() < window:
        raise ValueError('too few tested samples before or after the change')
    h = np.column_stack([np.sign(w), w])
    noise_var = _rss(h[before], e[before]) / (before.sum() - 2)
    u = t[after] - t[after][0]
    shapes = [np.minimum(u, k) for k in u[window - 1::window]] + [u]
    limit = ramp_limits(2, z_threshold, len(shapes))[0]
    ha, ya = h[after], e[after]
    step = _rss(ha, ya)
    after_only = max(step - _rss(np.column_stack([ha, r[:, None] * ha]), ya)
                     for r in shapes) / noise_var
    both = before | after
    y = e[both]
    late = after[both]
    hb = h[both]
    offsets = np.column_stack([hb, hb * late[:, None]])
    shared = {}
    for k in knots:
        null = np.column_stack([offsets, speed_shape(w[both], k)])
        base = _rss(null, y)
        best = 0.0
        for r in shapes:
            grow = np.zeros(y.size)
            grow[late] = r
            best = max(best, base - _rss(np.column_stack([null, grow[:, None] * hb]), y))
        shared[k] = best / noise_var
    return {'after_only': after_only, 'shared_speed_shape': shared, 'limit': limit,
            'shapes': len(shapes), 'before': int(before.sum()), 'after': int(after.sum())}
