"""Candidate friction effects: the physics of each, and its regressor columns.

Every column follows the sign of model (1) of the llr-realtime paper: f = h x with
h = -[sign(w), w], so a positive weight is a torque that opposes the motion. Each effect
adds linear columns; the few nonlinear parameters (a speed scale, an exponent, a
frequency) are profiled over a small grid, and every grid point counts as one test in
the Bonferroni correction of the selection (select.py).

Effects (names are the DESIGN.md vocabulary):

- ``stribeck``: at low speed the lubricant film has not built up and the contact is
  metal-on-metal; friction rises from the Coulomb level to the static (breakaway) level
  as |w| -> 0. Column -sign(w) exp(-(|w|/w_s)^d); the weight is the static excess
  torque, w_s the Stribeck speed, d = 2 (Gaussian) or 1 (exponential).
- ``stribeck_hysteresis``: friction with a memory of the direction of approach. Leaving
  zero speed the contact breaks away: friction follows the Stribeck curve (static peak,
  then down to Coulomb as the lubricant film builds); approaching zero the film still
  carries the load and friction stays at the Coulomb level: the friction-speed curve is
  a loop, not a function (the hysteresis measured on lubricated contacts under
  oscillating speed, lower friction on the decelerating branch). Column
  -sign(w) S(abs(w)) L, L = 1 while the wheel has moved away from zero speed ever since
  its last zero passage (history.py ``left_zero``), else 0; S the Stribeck shape:
  ``peak`` sqrt(e) x exp(-x^2/2) (zero at rest, maximum at x = 1: the excess of a
  friction that is regularised through zero, as a bearing's is inside its pre-sliding
  band), or exp(-x^2), exp(-x); x = abs(w)/w_s. The weight is the static excess (peak
  minus Coulomb), w_s the Stribeck speed (the speed of the peak for ``peak``).
- ``presliding``: near zero speed the contact does not slide: its asperities (or the
  rolling elements' contact patches) deform elastically first, so friction passes
  through zero continuously instead of jumping by twice the Coulomb level (Dahl's
  pre-sliding regime; the regularised Coulomb friction of simulators, whose band keeps
  an integrator from chattering at zero speed). Column -(r(w/w_b) - sign(w)), r = a
  linear ramp clipped at +-1 or tanh; the weight is the Coulomb level the ramp replaces,
  w_b the width of the band.
- ``asymmetric_coulomb``: dry friction that differs with the spin direction (preload or
  seal lay, a bias in the torque or current measurement). Column -1 for w != 0, so that
  dry_positive = dry + offset, dry_negative = dry - offset. Needs both directions.
- ``drag``: losses that grow faster than linearly with speed: aerodynamic drag
  (~ w|w|) and lubricant churning (exponent between 1 and 2 or beyond). Column
  -sign(w)|w|^n, n = 2 or free (grid).
- ``aux:<column>:dry`` / ``aux:<column>:viscous``: dry or viscous friction depending on
  an auxiliary channel a (temperature changes the lubricant's viscosity and the bearing
  preload; current heats the motor). Column -sign(w)(a - a0) or -w(a - a0), a0 the mean.
- ``drift``: slow change in time (lubricant loss or migration, run-in, wear). Column
  -sign(w) tau (dry), -w tau (viscous) or -tau (torque offset), tau = (t - t0) / T.
- ``periodic``: a disturbance periodic in time (thermal cycle of an orbit, a structural
  mode, a cage frequency). Columns cos(2 pi f (t - t0)), sin(...); f from the largest
  peaks of the residual's spectrum.
- ``smooth_speed``: the generic fallback, a piecewise-linear function of speed on each
  side of zero (free to jump at w = 0, as friction does; hat
  functions on 12 quantile knots plus knots at 0 and at +- the 0.5, 1, 2, 4 and 8 %
  quantiles of |w|, where low-speed effects live). Not physics: it proves that friction
  depends on speed in a way model (1) misses when no named effect fits.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from rwa_monitor.core.identify import effects_motion as em
from rwa_monitor.core.identify.candidate import Candidate
from rwa_monitor.core.identify.candidates_motion import motion_candidates, speed_noise
from rwa_monitor.core.identify.data import IdentData, speed_history
from rwa_monitor.core.identify.fitting import held_out_mask

Column = Callable[..., np.ndarray]
NAMED = ('stribeck', 'stribeck_hysteresis', 'presliding', 'presliding_state',
         'frictional_lag', 'stick', 'asymmetric_coulomb', 'drag', 'inertia', 'gravity_load',
         'load_dry', 'gear_ripple', 'aux', 'drift', 'periodic')
FALLBACK = 'smooth_speed'
DRAG_EXPONENTS = (2.0, 1.25, 1.5, 1.75, 2.5, 3.0, 4.0)
STRIBECK_QUANTILES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.35)
PERIODIC_PEAKS = 3
HYSTERESIS_SHAPES = ('peak', 2.0, 1.0)
HYSTERESIS_GRID = 16           # Stribeck speeds, geometric between the quantiles below
HYSTERESIS_RANGE = (0.005, 0.35)
PRESLIDING_SHAPES = ('linear', 'tanh')
PRESLIDING_GRID = 10
PRESLIDING_RANGE = (0.001, 0.05)   # quantiles of abs(w) spanned by the band widths
LEFT_ZERO = 'history:left_zero'   # the history channel the hysteresis column reads
SMOOTH_KNOTS = 12
NEAR_ZERO = (0.005, 0.01, 0.02, 0.04, 0.08)  # quantiles of abs(w): extra knots


POSITIVE_WEIGHT = ('stribeck', 'stribeck_hysteresis', 'presliding', 'drag')
# Effects whose weight has a physical sign (positive: it opposes the motion): the
# Stribeck and hysteresis excess is the static level above Coulomb (friction rises as
# the wheel leaves rest), the pre-sliding weight is the Coulomb level the ramp replaces
# (friction falls inside the band), drag is a loss. A fit with the other sign is not that
# effect: a pre-sliding band with a negative weight is a Stribeck curve, a Stribeck term
# with a negative excess and a speed scale of the whole range is curvature (drag).


def physical_weights(kind: str, weights: np.ndarray) -> bool:
    """Return whether an effect's fitted weights have their physical sign (POSITIVE_WEIGHT).

    Effects with a state or a position: effects_motion.POSITIVE_COLUMNS.
    """
    if kind in em.KINDS:
        return em.positive_columns(kind, weights)
    return kind not in POSITIVE_WEIGHT or bool(np.all(np.asarray(weights) > 0))


def canonical_order(names) -> list[str]:
    """Return effect names in the vocabulary's order (NAMED, then the fallback), then by name.

    The order the selection added them in depends on noise (two effects of nearly equal
    evidence swap places); reports list effects in this order so that two wheels with the
    same effects read the same.
    """
    order = NAMED + (FALLBACK,)

    def key(name: str) -> tuple[int, str]:
        kind = name.split(':')[0]
        return (order.index(kind) if kind in order else len(order), name)
    return sorted(names, key=key)


def _get(aux, name):
    if aux is None or name not in aux:
        raise KeyError(f'the friction model needs the auxiliary channel {name!r}')
    return np.asarray(aux[name], dtype=float)


def stribeck_shape(speed: np.ndarray, velocity: float, shape) -> np.ndarray:
    """Return S(abs(w)) of the Stribeck excess: ``peak``, or exp(-x^shape)."""
    x = np.abs(np.asarray(speed, dtype=float)) / velocity
    if shape == 'peak':
        return np.sqrt(np.e) * x * np.exp(-0.5 * x * x)
    return np.exp(-x ** float(shape))


def _left_zero(w, t, a) -> np.ndarray:
    """Return the history channel ``left_zero``: from aux, or computed from a batch."""
    if a is not None and LEFT_ZERO in a:
        return np.asarray(a[LEFT_ZERO], dtype=float)
    w = np.atleast_1d(np.asarray(w, dtype=float))
    if len(w) < 5 or t is None:
        raise KeyError(LEFT_ZERO)
    return speed_history(np.atleast_1d(np.asarray(t, dtype=float)), w).left_zero.astype(float)


def regressor_columns(kind: str, params: dict) -> list[tuple[str, Column]]:
    """Return (weight name, column(speed, time, aux)) pairs of an effect.

    ``aux`` is a mapping of auxiliary channel name -> values (arrays or scalars). These
    callables are the single definition of every effect, used by the selection and by
    the refined model fed back to the detectors. Effects with a state or a position:
    effects_motion.py (their columns need the record: time and speed of every sample).
    """
    if kind in em.KINDS:
        return em.regressor_columns(kind, params)
    if kind == 'stribeck':
        ws, shape = float(params['velocity_rad_s']), float(params.get('shape', 2.0))
        return [('stribeck', lambda w, t, a: -np.sign(w) * np.exp(-(np.abs(w) / ws) ** shape))]
    if kind == 'stribeck_hysteresis':
        ws, shape = float(params['velocity_rad_s']), params.get('shape', 'peak')
        shape = shape if shape == 'peak' else float(shape)
        return [('stribeck_hysteresis', lambda w, t, a: -np.sign(w) * stribeck_shape(
            w, ws, shape) * _left_zero(w, t, a))]
    if kind == 'presliding':
        wb, shape = float(params['band_rad_s']), params.get('shape', 'linear')
        ramp = (lambda x: np.clip(x, -1.0, 1.0)) if shape == 'linear' else np.tanh
        return [('presliding', lambda w, t, a: -(ramp(np.asarray(w) / wb) - np.sign(w)))]
    if kind == 'asymmetric_coulomb':
        return [('offset', lambda w, t, a: -(np.asarray(w) != 0).astype(float))]
    if kind == 'drag':
        n = float(params['exponent'])
        return [('drag', lambda w, t, a: -np.sign(w) * np.abs(w) ** n)]
    if kind == 'aux':
        col, comp, a0 = params['column'], params['component'], float(params['center'])
        if comp == 'dry':
            return [('aux', lambda w, t, a: -np.sign(w) * (_get(a, col) - a0))]
        return [('aux', lambda w, t, a: -np.asarray(w) * (_get(a, col) - a0))]
    if kind == 'drift':
        comp, t0, scale = params['component'], float(params['t0_s']), float(params['scale_s'])
        factor = {'dry': lambda w: -np.sign(w), 'viscous': lambda w: -np.asarray(w),
                  'offset': lambda w: -np.ones_like(np.asarray(w, dtype=float))}[comp]
        return [('drift', lambda w, t, a: factor(w) * (np.asarray(t) - t0) / scale)]
    if kind == 'periodic':
        f, t0 = float(params['frequency_hz']), float(params['t0_s'])
        return [('cos', lambda w, t, a: np.cos(2 * np.pi * f * (np.asarray(t) - t0))),
                ('sin', lambda w, t, a: np.sin(2 * np.pi * f * (np.asarray(t) - t0)))]
    if kind == 'smooth_speed':
        knots = np.asarray(params['knots_rad_s'], dtype=float)
        out = []
        for j, k in enumerate(knots):
            for side, tag in ((1.0, 'p'), (-1.0, 'n')):
                if k * side > 0 or k == 0:
                    out.append((f'hat{j}{tag}', _hat(knots, j, side)))
        return out
    raise ValueError(f'unknown effect kind {kind!r}')


def _hat(knots: np.ndarray, j: int, side: float) -> Column:
    """Return the hat function of knot j on one side of zero speed (0 on the other)."""
    def column(w, t, a):
        values = np.zeros(len(knots))
        values[j] = 1.0
        return np.interp(w, knots, values) * (np.sign(w) == side)
    return column


def evaluate(kind: str, params: dict, data: IdentData) -> np.ndarray:
    """Return the effect's columns on the data as an (n, k) array."""
    aux = data.aux
    if kind == 'stribeck_hysteresis' and data.past is not None:
        aux = {**data.aux, LEFT_ZERO: data.past.left_zero.astype(float)}
    return np.column_stack([col(data.speed, data.time, aux)
                            for _, col in regressor_columns(kind, params)])


