"""Output error: the speed a friction model predicts, against the speed measured.

When friction was derived from speed (eq. 1b of the physics-informed paper, f = J dw/dt
- K_T I), the model's worth is shown on what was measured: the speed obtained by
integrating J dw/dt = u + f(w, t) from the first measured sample of each segment
(a run without gaps; on a coast-down u = 0), compared with the measured speed. A
derivative amplifies the speed noise by the differentiator's gain; the integrated speed
does not, so small, systematic model errors (a missing drag term) dominate it.

Initial value: the first sample's speed, corrected by the median misfit of the
integrated speed over the segment's first 2h+1 samples (h the differentiator's half
width) and integrated again. A per-revolution speed carries single glitched samples
(one pulse late: one speed high, the next low); taken as is, such a first sample set
the whole trajectory off by its error (0.27 rad/s on one drum run, ten times the
model's error). The median over a window is not moved by one glitch; both models get
the same rule.

Integration: classical Runge-Kutta (order 4) on the sample times, u held over each
interval (the zero-order hold of a torque command), aux channels and history channels
(hysteresis) taken at the interval's start; time-dependent effects (drift, periodic) are
evaluated at the stage times. Effects with a state or a position (effects_motion.py:
lag, stop, pre-sliding state, position) are simulated along the measured speed and
held over each interval, as the history channel is. Each segment's coefficients are
those of the baseline segment (friction jumps) the sample belongs to.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify import effects_motion as em


def _friction(selection, coef: np.ndarray, effects: list, w: np.ndarray, t: np.ndarray,
              rows: np.ndarray) -> np.ndarray:
    """Return f(w, t) of a model (coefficients ``coef``) for rows' segment and aux."""
    data = selection.data
    seg = np.searchsorted(np.asarray(selection.segments.starts), rows, side='right') - 1
    dry, visc = coef[2 * seg], coef[2 * seg + 1]
    f = -dry * np.sign(w) - visc * w
    aux = {k: v[rows] for k, v in data.aux.items()}
    if data.past is not None:
        aux[fx.LEFT_ZERO] = data.past.left_zero[rows].astype(float)
    for eff in effects:
        if eff.kind in em.KINDS:
            f = f + _along_record(selection, eff)[rows] @ coef[eff.columns]
            continue
        cols = [col(w, t, aux) for _, col in fx.regressor_columns(eff.kind, eff.params)]
        f = f + np.column_stack(cols) @ coef[eff.columns]
    return f


def _along_record(selection, eff) -> np.ndarray:
    """Return an effect's columns simulated along the measured record (cached)."""
    cache = selection.__dict__.setdefault('_state_columns', {})
    key = (eff.name, repr(sorted(eff.params.items())))
    if key not in cache:
        cache[key] = fx.evaluate(eff.kind, eff.params, selection.data)
    return cache[key]


def integrate_speed(selection, inertia: float, model: str, torque: np.ndarray | None = None,
                    starts: list[int] | None = None) -> np.ndarray:
    """Return the speed predicted by the ``baseline`` or ``refined`` model at every sample.

    ``starts`` are the first rows of the segments (default: the data's runs); ``torque``
    the drive torque u per sample (N m; None on a coast).
    """
    data = selection.data
    n = len(data)
    coef = selection.baseline_fit.coef if model == 'baseline' else selection.final_fit.coef
    effects = [] if model == 'baseline' else selection.effects
    u = np.zeros(n) if torque is None else np.asarray(torque, dtype=float)
    bounds = list(starts if starts is not None else data.runs) + [n]
    out = np.empty(n)
    first = 2 * max(data.half_width, 1) + 1
    for a, b in zip(bounds[:-1], bounds[1:]):
        start = float(data.speed[a])
        path = _segment(selection, coef, effects, inertia, u, a, b, start)
        m = min(first, b - a)
        misfit = float(np.median(path[:m] - data.speed[a:a + m]))
        out[a:b] = _segment(selection, coef, effects, inertia, u, a, b, start - misfit) \
            if misfit != 0.0 else path
    return out


def _segment(selection, coef, effects, inertia, u, a, b, start: float) -> np.ndarray:
    """Integrate one segment (rows a..b-1) from ``start`` (rad/s): one RK4 per step."""
    t = selection.data.time
    w = np.empty(b - a)
    w[0] = start
    for k in range(a, b - 1):
        h = t[k + 1] - t[k]
        row = np.array([k])

        def rate(speed: float, time: float) -> float:
            f = _friction(selection, coef, effects, np.array([speed]), np.array([time]), row)
            return float((u[k] + f[0]) / inertia)
        x = w[k - a]
        k1 = rate(x, t[k])
        k2 = rate(x + 0.5 * h * k1, t[k] + 0.5 * h)
        k3 = rate(x + 0.5 * h * k2, t[k] + 0.5 * h)
        k4 = rate(x + h * k3, t[k + 1])
        w[k - a + 1] = x + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
    return w


def speed_rmse(selection, inertia: float, torque: np.ndarray | None = None) -> dict:
    """Return {'before', 'after'} speed RMSE (rad/s), and the details per segment.

    With several segments the RMSE is taken over the held-out segments (every third, as
    the rows' blocks) when there are at least three segments, else over all.
    """
    data = selection.data
    runs = list(data.runs)
    bounds = runs + [len(data)]
    measured = data.speed
    pred = {m: integrate_speed(selection, inertia, m, torque) for m in ('baseline', 'refined')}
    per = []
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        per.append({'first_row': int(a), 'rows': int(b - a),
                    'held_out': bool(len(runs) >= 3 and i % 3 == 2),
                    'before': float(np.sqrt(np.mean((pred['baseline'][a:b]
                                                     - measured[a:b]) ** 2))),
                    'after': float(np.sqrt(np.mean((pred['refined'][a:b]
                                                    - measured[a:b]) ** 2)))})
    use = [p for p in per if p['held_out']] or per

    def pooled(key: str) -> float:
        return float(np.sqrt(sum(p[key] ** 2 * p['rows'] for p in use)
                             / sum(p['rows'] for p in use)))
    return {'before': pooled('before'), 'after': pooled('after'), 'segments': per,
            'scored_on': 'held-out segments' if use is not per else 'all segments'}
