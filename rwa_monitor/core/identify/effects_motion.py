"""Effects with a state or a position: simulated along the record from the speed (issue 35).

A reciprocating joint (a robot arm's, a wheel that stops and reverses) shows friction
that is not a function of the present speed. Each effect's columns come from a state
simulated along the record from the measured speed alone (motion.py); the measured
friction never enters the state, so the least-squares fit of the weights is the
output-error fit of the model at those nonlinear parameters, which are profiled on
their grids and refined (scoring.py) on the training rows. Paper sign: a positive
weight opposes the motion.

- ``frictional_lag`` (frictional memory): after a change of the motion the contact takes
  time to reach its new friction level (the junctions' or the lubricant film's
  rebuilding time; friction measured under oscillating speed lags the speed). The dry
  term's direction, tanh(w / w_b) (w_b: within the speed noise the direction is
  unknown), passes through a first-order lag of time constant T. Column
  -(L_T[tanh(w / w_b)] - sign(w)); weight: the Coulomb level that follows with the lag
  (positive).
- ``stick`` (static friction holds the drive): while the joint rests, friction is
  reactive: it equals whatever the drive applies, up to the breakaway level. A stop
  starts at the sliding level of the last motion and ends when the applied torque
  reaches the breakaway level of the next one, the torque passing smoothly in between
  as the drive winds up (S(u), u the normalised time in the stop: linear, quadratic or
  cosine). Columns inside stops: sign(w) (there the dry term does not follow the sign of
  the sampled speed, which is noise), -(1 - S) d_before (the level held at the stop's
  start, positive) and -S d_after (the breakaway level, positive).
  The stop's end is read from the record: the column is known once the stop is over.
- ``presliding_state`` (pre-sliding with a state): before gross sliding the contact
  deforms elastically: after a reversal friction builds up over a displacement, not a
  speed (Dahl's model, dz/dq = (sign(dq) - z) / d; or one Maxwell-slip element, linear
  until it slips at displacement d). Column -(z(q) - sign(w)), q the integral of the
  speed; weight: the Coulomb level carried by the element (positive), d the breakaway
  displacement.
- ``gravity_load``: a torque periodic in the joint angle with period 2 pi: the weight of
  a load about the axis that the torque measurement's gravity model does not cancel
  (a payload, a centre-of-mass error). Columns sin(q), cos(q) (q relative: any offset is
  a phase); amplitude and phase free. Every position column is centred on its mean over
  the identification record (``sin_mean``, ``cos_mean``: parameters of the effect), so
  that a constant torque offset stays the offset's (asymmetric_coulomb) and a constant
  dry level the baseline's.
- ``load_dry``: dry friction growing with the load the joint carries (the normal force
  on gear teeth and bearings follows the gravity load): columns -tanh(w / w_b) sin(q),
  -tanh(w / w_b) cos(q).
- ``gear_ripple``: friction and torque periodic in position at a transmission's own
  spatial frequency (tooth meshing, a wave generator's lobes, an eccentric shaft):
  cos, sin(2 pi nu q) (a torque) and/or -tanh(w / w_b) times them (a dry level that
  varies along the path); nu from the residual's spectrum in position.
- ``inertia`` (acceleration dependence): a torque J dw/dt from the inertia between the
  torque measurement and the contact (the link side of a joint torque sensor). Column
  -dw/dt (local quadratic slope); weight J (kg m^2, positive). Not testable when friction
  was itself derived from dw/dt.

Position effects need a reciprocating motion (the joint revisits its positions within
one turn: the integral of the speed is then the angle up to an offset, its drift bounded
by the speed's bias times the record); a wheel that spins on does not give them.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.identify import motion
from rwa_monitor.core.identify.differentiate import local_polynomial_derivative

KINDS = ('frictional_lag', 'stick', 'presliding_state', 'gravity_load', 'load_dry',
         'gear_ripple', 'inertia')
# Columns whose weight has a physical sign (positive: opposes the motion), per kind.
POSITIVE_COLUMNS = {'frictional_lag': (0,), 'presliding_state': (0,), 'inertia': (0,),
                    'stick': (1, 2)}
STICK_SHAPES = ('linear', 'quadratic', 'cosine')
PRESLIDING_SHAPES = ('dahl', 'maxwell')
RATE = 'history:rate'        # aux channel of dw/dt (inertia), else computed from a batch
LAG_GRID = 12
BAND_FACTORS = (1.0, 3.0, 10.0)   # tanh band widths: multiples of the speed noise
STICK_GRID = 5
PRESLIDING_GRID = 10
MIN_STOPS = 2
REVISITS = 4.0               # the path covers its range at least this many times
RIPPLES = 3                  # gear_ripple may be added this often (several stages)


def positive_columns(kind: str, weights: np.ndarray) -> bool:
    """Return whether the columns with a physical sign have a positive weight."""
    cols = POSITIVE_COLUMNS.get(kind, ())
    weights = np.asarray(weights, dtype=float)
    return bool(all(weights[i] > 0 for i in cols if i < len(weights)))


def _direction(w, band: float) -> np.ndarray:
    return np.tanh(np.asarray(w, dtype=float) / band)


def _shape(u: np.ndarray, shape: str) -> np.ndarray:
    if shape == 'linear':
        return u
    if shape == 'quadratic':
        return u * u
    return 0.5 - 0.5 * np.cos(np.pi * u)


def _rate(w, t, a, half_width: int) -> np.ndarray:
    if a is not None and RATE in a:
        return np.asarray(a[RATE], dtype=float)
    w = np.atleast_1d(np.asarray(w, dtype=float))
    if t is None or len(w) < 2 * half_width + 1:
        raise KeyError(RATE)
    return local_polynomial_derivative(np.asarray(t, dtype=float), w, half_width)[0]


def _stick(w, t, params: dict) -> motion.Stick:
    if t is None or np.ndim(w) == 0:
        raise KeyError('time (stick episodes need the record)')
    return motion.stick_episodes(np.asarray(t, dtype=float), np.asarray(w, dtype=float),
                                 float(params['band_rad_s']), int(params['half_width']))


def _position(w, t) -> np.ndarray:
    if t is None or np.ndim(w) == 0:
        raise KeyError('time (the position is the integral of the speed)')
    return motion.position(np.asarray(t, dtype=float), np.asarray(w, dtype=float))


def regressor_columns(kind: str, params: dict) -> list[tuple[str, object]]:
    """Return (weight name, column(speed, time, aux)) pairs of one effect of this module."""
    p = dict(params)
    if kind == 'frictional_lag':
        lag, band = float(p['lag_s']), float(p['band_rad_s'])
        return [('frictional_lag', lambda w, t, a: -(motion.first_order_lag(
            np.asarray(t, dtype=float), _direction(w, band), lag) - np.sign(w)))]
    if kind == 'stick':
        def column(part):
            def f(w, t, a):
                st = _stick(w, t, p)
                s = _shape(st.u, p['shape'])
                return {'release': np.sign(w) * st.mask,
                        'held': -(1.0 - s) * st.before * st.mask,
                        'breakaway': -s * st.after * st.mask}[part]
            return f
        return [(part, column(part)) for part in ('release', 'held', 'breakaway')]
    if kind == 'presliding_state':
        d, shape = float(p['breakaway_rad']), p['shape']
        state = motion.dahl if shape == 'dahl' else motion.maxwell_slip
        return [('presliding_state',
                 lambda w, t, a: -(state(_position(w, t), d) - np.sign(w)))]
    if kind in ('gravity_load', 'load_dry'):
        centre = (float(p['sin_mean']), float(p['cos_mean']))
        band = float(p.get('band_rad_s', 0.0))

        def load(w, t, i):
            values = (np.sin, np.cos)[i](_position(w, t)) - centre[i]
            return values if kind == 'gravity_load' else -_direction(w, band) * values
        return [(name, lambda w, t, a, i=i: load(w, t, i))
                for i, name in enumerate(('sin', 'cos'))]
    if kind == 'gear_ripple':
        nu, comp, band = float(p['cycles_per_rad']), p['component'], float(p['band_rad_s'])
        centre = {'cos': float(p['cos_mean']), 'sin': float(p['sin_mean'])}
        out = []
        for name, f in (('cos', np.cos), ('sin', np.sin)):
            def wave(w, t, f=f, name=name):
                return f(2 * np.pi * nu * _position(w, t)) - centre[name]
            if comp in ('torque', 'both'):
                out.append((name, lambda w, t, a, wave=wave: wave(w, t)))
            if comp in ('dry', 'both'):
                out.append((f'dry_{name}', lambda w, t, a, wave=wave:
                            -_direction(w, band) * wave(w, t)))
        return out
    if kind == 'inertia':
        h = int(p['half_width'])
        return [('inertia', lambda w, t, a: -_rate(w, t, a, h))]
    raise ValueError(f'unknown effect kind {kind!r}')