def prerequisite(name: str) -> str | None:
    """Return the effect that must be in the model before ``name`` is offered, or None.

    ``gear_ripple:k`` (a transmission's k-th spatial frequency) follows ``gear_ripple:k-1``
    (``gear_ripple`` for k = 2); every other effect is offered from the start.
    """
    base, _, count = name.partition(':')
    if base != 'gear_ripple' or not count.isdigit():
        return None
    return base if int(count) == 2 else f'{base}:{int(count) - 1}'


def offered(name: str, tried: set[str], present: set[str]) -> bool:
    """Return whether ``name`` may be scored: untried, its prerequisite in the model."""
    need = prerequisite(name)
    return name not in tried and (need is None or need in present)


def renumbered(names: list[str]) -> list[str]:
    """Return effect names with the repeats of an effect numbered 1, 2, ... in order.

    A stage removed by the backfit leaves its followers' numbers with a gap
    (``gear_ripple:2`` alone): the final model counts its stages from the first again.
    """
    out, seen = [], 0
    for name in names:
        if name.partition(':')[0] == 'gear_ripple' and prerequisite(name) is not None \
                or name == 'gear_ripple':
            seen += 1
            name = 'gear_ripple' if seen == 1 else f'gear_ripple:{seen}'
        out.append(name)
    return out


