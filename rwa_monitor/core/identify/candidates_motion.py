"""Candidates of the effects with a state or a position (effects_motion.py): their grids.

Every grid is derived from the record (sampling step, speed noise, the position's range
and steps, the stops it contains), never from constants of a particular machine, so the
same rules run on any record. Each grid point counts as one test in the selection's
Bonferroni correction; a continuous parameter refined between grid neighbours counts
three per point (scoring._refine), a frequency searched in a spectrum three per
independent frequency (as the time-periodic effect).
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.identify import effects_motion as em
from rwa_monitor.core.identify import motion
from rwa_monitor.core.identify.candidate import Candidate
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.differentiate import local_noise_std
from rwa_monitor.core.identify.fitting import held_out_mask

RIPPLE_PEAKS = 3
RIPPLE_STEPS = 4.0   # the scan's highest spatial frequency: 1 / (4 median position steps)
MAX_RIPPLE_BINS = 1 << 16


def speed_noise(data: IdentData) -> float:
    """Return the speed's white-noise standard deviation (median of block estimates)."""
    h = max(int(data.half_width), 2)
    if len(data) < 4 * h + 2:
        return 0.0
    return float(np.median(local_noise_std(data.time, data.speed, h, 2,
                                           max(200, len(data) // 20))))


def direction_bands(data: IdentData, noise: float) -> list[float]:
    """Return the tanh band widths: multiples of the speed noise (quantiles if none)."""
    aw = np.abs(data.speed[data.speed != 0])
    floor = float(np.quantile(aw, 0.005)) if len(aw) else 0.0
    base = max(noise, floor, 1e-12)
    return [base * f for f in em.BAND_FACTORS]


def reciprocating(data: IdentData) -> str | None:
    """Return why position effects cannot be tested here, or None when they can."""
    q = motion.position(data.time, data.speed)
    span = float(np.ptp(q))
    travel = float(np.sum(np.abs(np.diff(q))))
    if span <= 0 or span >= 2 * np.pi:
        return ('not testable: the position (integral of the speed) spans more than a '
                'turn, or none; friction that depends on the position needs a joint that '
                'moves back and forth within a turn')
    if travel < em.REVISITS * span:
        return ('not testable: the joint does not revisit its positions (travel '
                f'{travel:.3g} rad over a range of {span:.3g} rad)')
    return None


def motion_candidates(data: IdentData, residual: np.ndarray) -> list[Candidate]:
    """Return the candidates of effects_motion.py that these data can test (or why not)."""
    noise = speed_noise(data)
    bands = direction_bands(data, noise)
    passes = data.past.passages if data.past is not None else 0
    out = [lag_candidate(data, bands, passes), stick_candidate(data, noise)]
    out.append(presliding_state_candidate(data, passes))
    why = reciprocating(data)
    q = motion.position(data.time, data.speed)
    centre = {'sin_mean': float(np.mean(np.sin(q))), 'cos_mean': float(np.mean(np.cos(q)))}
    out.append(Candidate('gravity_load', 'gravity_load', [centre], skipped=why))
    out.append(Candidate('load_dry', 'load_dry', [{**centre, 'band_rad_s': b} for b in bands],
                         skipped=why))
    out += ripple_candidates(data, residual, bands[0], why)
    out.append(Candidate('inertia', 'inertia', [{'half_width': max(int(data.half_width), 2)}],
                         skipped='not testable: friction was derived from dw/dt itself'
                         if data.derived else None))
    return out


def lag_candidate(data: IdentData, bands: list[float], passes: int) -> Candidate:
    """Return the frictional-lag candidate: T from 2 sampling steps to 1/20 of the record."""
    if passes < 2:
        return Candidate('frictional_lag', 'frictional_lag', [], tests=1,
                         skipped='not testable: the speed never reverses, so a lag of the '
                                 'friction behind the motion cannot be seen')
    step = float(np.median(np.diff(data.time)))
    span = float(data.time[-1] - data.time[0])
    lo, hi = 2.0 * step, max(span / 20.0, 20.0 * step)
    lags = np.geomspace(lo, hi, em.LAG_GRID)
    grid = [{'lag_s': float(t), 'band_rad_s': b} for b in bands for t in lags]
    return Candidate('frictional_lag', 'frictional_lag', grid, tests=3 * len(grid),
                     extra={'refine': 'lag_s', 'ratio': float(lags[1] / lags[0])})


def stick_candidate(data: IdentData, noise: float) -> Candidate:
    """Return the stick candidate: bands from the averaged speed's noise, stops found."""
    h = max(int(data.half_width), 2)
    sigma = noise / np.sqrt(2 * h + 1)
    if sigma <= 0:
        aw = np.abs(data.speed)
        sigma = float(np.quantile(aw, 0.01)) if len(aw) else 0.0
    if sigma <= 0:
        return Candidate('stick', 'stick', [], tests=1,
                         skipped='not testable: the speed has no noise to tell a stop by')
    bands = np.geomspace(sigma, 10.0 * sigma, em.STICK_GRID)
    usable = [float(b) for b in bands if motion.stick_episodes(
        data.time, data.speed, float(b), h).count >= em.MIN_STOPS]
    if not usable:
        return Candidate('stick', 'stick', [], tests=1,
                         skipped='not testable: the joint never rests (no stop of at '
                                 f'least {3 * (2 * h + 1)} samples within the speed noise)')
    grid = [{'band_rad_s': b, 'half_width': h, 'shape': s} for b in usable
            for s in em.STICK_SHAPES]
    return Candidate('stick', 'stick', grid, tests=len(bands) * len(em.STICK_SHAPES))


def presliding_state_candidate(data: IdentData, passes: int) -> Candidate:
    """Return the pre-sliding state candidate: breakaway displacements from the path."""
    q = motion.position(data.time, data.speed)
    step = np.abs(np.diff(q))
    moving = step[step > 0]
    if passes < 2 or len(moving) < 10:
        return Candidate('presliding_state', 'presliding_state', [], tests=1,
                         skipped='not testable: the speed never reverses')
    lo = 10.0 * float(np.median(moving))
    hi = max(0.25 * float(np.ptp(q)), 2.0 * lo)
    if not np.isfinite(hi) or hi > 1e3 * lo:
        hi = 1e3 * lo
    scales = np.geomspace(lo, hi, em.PRESLIDING_GRID)
    grid = [{'breakaway_rad': float(d), 'shape': s} for s in em.PRESLIDING_SHAPES
            for d in scales]
    return Candidate('presliding_state', 'presliding_state', grid, tests=3 * len(grid),
                     extra={'refine': 'breakaway_rad', 'ratio': float(scales[1] / scales[0])})


def ripple_candidates(data: IdentData, residual: np.ndarray, band: float, why: str | None
                      ) -> list[Candidate]:
    """Return the gear-ripple candidates: spatial frequencies at the residual's peaks.

    A transmission has several stages, each with its own spatial frequency: the effect
    may be added up to em.RIPPLES times (``gear_ripple``, ``gear_ripple:2``, ...), each
    offered once the one before it is in the model (effects.offered).
    """
    names = ['gear_ripple'] + [f'gear_ripple:{k}' for k in range(2, em.RIPPLES + 1)]
    return [ripple_candidate(data, residual, band, why).renamed(n) for n in names]


def ripple_candidate(data: IdentData, residual: np.ndarray, band: float, why: str | None
                     ) -> Candidate:
    """Return one gear-ripple candidate: spatial frequencies at the residual's peaks."""
    if why is not None:
        return Candidate('gear_ripple', 'gear_ripple', [], tests=1, skipped=why)
    freqs, tested = position_peaks(data, residual, band)
    q = motion.position(data.time, data.speed)
    grid = [{'cycles_per_rad': f, 'component': c, 'band_rad_s': band,
             'cos_mean': float(np.mean(np.cos(2 * np.pi * f * q))),
             'sin_mean': float(np.mean(np.sin(2 * np.pi * f * q)))}
            for f in freqs for c in ('torque', 'dry', 'both')]
    return Candidate('gear_ripple', 'gear_ripple', grid, tests=max(3 * tested, 1),
                     skipped=None if freqs else 'not testable: too few positions')


def position_peaks(data: IdentData, residual: np.ndarray, band: float) -> tuple[list[float], int]:
    """Return the RIPPLE_PEAKS largest spatial frequencies (cycles/rad), and how many.

    The residual (held-out test rows left out) and the residual times the direction are
    averaged in bins of position (width a quarter of the highest frequency's period);
    the power of the two binned series' Fourier transforms is summed; frequencies below
    1.5 cycles over the range are left to the gravity and load effects. The peaks are
    refined by a direct fit on the samples within +-1 frequency bin.
    """
    q = motion.position(data.time, data.speed)
    use = ~held_out_mask(len(q))
    span = float(np.ptp(q))
    step = np.abs(np.diff(q))
    moving = step[step > 0]
    if len(moving) < 32:
        return [], 0
    top = 1.0 / (RIPPLE_STEPS * float(np.median(moving)))
    bins = int(min(MAX_RIPPLE_BINS, max(64, 2 ** int(np.ceil(np.log2(4 * top * span))))))
    label = np.clip(((q - q.min()) / span * bins).astype(int), 0, bins - 1)[use]
    direction = np.tanh(data.speed[use] / band)
    r = residual[use] - np.mean(residual[use])
    count = np.bincount(label, minlength=bins)
    power = 0.0
    for series in (r, r * direction):
        mean = np.bincount(label, series, bins) / np.maximum(count, 1)
        power = power + np.abs(np.fft.rfft(mean - np.mean(mean[count > 0]))) ** 2
    freqs = np.fft.rfftfreq(bins, span / bins)
    ok = (freqs >= 1.5 / span) & (freqs <= top)
    tested = int(np.sum(ok))
    if tested == 0:
        return [], 0
    power = np.where(ok, power, 0.0)
    picked: list[int] = []
    for i in np.argsort(power)[::-1]:
        if len(picked) == RIPPLE_PEAKS or power[i] <= 0:
            break
        if all(abs(int(i) - j) > 2 for j in picked):
            picked.append(int(i))
    df = float(freqs[1] - freqs[0])
    return [_refine_ripple(q[use], direction, r, float(freqs[i]), df, 1.5 / span)
            for i in picked], tested


def _refine_ripple(q: np.ndarray, direction: np.ndarray, r: np.ndarray, nu: float,
                   df: float, lowest: float) -> float:
    """Return the frequency within +-1 bin of ``nu`` (>= ``lowest``) that fits ``r`` best."""
    best, best_gain = nu, -np.inf
    for f in nu + df * np.linspace(-1.0, 1.0, 21):
        if f < lowest:
            continue
        c, s = np.cos(2 * np.pi * f * q), np.sin(2 * np.pi * f * q)
        X = np.column_stack([c, s, direction * c, direction * s])
        coef, *_ = np.linalg.lstsq(X, r, rcond=None)
        gain = float(r @ (X @ coef))
        if gain > best_gain:
            best, best_gain = float(f), gain
    return best
