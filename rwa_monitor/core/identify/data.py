"""The samples the identification loop works on: time, speed, friction, noise, aux."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from rwa_monitor.core.identify.differentiate import choose_half_width, HALF_WIDTHS
from rwa_monitor.core.identify.differentiate import local_noise_std
from rwa_monitor.core.identify.differentiate import local_polynomial_derivative
from rwa_monitor.core.identify.history import History, history
from rwa_monitor.core.identify.transients import external_torques
from rwa_monitor.core.params import check_int, check_real
from rwa_monitor.exceptions import NotIdentifiableError, TooFewSamplesError

MIN_SAMPLES = 50
DEFAULT_HALF_WIDTH = 5
NOISE_BLOCK = 200
GAP_FACTOR = 5.0


def _block(n: int) -> int:
    return max(NOISE_BLOCK, n // 20)


@dataclass
class IdentData:
    """Valid samples of one wheel, with the per-sample noise standard deviation (N m).

    ``derived`` is True when friction was estimated from speed (eq. 1b); then the
    residual noise is correlated over ``stride`` samples and the whiteness test uses
    every ``stride``-th residual. ``rows`` are the input rows kept (None: all).
    """

    wheel: str
    time: np.ndarray
    speed: np.ndarray
    friction: np.ndarray
    noise_std: np.ndarray
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    derived: bool = False
    stride: int = 1
    counts: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    signals: dict[str, np.ndarray] = field(default_factory=dict)
    past: History | None = None
    runs: list[int] = field(default_factory=lambda: [0])
    half_width: int = 0
    differentiator: dict = field(default_factory=dict)
    rows: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.past is None:
            self.past = speed_history(self.time, self.speed)

    def __len__(self) -> int:
        return len(self.time)

    @property
    def noise_floor(self) -> float:
        """Return the root-mean-square noise standard deviation (N m)."""
        return float(np.sqrt(np.mean(self.noise_std ** 2)))


def _chunks(time: np.ndarray, ok: np.ndarray) -> list[np.ndarray]:
    """Return index arrays of runs of valid samples without long time gaps."""
    index = np.flatnonzero(ok)
    if len(index) == 0:
        return []
    dt = np.diff(time[index])
    typical = np.median(dt) if len(dt) else 0.0
    breaks = np.flatnonzero((np.diff(index) > 1) | (dt > GAP_FACTOR * typical)) + 1
    return np.split(index, breaks)


def _increasing(time: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Return ``ok`` without the rows whose time is not later than every earlier kept row.

    The rule for stamps out of order or repeated (docs/identify.md, "Bad input"): a row
    is kept only when its time exceeds the largest time of the rows kept before it, so
    the kept times increase strictly; a duplicate keeps its first row, a step back
    drops the rows until time passes the last kept stamp again.
    """
    finite_time = np.where(ok, time, -np.inf)
    before = np.concatenate([[-np.inf], np.maximum.accumulate(finite_time)[:-1]])
    return ok & (time > before)


def _usable(time: np.ndarray, ok: np.ndarray, counts: dict[str, int]) -> np.ndarray:
    """Count the non-finite rows and the rows out of time order; return the usable mask."""
    counts['non_finite_rows'] = int(np.sum(~ok))
    usable = _increasing(time, ok)
    counts['time_not_increasing_rows'] = int(np.sum(ok & ~usable))
    return usable