def left_out(name: str) -> frozenset[str]:
    """Return ``name`` and the repeats that follow it (left out of a selection together)."""
    if name.partition(':')[0] != 'gear_ripple':
        return frozenset({name})
    first = 1 if ':' not in name else int(name.partition(':')[2])
    return frozenset({name} | {f'gear_ripple:{k}' for k in range(first + 1, em.RIPPLES + 1)})


def named_candidates(data: IdentData, residual: np.ndarray) -> list[Candidate]:
    """Return the named effects that can be tested on these data (with skip reasons)."""
    w = data.speed
    aw = np.abs(w[w != 0])
    out = []
    out.append(stribeck_candidate(aw))
    out.append(hysteresis_candidate(data))
    out.append(presliding_candidate(data))
    share = min(np.mean(w > 0), np.mean(w < 0))
    out.append(Candidate('asymmetric_coulomb', 'asymmetric_coulomb', [{}],
                         skipped=None if share >= 0.02 else
                         'not testable: the wheel spins one way only'))
    out.append(Candidate('drag', 'drag', [{'exponent': n} for n in DRAG_EXPONENTS]))
    for column, values in data.aux.items():
        spread = np.std(values)
        reason = None
        if not np.isfinite(spread) or spread <= 1e-9 * (1.0 + abs(np.mean(values))):
            reason = f'not testable: auxiliary channel {column} is constant'
        for comp in ('dry', 'viscous'):
            out.append(Candidate(f'aux:{column}:{comp}', 'aux',
                                 [{'column': column, 'component': comp,
                                   'center': float(np.mean(values))}], skipped=reason))
    t0, span = float(data.time[0]), float(data.time[-1] - data.time[0])
    out.append(Candidate('drift', 'drift', [{'component': c, 't0_s': t0, 'scale_s': span}
                                            for c in ('dry', 'viscous', 'offset')]))
    seen = np.where(held_out_mask(len(residual)), 0.0, residual)   # test rows unseen
    freqs, tested = spectral_peaks(data.time, seen, PERIODIC_PEAKS)
    out.append(Candidate('periodic', 'periodic',
                         [{'frequency_hz': f, 't0_s': t0} for f in freqs],
                         tests=max(tested, 1),
                         skipped=None if freqs else 'not testable: too few samples'))
    return out + motion_candidates(data, residual)


