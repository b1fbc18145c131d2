"""What ``LLRDetector.restore`` checks before it takes a saved state (core/llr_state.py).

:func:`checked` returns the working state of an :class:`LLRState` for a detector of a
given configuration, or raises :class:`rwa_monitor.core.records.RecordError` (a
ValueError) naming the first field that does not fit; nothing of the detector is touched
before every check has passed. The record must

- hold the declared types (``records.encode`` checks every field, as a decode would);
- have been made with these parameters (``parameters`` equal to
  ``LLRConfig.fingerprint()``), with kernel arrays of this configuration's size and the
  parameter slots of the layout (core/llr_layout.py: window, k_verif, ring length and
  offsets, AR room, bounds) of a fresh detector of it;
- be consistent in what the compiled kernel and the Python parts rely on: counts
  non-negative and adding up to the rows seen, the reference start, the minimum and the
  checkpoint at valid positions, the AR order within the room the kernel arrays hold and
  equal to the noise model's, the skip bound the one of p_min, the buffered samples of
  the noise fit fewer than the fit needs, in order and after no later sample, the last
  change's arrays of their widths and its ramp sums within the ring of the last samples.

Checked here rather than trusted because a state file may come from elsewhere: an index
beyond its ring would be an out-of-bounds write in compiled code, a skip bound raised by
hand would hide changes.
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core import llr_kinds, llr_layout as layout, llr_stats, records
from rwa_monitor.core.gchi2 import skip_threshold
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_noise import SPEED_FIT_CAP, speed_fit_ready
from rwa_monitor.core.llr_state import (
    COUNTER_NAMES, DeclaredChange, fresh, Live, LLRState, working)
from rwa_monitor.core.records import RecordError

# Slots of the kernel arrays set from the parameters (equal to a fresh detector's).
_INT_SLOTS = ('I_W', 'I_KVERIF', 'I_R', 'I_L', 'I_ESTIMATED', 'I_O_RPREF', 'I_O_RTERM',
              'I_O_RTIME', 'I_O_RSPEED', 'I_O_AR', 'I_O_LAGS')
_FLOAT_SLOTS = ('F_LOGR', 'F_MIN_EXC', 'F_NOISE_VAR', 'F_MAX_W', 'F_MAX_F', 'F_FLOOR_REL',
                'F_FLOOR_ABS')
# Relative tolerance of the float slots and of the skip bound: values computed by the
# math library (log r, y*) may differ in the last bits between machines.
_ULPS = 1e-12
_KINDS = llr_stats.KINDS + (llr_kinds.UNDECIDED,)


def checked(state: LLRState, config: LLRConfig) -> Live:
    """Return the working state of ``state`` for a detector of ``config`` (RecordError if not)."""
    if type(state) is not LLRState:
        raise RecordError(f'LLRState: expected an LLRState, got {type(state).__name__}')
    records.encode(state)
    _parameters(state, config)
    new = fresh(config)
    _kernel_layout(state.floats, state.ints, new)
    live = working(state, config)
    for name in _FLOAT_SLOTS:   # the detector's own values (equal within _ULPS)
        slot = getattr(layout, name)
        live.floats[slot] = new.floats[slot]
    _noise(live, config)
    _fit(state, live, config)
    _general(live, config)
    _positions(live, config)
    _change(live, config)
    event = live.last_event
    if event is not None and (event.detector != 'llr' or event.component != config.component):
        raise RecordError(f'LLRState.last_event: an event of {event.detector} '
                          f'{event.component}, not of this llr detector of {config.component}')
    return live


def _fail(field: str, what: str) -> None:
    raise RecordError(f'LLRState.{field}: {what}')


def _parameters(state: LLRState, config: LLRConfig) -> None:
    ours = config.fingerprint()
    theirs = state.parameters
    for name in sorted(set(ours) | set(theirs)):
        a, b = theirs.get(name), ours.get(name)
        if type(a) is not type(b) or a != b:
            _fail(f'parameters[{name}]', f'{a!r} in the record, {b!r} in this detector '
                  '(a state resumes only with the parameters it was made with)')


def _kernel_layout(floats: np.ndarray, ints: np.ndarray, new: Live) -> None:
    for name, got, want in (('floats', floats, new.floats), ('ints', ints, new.ints)):
        if got.size != want.size:
            _fail(name, f'{got.size} values, this configuration has {want.size}')
    for name in _INT_SLOTS:
        slot = getattr(layout, name)
        if ints[slot] != new.ints[slot]:
            _fail(f'ints[{name}]', f'{ints[slot]} in the record, {new.ints[slot]} for these '
                  'parameters')
    for name in _FLOAT_SLOTS:
        slot = getattr(layout, name)
        got, want = float(floats[slot]), float(new.floats[slot])
        if not (math.isnan(got) and math.isnan(want) or abs(got - want) <= _ULPS * abs(want)):
            _fail(f'floats[{name}]', f'{got!r} in the record, {want!r} for these parameters')


def _positions(live: Live, config: LLRConfig) -> None:
    ints, floats = live.ints, live.floats
    n = {name: int(ints[getattr(layout, name)]) for name in (
        'I_ROWS', 'I_POS', 'I_C', 'I_C_ROW', 'I_KMIN', 'I_CHECKPOINT', 'I_ILL', 'I_K',
        'I_DOF', 'I_FLAGS', 'I_NON_FINITE', 'I_OUT_OF_RANGE', 'I_NON_INCREASING',
        'I_AR_ORDER', 'I_NLAGS', 'I_SPEED_MODEL')}
    for name in ('I_ROWS', 'I_POS', 'I_ILL', 'I_K', 'I_NON_FINITE', 'I_OUT_OF_RANGE',
                 'I_NON_INCREASING', 'I_NLAGS'):
        if n[name] < 0:
            _fail(f'ints[{name}]', f'{n[name]} is negative')
    if set(live.counters) != set(COUNTER_NAMES) or min(live.counters.values()) < 0:
        _fail('counters', f'expected non-negative {", ".join(COUNTER_NAMES)}, got '
              f'{live.counters}')
    waiting = 0 if live.fit is None else len(live.fit)
    seen = (n['I_POS'] + waiting + n['I_NON_FINITE'] + n['I_OUT_OF_RANGE']
            + n['I_NON_INCREASING'] + sum(v for k, v in live.counters.items()
                                          if k != 'ill_conditioned'))
    if seen != n['I_ROWS']:
        _fail('ints[I_ROWS]', f'{n["I_ROWS"]} rows, but accepted and rejected samples add '
              f'up to {seen}')
    if not 0 <= n['I_C'] <= n['I_POS']:
        _fail('ints[I_C]', f'reference start {n["I_C"]} is not a position of the '
              f'{n["I_POS"]} samples')
    if not (n['I_KMIN'] == n['I_C']
            or n['I_C'] + config.window < n['I_KMIN'] <= n['I_POS'] - config.window):
        _fail('ints[I_KMIN]', f'{n["I_KMIN"]} is not a candidate tested since the reference '
              f'start {n["I_C"]}')
    if not (n['I_C_ROW'] == -1 if n['I_POS'] == 0 else 0 <= n['I_C_ROW'] < n['I_ROWS']):
        _fail('ints[I_C_ROW]', f'{n["I_C_ROW"]} is not a row seen (of {n["I_ROWS"]})')
    for name, ok in (('I_K', n['I_K'] <= n['I_POS']), ('I_DOF', n['I_DOF'] >= -1),
                     ('I_FLAGS', n['I_FLAGS'] == 0)):
        if not ok:
            _fail(f'ints[{name}]', f'{n[name]} is out of range')
    ar_order = len(live.noise.ar) if live.noise is not None and config.p == 2 else 0
    speed = int(config.p == 2 and live.noise is not None and live.noise.speed_std is not None)
    for name, ok in (('I_AR_ORDER', n['I_AR_ORDER'] == ar_order),
                     ('I_NLAGS', n['I_NLAGS'] <= ar_order),
                     ('I_SPEED_MODEL', n['I_SPEED_MODEL'] == speed)):
        if not ok:
            _fail(f'ints[{name}]', f"{n[name]} does not fit the record's noise model")
    rows = live.ring.row
    if rows.size and (rows.min() < 0 or rows.max() >= max(n['I_ROWS'], 1)):
        _fail('ints', 'a row index in the ring is not a row seen')
    last_t = float(floats[layout.F_LAST_T])
    if math.isnan(last_t) or last_t == math.inf or (last_t == -math.inf) != (
            n['I_POS'] + waiting == 0):
        _fail('floats[F_LAST_T]', f'{last_t!r} is not the time of the last accepted sample')
    log_p = float(floats[layout.F_LOGPMIN])
    ystar = float(floats[layout.F_YSTAR])
    if not log_p <= 0.0:
        _fail('floats[F_LOGPMIN]', f'log p_min {log_p!r} is not <= 0')
    want = skip_threshold(log_p)
    if not abs(ystar - want) <= _ULPS * want:
        _fail('floats[F_YSTAR]', f'skip bound {ystar!r}, p_min gives {want!r}')


def _noise(live: Live, config: LLRConfig) -> None:
    noise, ints, floats = live.noise, live.ints, live.floats
    if config.fits_noise == (noise is None and live.fit is None) or (
            noise is not None and live.fit is not None):
        _fail('noise', 'expected a noise model or samples waiting for its fit, as the '
              'parameters ask' if config.fits_noise else 'no noise model with these '
              'parameters')
    if noise is None:
        ar, speed_std = (), None
    else:
        ar, speed_std = noise.ar, noise.speed_std
        if len(ar) > config.noise_ar_max_order or (speed_std is not None
                                                   and not config.noise_speed_model):
            _fail('noise', 'a model of a higher order or with a speed model the parameters '
                  'do not allow')
    if config.p == 2:
        room = floats[ints[layout.I_O_AR]:ints[layout.I_O_LAGS]]
        if room.tolist() != list(ar) + [0.0] * (room.size - len(ar)):
            _fail('floats', "the kernel's AR coefficients differ from the noise model's")
        if floats[layout.F_SPEED_A:layout.F_SPEED_FLOOR + 1].tolist() != list(
                speed_std or (0.0, 0.0, 0.0)):
            _fail('floats', "the kernel's speed noise level differs from the noise model's")


def _fit(state: LLRState, live: Live, config: LLRConfig) -> None:
    fit = state.fit
    if fit is None:
        return
    n = fit.rows.size
    if any(a.shape[0] != n for a in (fit.time, fit.friction, fit.speed, fit.regressors)) \
            or fit.regressors.shape[1] != config.p:
        _fail('fit', f'arrays of different lengths, or regressors not of {config.p} columns')
    if live.position:
        _fail('fit', 'samples wait for the noise fit after samples entered the sums')
    fit_n = config.noise_fit_samples
    if config.noise_speed_model:
        ready = speed_fit_ready(n, fit_n, fit.speed_low, fit.speed_high) \
            if fit.next_fit is None else not n < fit.next_fit <= n + fit_n
        if ready or n >= SPEED_FIT_CAP * fit_n:
            _fail('fit', f'{n} samples: the fit would have run')
        low, high = (float(np.min(np.abs(fit.speed))), float(np.max(np.abs(fit.speed)))) \
            if n else (math.inf, 0.0)
        if (fit.speed_low, fit.speed_high) != (low, high):
            _fail('fit.speed_low', 'not the range of the buffered speeds')
    elif n >= fit_n or fit.next_fit is not None or (fit.speed_low, fit.speed_high) != (
            math.inf, 0.0):
        _fail('fit', f'{n} samples of a fit on {fit_n} without a speed model')
    values = np.column_stack([fit.time, fit.friction, fit.speed, fit.regressors])
    if n and (np.any(np.diff(fit.rows) <= 0) or fit.rows[0] < 0
              or fit.rows[-1] >= live.ints[layout.I_ROWS]
              or not np.all(np.diff(fit.time) > 0.0)
              or fit.time[-1] != live.floats[layout.F_LAST_T]
              or not np.all(np.isfinite(values))):
        _fail('fit.rows', 'samples not finite, not in the order of rows and times, or not '
              'before the last accepted one')


def _general(live: Live, config: LLRConfig) -> None:
    general = live.general
    if (general is None) != (config.p == 2):
        _fail('general', f'expected {"none" if config.p == 2 else "the state"} of the '
              f'p > 2 path for a model of {config.p} columns')
    if general is None:
        return
    lags = general.lag_friction.shape[0]
    ar = 0 if live.noise is None else len(live.noise.ar)
    if general.reference_sums.shape != (config.width,) or lags > ar \
            or general.lag_regressors.shape != (lags, config.p):
        _fail('general', 'arrays of other widths than the model, or more lags than its AR '
              'order')


def _change(live: Live, config: LLRConfig) -> None:
    change = live.change
    pos = live.position
    checkpoint = int(live.ints[layout.I_CHECKPOINT])
    open_ramp = change is not None and not change.finished and bool(change.checks)
    if open_ramp:
        stride = config.tail_stride if change.closed else config.window
        if not pos <= checkpoint <= change.ramp_end + stride:
            _fail('ints[I_CHECKPOINT]', f'{checkpoint}: not a position within {stride} '
                  f'samples after the ramp sums (at {change.ramp_end}) and the last sample '
                  f'({pos})')
    elif checkpoint != -1:
        _fail('ints[I_CHECKPOINT]', f'{checkpoint} without a change under revision')
    if change is None:
        return
    width = config.width
    if change.before.shape != (width,) or change.gap.shape != (width,) \
            or change.ramp.shape[0] < 1 or change.ramp.shape[1] != 1 + 3 * width:
        _fail('change', f'arrays not of the prefix width {width} of this model')
    if change.speeds.shape != (change.ramp.shape[0], 2) or (
            config.p == 2 and not np.all(change.speeds[:, 0] <= change.speeds[:, 1])):
        _fail('change.speeds', 'not one speed range (lowest <= highest) per ramp block')
    if not all(np.all(np.isfinite(a)) for a in (change.before, change.gap, change.ramp)) \
            or not math.isfinite(change.time) or not change.log_p <= 0.0:
        _fail('change', 'sums, time or p-value not finite')
    if change.kind not in _KINDS or change.guess not in _KINDS:
        _fail('change.kind', f'{change.kind!r} / {change.guess!r} is not a kind')
    if change.shape not in llr_kinds.SHAPES:
        _fail('change.shape', f'{change.shape!r} is not a shape')
    if not (0 <= change.tau <= change.ramp_end < pos and change.n_before > config.p
            and change.revision >= 0 and all(0 <= r < live.ints[layout.I_ROWS]
                                             for r in change.rows)):
        _fail('change.tau', 'positions, rows or counts out of range')
    for name in ('checks', 'points'):
        values = getattr(change, name)
        if any(b <= a for a, b in zip(values, values[1:])):
            _fail(f'change.{name}', 'positions not increasing')
    _change_time(live, change)


def _change_time(live: Live, change: DeclaredChange) -> None:
    """Check the change time against the samples the ring still holds.

    The categorisation's ramp offsets are ``t - change.time`` (core/llr_growth.py): a
    time edited far from the samples overflows their squares and poisons every later
    re-check. The time is the sample time at ``tau`` (llr_changes ``_declare``): equal to
    it while the ring holds ``tau``, else before the oldest sample it holds; and the last
    ramp block's offset is ``t(ramp_end) - change.time`` while the ring holds
    ``ramp_end``.
    """
    pos, length = live.position, int(live.ints[layout.I_L])
    times = live.ring.time
    oldest = max(0, pos - length)
    if change.tau >= oldest:
        ok = change.time == times[change.tau % length]
    else:
        ok = change.time < times[oldest % length]
    if ok and change.ramp_end >= oldest:
        ok = times[change.ramp_end % length] - change.time == change.ramp[-1, 0]
    if not ok:
        _fail('change.time', f'{change.time!r} is not the time of the change at position '
              f'{change.tau} as the samples held and the ramp sums give it')