def prepare(time: np.ndarray, speed: np.ndarray, friction: np.ndarray | None = None, *,
            wheel: str = 'rw1', aux: Mapping[str, np.ndarray] | None = None,
            signals: Mapping[str, np.ndarray] | None = None, inertia: float | None = None,
            torque_constant: float | None = None, half_width: int | str = 'auto'
            ) -> IdentData:
    """Return the samples of one wheel, with friction measured or estimated (eq. 1b).

    ``time``, ``speed``, ``friction`` (None or all NaN: derive it from speed) and every
    array of ``aux`` (this wheel's auxiliary channels: candidate effects; the motor
    current ``<wheel>_current`` enters eq. 1b) and ``signals`` (every other channel of the
    record: residual diagnostics only) have one value per row.
    Rows with a non-finite time, speed or friction are dropped and counted, then rows
    whose time does not increase (:func:`_increasing`). Without friction the friction is
    J dw/dt - K_T I from a local-polynomial derivative on
    each run of valid samples (runs split at NaN rows and at time gaps longer than five
    typical steps; runs shorter than two windows are dropped and counted). The first and
    last h samples of each run are dropped (counted): their windows are all the same
    window shifted inward, an extrapolation whose errors are shared, not independent.
    ``half_width='auto'`` chooses the differentiator's width from the data
    (differentiate.choose_half_width, on the longest run) when friction is derived from
    speed, and uses DEFAULT_HALF_WIDTH otherwise.
    """
    aux = dict(aux or {})
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    if friction is not None:
        friction = np.asarray(friction, dtype=float)
    differentiator: dict = {}
    measured = friction is not None and bool(np.any(np.isfinite(friction)))
    counts = {'rows': len(time)}
    notes: list[str] = []
    if measured:
        ok = _usable(time, np.isfinite(time) & np.isfinite(speed) & np.isfinite(friction),
                     counts)
        if half_width == 'auto':
            half_width = DEFAULT_HALF_WIDTH
        half_width = check_int('half_width', half_width, 1, 1000)
        keep = np.flatnonzero(ok)
        _need(len(keep))
        friction = friction[keep]
        noise = local_noise_std(time[keep], friction, half_width, 2, _block(len(keep)),
                                exclude=_near_sign_change(speed[keep], half_width))
        derived, stride = False, 1
        run_starts = _run_starts(time[keep])
    else:
        current = aux.get(f'{wheel}_current')
        current = None if current is None else np.asarray(current, dtype=float)
        _check_physics(wheel, inertia, torque_constant, current)
        ok = np.isfinite(time) & np.isfinite(speed)
        if current is not None:
            ok &= np.isfinite(current)
        ok = _usable(time, ok, counts)
        if current is None:
            ok = _without_external_torques(time, speed, ok, counts, notes)
        if half_width == 'auto':
            half_width, differentiator = _auto_half_width(time, speed, ok)
        half_width = check_int('half_width', half_width, 1, 1000)
        keep, friction, noise, run_starts = _from_speed(
            time, speed, ok, current, float(inertia), torque_constant, half_width, counts,
            notes)
        derived, stride = True, 2 * half_width + 1
    return IdentData(wheel=wheel, time=time[keep], speed=speed[keep], friction=friction,
                     noise_std=noise, aux=_aux_channels(time, aux, keep, notes, counts),
                     derived=derived, stride=stride, counts=counts, notes=notes,
                     signals=_other_signals(signals or {}, keep),
                     past=speed_history(time[keep], speed[keep], half_width),
                     runs=run_starts, half_width=half_width,
                     differentiator=differentiator, rows=keep)


def _auto_half_width(time: np.ndarray, speed: np.ndarray, ok: np.ndarray
                     ) -> tuple[int, dict]:
    """Return the differentiator half width chosen on the longest valid run, and why."""
    runs = _chunks(time, ok)
    if not runs or len(max(runs, key=len)) < 2 * HALF_WIDTHS[0] + 1:
        return DEFAULT_HALF_WIDTH, {}
    run = max(runs, key=len)
    best, table = choose_half_width(time[run], speed[run])
    return best, {'half_width': best, 'chosen_from': 'data (noise against bias)',
                  'rows_used': len(run), 'candidates': {str(k): v for k, v in table.items()}}


def _without_external_torques(time: np.ndarray, speed: np.ndarray, ok: np.ndarray,
                              counts: dict[str, int], notes: list[str]) -> np.ndarray:
    """Return ``ok`` without the rows of external torque episodes (transients.py).

    Only on a coast (no motor current): with a drive the commanded torque changes dw/dt
    legitimately. The rows are dropped and counted; an episode inside a run splits it
    (each side is differentiated and, in the output error, integrated on its own).
    """
    before = ok
    ok = ok.copy()
    total = int(np.sum(ok))
    for run in _chunks(time, ok):
        for ep in external_torques(time[run], speed[run], samples=total):
            rows = run[ep.first:ep.last + 1]
            ok[rows] = False
            what = (f'speed step {ep.impulse_rad_s:.3g} rad/s, z = {ep.impulse_z:.1f}'
                    if ep.kind == 'impulse' else 'at an end of a run: run trimmed')
            notes.append(f'external torque (touch or brake) from t = {time[rows[0]]:.6g} s to '
                         f'{time[rows[-1]]:.6g} s ({what}; dw/dt up to {ep.peak_z:.1f} sigma '
                         f'off its trend): {len(rows)} rows cut out')
    counts['dropped_external_torque_rows'] = int(np.sum(before & ~ok))
    return ok


def _run_starts(time: np.ndarray) -> list[int]:
    """Return the first row of every run without a long time gap."""
    return [int(c[0]) for c in _chunks(time, np.ones(len(time), dtype=bool))] or [0]