def stribeck_candidate(abs_speed: np.ndarray) -> Candidate:
    """Return the Stribeck candidate: speeds at quantiles of abs(w), refined in between.

    The Stribeck speed is refined between its grid neighbours as the hysteresis and
    pre-sliding widths are (select._refine; three tests per grid point): on a grid
    point alone the true curve fitted no better than a pre-sliding ramp, and the
    effect chosen depended on where the quantiles fell.
    """
    scales = sorted({float(np.quantile(abs_speed, q)) for q in STRIBECK_QUANTILES}
                    - {0.0}) if len(abs_speed) else []
    grid = [{'velocity_rad_s': s, 'shape': d} for s in scales for d in (2.0, 1.0)]
    if len(scales) < 2:
        return Candidate('stribeck', 'stribeck', grid)
    ratio = float(max(b / a for a, b in zip(scales[:-1], scales[1:])))
    return Candidate('stribeck', 'stribeck', grid, tests=3 * len(grid),
                     extra={'refine': 'velocity_rad_s', 'ratio': ratio})


def hysteresis_candidate(data: IdentData, abs_speed: np.ndarray | None = None
                         ) -> Candidate:
    """Return the hysteresis candidate, or its skip reason when the run cannot show it.

    The effect lives on the samples that left zero speed; a run whose speed never passes
    through zero (never reverses, never comes to rest) has none, and friction's
    dependence on the direction of approach cannot be identified from it. The grid of
    Stribeck speeds spans quantiles of ``abs_speed`` (default abs(w) of ``data``; the
    joint selection of sibling wheels passes their pooled speeds).
    """
    past = data.past
    left = past.left_zero if past is not None else np.zeros(len(data), dtype=bool)
    approach = past.approaching if past is not None else left
    aw = np.abs(data.speed) if abs_speed is None else np.abs(abs_speed)
    if past is None or past.passages == 0 or np.sum(left) < 10 or np.sum(approach) < 10:
        what = 'never reverses or approaches zero' if past is None or past.passages == 0 \
            else 'leaves zero speed on too few samples'
        return Candidate('stribeck_hysteresis', 'stribeck_hysteresis', [], tests=1,
                         skipped=f'not testable: the speed {what}, so friction that '
                                 f'depends on the direction of approach (hysteresis) '
                                 f'cannot be identified from this run')
    lo, hi = (float(np.quantile(aw[aw > 0], q)) for q in HYSTERESIS_RANGE)
    lo = max(lo, 1e-6)
    scales = np.geomspace(lo, max(hi, 1.01 * lo), HYSTERESIS_GRID)
    grid = [{'velocity_rad_s': float(v), 'shape': s} for s in HYSTERESIS_SHAPES
            for v in scales]
    return Candidate('stribeck_hysteresis', 'stribeck_hysteresis', grid,
                     tests=3 * len(grid), extra={'refine': 'velocity_rad_s',
                                                 'ratio': float(scales[1] / scales[0])})


def presliding_candidate(data: IdentData, abs_speed: np.ndarray | None = None
                         ) -> Candidate:
    """Return the pre-sliding band candidate (needs samples near zero speed).

    Band widths span quantiles of ``abs_speed`` (default abs(w) of ``data``), and reach
    at least three times the speed's noise (candidates_motion.speed_noise): within its
    noise the sampled speed's sign says nothing of the motion's direction, so a band
    narrower than that cannot be told from a jump of the dry term at every noisy sign
    change (a joint at rest: a quarter of its samples within the noise).
    """
    aw = np.abs(data.speed) if abs_speed is None else np.abs(abs_speed)
    lo, hi = (float(np.quantile(aw, q)) for q in PRESLIDING_RANGE)
    hi = max(hi, 3.0 * speed_noise(data))
    if hi <= 0 or np.sum(aw < hi) < 10 or data.past is None or data.past.passages == 0:
        return Candidate('presliding', 'presliding', [], tests=1,
                         skipped='not testable: the speed never comes near zero')
    lo = max(lo, hi / 100.0)
    scales = np.geomspace(lo, hi, PRESLIDING_GRID)
    grid = [{'band_rad_s': float(v), 'shape': s} for s in PRESLIDING_SHAPES for v in scales]
    return Candidate('presliding', 'presliding', grid, tests=3 * len(grid),
                     extra={'refine': 'band_rad_s', 'ratio': float(scales[1] / scales[0])})