def speed_history(time: np.ndarray, speed: np.ndarray, half_width: int = 2) -> History:
    """Return the history features of the speed (history.py), run by run.

    dw/dt is the local-quadratic slope over 2h+1 samples on each run without long gaps;
    its noise (speed noise times the differentiator's gain) sets the dead band of the
    rising/falling decision.
    """
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    rate = np.zeros(len(time))
    noise = np.zeros(len(time))
    for run in _chunks(time, np.ones(len(time), dtype=bool)):
        h = min(half_width, (len(run) - 1) // 2)
        if h < 1:
            continue
        slope, gain = local_polynomial_derivative(time[run], speed[run], h)
        speed_noise = local_noise_std(time[run], speed[run], h, 2, NOISE_BLOCK) \
            if len(run) > 2 * h + 2 else 0.0
        rate[run] = slope
        noise[run] = gain * speed_noise
    return history(time, speed, rate, noise)


def _other_signals(signals: Mapping[str, np.ndarray], keep: np.ndarray
                   ) -> dict[str, np.ndarray]:
    """Return every other signal of the record on the kept rows, if finite there.

    Other wheels' speeds, frictions and channels: not candidate effects (aux), but the
    residual is tested against them (diagnostics only) so that nothing in the record
    goes unlooked at.
    """
    out = {name: np.asarray(values, dtype=float)[keep] for name, values in signals.items()}
    return {k: v for k, v in out.items() if np.all(np.isfinite(v))}


def _near_sign_change(speed: np.ndarray, half_width: int) -> np.ndarray:
    """Return the samples within ``half_width`` rows of a change of sign of the speed."""
    sign = np.sign(speed)
    change = np.flatnonzero(sign[1:] != sign[:-1])
    near = np.zeros(len(speed) + 1, dtype=int)
    np.add.at(near, np.clip(change - half_width, 0, len(speed)), 1)
    np.add.at(near, np.clip(change + half_width + 2, 0, len(speed)), -1)
    return np.cumsum(near)[:len(speed)] > 0


def _need(n: int) -> None:
    if n < MIN_SAMPLES:
        raise TooFewSamplesError(
            f'too few valid samples: {n}; the identification needs at least {MIN_SAMPLES}')


def _check_physics(wheel: str, inertia: float | None, torque_constant: float | None,
                   current: np.ndarray | None) -> None:
    """Raise NotIdentifiableError unless eq. 1b has what it needs (J; K_T with a current)."""
    current_name = f'{wheel}_current'
    if inertia is None:
        need = 'the wheel inertia J (--inertia, kg m^2)'
        if current is not None:
            need += ' and the motor torque constant K_T (--torque-constant, N m/A)'
        raise NotIdentifiableError(
            f'no {wheel}_friction column: friction must be estimated from speed as '
            f'f = J dw/dt - K_T I (eq. 1b), which needs {need}')
    check_real('inertia', inertia, 0.0, low_open=True)
    if current is not None and torque_constant is None:
        raise NotIdentifiableError(
            f'the file has a {current_name} column (motor current): the friction '
            f'estimate f = J dw/dt - K_T I needs the torque constant (--torque-constant, '
            f'N m/A)')
    if torque_constant is not None:
        check_real('torque_constant', torque_constant, 0.0, low_open=True)
        if current is None:
            raise NotIdentifiableError(
                f'--torque-constant given but the file has no {current_name} column')


def _from_speed(time: np.ndarray, speed: np.ndarray, ok: np.ndarray,
                current: np.ndarray | None, inertia: float, torque_constant: float | None,
                half_width: int, counts: dict[str, int], notes: list[str]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Return kept rows, friction J dw/dt - K_T I, its noise, and the runs' first rows."""
    pieces, dropped, edges = [], 0, 0
    for run in _chunks(time, ok):
        if len(run) < 4 * half_width + 1:
            dropped += len(run)
            continue
        slope, gain = local_polynomial_derivative(time[run], speed[run], half_width)
        speed_noise = local_noise_std(time[run], speed[run], half_width, 2, NOISE_BLOCK)
        friction = inertia * slope
        variance = (inertia * gain * speed_noise) ** 2
        if current is not None:
            friction = friction - torque_constant * current[run]
            current_noise = local_noise_std(time[run], current[run], half_width, 2,
                                            NOISE_BLOCK)
            variance = variance + (torque_constant * current_noise) ** 2
        inner = slice(half_width, len(run) - half_width)
        edges += 2 * half_width
        pieces.append((run[inner], friction[inner], np.sqrt(variance[inner])))
    counts['dropped_short_run_rows'] = dropped
    counts['dropped_run_edge_rows'] = edges
    if not pieces:
        _need(0)
    keep = np.concatenate([p[0] for p in pieces])
    _need(len(keep))
    notes.append(f'friction estimated from speed: f = J dw/dt'
                 f'{" - K_T I" if current is not None else ""} with J = {inertia:g} kg m^2, '
                 f'local quadratic over {2 * half_width + 1} samples')
    starts = np.cumsum([0] + [len(p[0]) for p in pieces[:-1]])
    return (keep, np.concatenate([p[1] for p in pieces]),
            np.concatenate([p[2] for p in pieces]), [int(s) for s in starts])


def _aux_channels(time: np.ndarray, aux: Mapping[str, np.ndarray], keep: np.ndarray,
                  notes: list[str], counts: dict[str, int]) -> dict[str, np.ndarray]:
    """Return the aux channels on the kept rows, gaps filled by interpolation in time.

    Only this wheel's channels belong here: another wheel's temperature or current does
    not act on this wheel's bearing, and through the attitude loop it correlates with
    this wheel's speed history, which would pass for an effect (those go to ``signals``).
    """
    out = {}
    time = time[keep]
    for name, values in aux.items():
        values = np.asarray(values, dtype=float)[keep]
        ok = np.isfinite(values)
        if np.sum(ok) < 0.5 * len(values):
            notes.append(f'aux channel {name} skipped: more than half of it is missing')
            continue
        if not np.all(ok):
            counts[f'aux_filled:{name}'] = int(np.sum(~ok))
            values = np.interp(time, time[ok], values[ok])
        out[name] = values
    return out