def fallback_candidate(data: IdentData) -> Candidate:
    """Return the smooth-function-of-speed fallback (knots at speed quantiles, near 0)."""
    w = data.speed
    aw = np.abs(w[w != 0])
    near = [float(np.quantile(aw, q)) for q in NEAR_ZERO] if len(aw) else []
    knots = np.unique(np.concatenate([np.quantile(w, np.linspace(0.0, 1.0, SMOOTH_KNOTS)),
                                      near, [-x for x in near], [0.0]]))
    knots = knots[(knots >= w.min()) & (knots <= w.max())]
    return Candidate(FALLBACK, 'smooth_speed', [{'knots_rad_s': [float(k) for k in knots]}])


def uniform_resample(time: np.ndarray, values: np.ndarray, max_points: int = 1 << 16
                     ) -> tuple[np.ndarray, float]:
    """Return values linearly interpolated on a uniform grid, and the grid step (s)."""
    n = min(len(time), max_points)
    grid = np.linspace(time[0], time[-1], n)
    return np.interp(grid, time, values), float(grid[1] - grid[0]) if n > 1 else 1.0


def spectral_peaks(time: np.ndarray, residual: np.ndarray, count: int, refine: bool = True
                   ) -> tuple[list[float], int]:
    """Return the ``count`` largest periodogram peaks (Hz) and how many were searched.

    The lowest three frequency bins are left out: a trend there is the drift effect's.
    """
    if len(time) < 32:
        return [], 0
    values, step = uniform_resample(time, residual - np.mean(residual))
    power = np.abs(np.fft.rfft(values)) ** 2
    freqs = np.fft.rfftfreq(len(values), step)
    power[:3] = 0.0
    order = np.argsort(power)[::-1]
    picked: list[int] = []
    for i in order:
        if len(picked) == count:
            break
        if all(abs(int(i) - j) > 2 for j in picked):
            picked.append(int(i))
    df = float(freqs[1] - freqs[0])
    r = residual - np.mean(residual)
    t = time - time[0]
    coarse = [_refine(freqs, power, i) for i in picked]
    if not refine:
        return coarse, len(freqs) - 3
    return [_refine_by_fit(t, r, f, df) for f in coarse], 3 * (len(freqs) - 3)


def _refine_by_fit(t: np.ndarray, r: np.ndarray, f0: float, df: float) -> float:
    """Return the frequency within +-1 bin of f0 whose sinusoid best fits the residual.

    A frequency off by a fraction of a bin drifts out of phase over a long record; the
    search over a continuous interval is counted as three tests per bin. The 21 trial
    frequencies are equally spaced, so exp(i 2 pi f t) is stepped from one to the next
    by one complex product (no trigonometric call per trial); the fit of cos and sin
    needs sum r e^(i w t) and sum e^(2 i w t) only.
    """
    n = len(t)
    trials = f0 + df * np.linspace(-1.0, 1.0, 21)
    phase = np.exp(2j * np.pi * trials[0] * t)
    step = np.exp(2j * np.pi * (trials[1] - trials[0]) * t)
    best, best_gain = f0, -np.inf
    for f in trials:
        if f > 0:
            a = complex(np.dot(r, phase))            # sum r cos + i sum r sin
            b = complex(np.dot(phase, phase))        # sum e^(2 i w t)
            cc, ss, cs = 0.5 * (n + b.real), 0.5 * (n - b.real), 0.5 * b.imag
            gram = np.array([[cc, cs], [cs, ss]])
            xy = np.array([a.real, a.imag])
            gain = float(xy @ np.linalg.solve(gram + 1e-12 * np.eye(2), xy))
            if gain > best_gain:
                best, best_gain = float(f), gain
        phase *= step
    return best


def _refine(freqs: np.ndarray, power: np.ndarray, i: int) -> float:
    """Return the peak frequency refined by a parabola through three bins."""
    if i <= 0 or i >= len(power) - 1 or power[i] <= 0:
        return float(freqs[i])
    a, b, c = np.log(np.maximum(power[i - 1:i + 2], 1e-300))
    denom = a - 2 * b + c
    shift = 0.5 * (a - c) / denom if denom < 0 else 0.0
    return float(freqs[i] + np.clip(shift, -0.5, 0.5) * (freqs[1] - freqs[0]))
