"""Commissioning calibration: the nominal models of a spacecraft from fault-free data.

Arrays in, plain dictionaries out (the ``calibration.yaml`` contract of DESIGN.md,
version 1; docs/contracts.md). Per wheel:

- ``friction_model``: the identification loop (core/identify/select.py ``identify``) on
  the wheel's speed and friction alone (no auxiliary channel: the nominal model is a
  function of speed, so a detector needs nothing else to evaluate it);
- ``noise``: the standard deviation of the residual against that model away from zero
  speed, and the low-speed band where the residual is larger than that (its half-width
  and its own standard deviation);
- ``speed_range_rad_s``: the speeds seen;
- ``fss``: the nominal reference of the window diagnoser (base dry friction, viscous
  coefficient and noise of the model's coulomb + viscous part).

Friction changes inside the calibration data are looked for with the calibrated LLR
detector itself; each is reported in ``warnings`` with wheel and time (see
:func:`calibrate_wheel`).

The modules by responsibility: this one is the commissioning procedure (noise profile,
the nominal model's fit and self-check); core/nominal.py the nominal model in force
(``nominal_prediction``, ``NominalWheel``); core/calibrated_fss.py the window diagnoser
against the nominal (``fss_reference``, ``fss_inputs``, ``diagnose_fss``);
core/calibration_check.py the file's shape (``check_calibration``). Their public names
are importable from here too.

The gyro block is filled by :func:`rwa_monitor.core.gyro_calibration.calibrate_gyro` (the
gyro diagnosis' own commissioning: time, gyro (n, 3), star-tracker quaternion (n, 4,
scalar last); a plain dict per axis); it is empty for a record without gyro and star
tracker.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from scipy import stats

from rwa_monitor.core.calibrated_fss import diagnose_fss, fss_extra, fss_inputs, fss_reference
from rwa_monitor.core.calibration_check import check_calibration, check_wheels, VERSION
from rwa_monitor.core.nominal import nominal_prediction, NominalWheel, TABLE_STEP_RAD_S

# Importers use these names from here as well as from their modules.
__all__ = ['BAND_EDGES', 'BAND_LEVEL', 'calibrate_gyro', 'calibrate_wheel',
           'check_calibration', 'check_wheels', 'diagnose_fss', 'fss_extra', 'fss_inputs',
           'fss_reference', 'MAX_BAND_RAD_S', 'MIN_EXCESS', 'noise_profile',
           'nominal_prediction', 'NOMINAL_SE_FRACTION', 'NominalWheel', 'REFERENCE_FRACTION',
           'refit_outside_band', 'REFIT_RCOND', 'SPEED_KINDS', 'TABLE_STEP_RAD_S',
           'tested_speeds', 'VERSION']

# |speed| bin edges (rad/s) of the noise profile; the last bin is open.
BAND_EDGES = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0)
# Level of the test "this bin's residual is larger than the reference noise".
BAND_LEVEL = 1.0e-3
# Widest low-speed band the self-check may choose (rad/s).
MAX_BAND_RAD_S = 8.0
# Least factor on the reference noise for a bin to count as larger.
MIN_EXCESS = 1.1
# Effects of the speed alone: the ones a nominal model keeps (see _keep_speed_effects).
SPEED_KINDS = ('stribeck', 'asymmetric_coulomb', 'drag', 'smooth_speed')
# Relative singular-value cut-off of the refit outside the low-speed band.
REFIT_RCOND = 1.0e-9
# Speeds above this fraction of the largest |speed| seen form the reference region.
REFERENCE_FRACTION = 0.3
# The nominal is tested where the commissioning determined it (tested_speeds): the
# standard error of its prediction at most this multiple of the standard error of the
# mean of one LLR test window, noise std / sqrt(window): the nominal rests on at least
# a window's worth of samples (docs/calibration.md, "Where the nominal is tested").
NOMINAL_SE_FRACTION = 1.0
# Speed step (rad/s) at which that standard error is evaluated.
COVERAGE_STEP_RAD_S = 0.05
# A speed whose regressor row leaves the fit's row space by more than this (relative) is
# an extrapolation of the fit: not determined by the data at all.
ESTIMABLE_TOLERANCE = 1.0e-6


def noise_profile(speed: np.ndarray, residual: np.ndarray,
                  edges: Sequence[float] = BAND_EDGES, level: float = BAND_LEVEL
                  ) -> dict[str, Any]:
    """Return the noise model: reference std, low-speed band and the per-bin profile.

    Reference: the residual's root mean square over |w| above REFERENCE_FRACTION of the
    largest |w| (at least 10 rad/s where the data reach it). A bin of |w| is *larger*
    when its mean square exceeds the reference's by more than the chi-square quantile
    at ``level`` (n - 1 degrees of freedom) allows; the band is ``|w| < b`` with b the
    upper edge of the first run of larger bins from zero speed upwards (0: no band). A
    bin is larger only if also by MIN_EXCESS: with tens of thousands of samples the test
    alone flags excesses of a few per cent far from zero, which are not the band.
    """
    speed = np.abs(np.asarray(speed, dtype=float))
    residual = np.asarray(residual, dtype=float)
    top = float(np.max(speed)) if speed.size else 0.0
    ref_from = min(max(10.0, REFERENCE_FRACTION * top), 0.8 * top)
    ref = residual[speed >= ref_from]
    if ref.size < 50:
        ref = residual
    std = float(np.sqrt(np.mean(ref ** 2)))
    profile = []
    band = 0.0
    closed = False
    bounds = list(edges) + [np.inf]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if lo >= ref_from:
            break
        part = residual[(speed >= lo) & (speed < min(hi, ref_from))]
        if part.size < 2:
            continue
        rms = float(np.sqrt(np.mean(part ** 2)))
        limit = std * np.sqrt(stats.chi2.isf(level, part.size) / part.size)
        larger = bool(rms > limit and rms > MIN_EXCESS * std)
        profile.append({'speed_abs_from_rad_s': float(lo),
                        'speed_abs_to_rad_s': float(min(hi, ref_from)),
                        'samples': int(part.size), 'rms_nm': rms, 'larger': larger})
        if larger and not closed:
            band = float(min(hi, ref_from))
        closed = closed or (band > 0.0 and not larger)
    inside = residual[speed < band]
    return {'std_nm': std,
            'reference_speed_abs_from_rad_s': float(ref_from),
            'low_speed_band': {'speed_abs_below_rad_s': band,
                               'std_nm': float(np.sqrt(np.mean(inside ** 2)))
                               if inside.size else std,
                               'samples': int(inside.size)},
            'profile': profile}


def calibrate_wheel(wheel: str, time: np.ndarray, speed: np.ndarray, friction: np.ndarray,
                    false_alarm_rate: float = 1.0e-5) -> tuple[dict[str, Any], list[str]]:
    """Return (the wheel's calibration block, warnings) from fault-free telemetry.

    Non-finite rows are dropped. The identification runs without its jump search (the
    data are meant to be fault-free; on bus telemetry the jump search cut fault-free
    records at zero-speed passages). Whether they are fault-free is then checked: the
    calibrated LLR detector (docs/llr.md, "Calibrated") runs on the calibration data
    against the model just fitted, at ``false_alarm_rate``. The low-speed band starts
    where the noise profile puts it (``noise_band_rad_s``) and is widened, edge by edge
    up to MAX_BAND_RAD_S, until that self-check is silent (if no width silences it, the
    noise profile's band stands: what is declared is not structure near zero speed); at
    each width the weights are refitted on the samples outside the band
    (:func:`refit_outside_band`): the residual of a static
    nominal model stays structured a little beyond where its excess noise is visible (on
    the bus: the Stribeck hysteresis, a few 1e-6 N m at 3-6 rad/s), and the band must
    hold what the detector would take for changes. Each change still declared at the
    widest band is a warning naming the wheel and the time (``changes_found_s``): a
    change in the data, or friction that is not a function of speed. Raise
    NotIdentifiableError when the data cannot separate dry from viscous.
    """
    from rwa_monitor.core.identify.data import IdentData
    from rwa_monitor.core.identify.differentiate import local_noise_std
    from rwa_monitor.core.identify.model import snippet
    from rwa_monitor.core.identify.select import identify
    from rwa_monitor.core.llr import detect_batch
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    ok = np.isfinite(time) & np.isfinite(speed) & np.isfinite(friction)
    t, w, f = time[ok], speed[ok], friction[ok]
    sign_change = np.zeros(len(w), dtype=bool)
    for k in np.flatnonzero(np.sign(w[1:]) != np.sign(w[:-1])):
        sign_change[max(0, k - 5):k + 7] = True
    noise = local_noise_std(t, f, 5, 2, max(200, len(t) // 20), exclude=sign_change)
    data = IdentData(wheel=wheel, time=t, speed=w, friction=f, noise_std=noise,
                     counts={'rows': int(len(time)), 'non_finite_rows': int(np.sum(~ok))})
    model = snippet(identify(data, jumps=False))['friction_model']
    dropped = _keep_speed_effects(model, data)
    fitted_everywhere = f - nominal_prediction(model, w)
    noise_model = noise_profile(w, fitted_everywhere)
    model['noise_std_nm'] = noise_model['std_nm']
    block = {
        'friction_model': model,
        'noise': noise_model,
        'speed_range_rad_s': [float(np.min(w)), float(np.max(w))],
        'fss': {},   # filled once the low-speed band is final
        'samples': int(len(t)),
        'dropped_effects': dropped,
    }
    band = noise_model['low_speed_band']
    widths = [band['speed_abs_below_rad_s']] + [
        e for e in BAND_EDGES if band['speed_abs_below_rad_s'] < e <= MAX_BAND_RAD_S]

    def self_check(width: float) -> list:
        band['speed_abs_below_rad_s'] = float(width)
        refit_outside_band(model, w, f, width)
        residual, _ = NominalWheel(block).residual(t, w, f)
        return [e for e in detect_batch(t, w, residual, component=wheel,
                                        false_alarm_rate=false_alarm_rate)
                if e.revision == 0]

    for width in widths:
        events = self_check(width)
        if not events:
            break
    if events and len(widths) > 1:
        # No band removes them: not the low-speed structure the widening is for (a change
        # in the data, or a chance declaration), so the noise profile's band stands.
        events = self_check(widths[0])
    inside = np.abs(w) < band['speed_abs_below_rad_s']
    band['std_nm'] = float(np.sqrt(np.mean(fitted_everywhere[inside] ** 2))
                           if inside.any() else noise_model['std_nm'])
    band['samples'] = int(np.sum(inside))
    band['noise_band_rad_s'] = float(widths[0])
    # After the self-check, which looks for changes in the data on every sample outside
    # the band (in sample, the nominal's error where data are few is fitted away).
    block['tested_speeds_rad_s'] = tested_speeds(model, w, band['speed_abs_below_rad_s'],
                                                 noise_model['std_nm'])
    block['tested_samples'] = int(sum(np.count_nonzero((w >= a) & (w <= b))
                                      for a, b in block['tested_speeds_rad_s']))
    block['fss'] = fss_reference(w, f, model, noise_model)
    block['changes_found_s'] = [float(e.time) for e in events]
    warnings = [f'{wheel}: a friction change ({e.kind}) at t = {e.time:.1f} s in the '
                f'calibration data; a nominal model needs fault-free data' for e in events]
    return block, warnings


def refit_outside_band(model: dict[str, Any], speed: np.ndarray, friction: np.ndarray,
                       band_rad_s: float) -> None:
    """Refit the model's weights, in place, on the samples the detectors test.

    The detectors never test |w| < ``band_rad_s`` (the low-speed band), so the nominal
    model is fitted where it is used: least squares on |w| >= band only. Fitted on every
    sample, the few smooth-speed knots near zero (and Stribeck-type columns) bend to the
    hysteresis inside the band and leave a bias of ~5e-6 N m just outside it (measured on
    the bus: 4-6 rad/s), which the LLR detector, testing changes of that size, declares
    once a wheel dwells there, e.g. when the controller moves the other wheels' speeds
    after a fault. Columns are scaled to unit RMS over the fitting samples; a column with
    no support there (a knot wholly inside the band) gets weight 0, and directions the
    fitting samples cannot tell apart are cut by the relative singular-value cut-off.
    """
    from rwa_monitor.core.identify.model import regressors_from_config
    regs = regressors_from_config(model)
    use = np.abs(speed) >= band_rad_s
    if np.count_nonzero(use) < 2 * len(regs.names):
        return
    x = regs.matrix(speed[use])
    scale = np.sqrt(np.mean(x ** 2, axis=0))
    keep = scale > 0
    coef = np.zeros(x.shape[1])
    coef[keep] = np.linalg.lstsq(x[:, keep] / scale[keep], friction[use],
                                 rcond=REFIT_RCOND)[0] / scale[keep]
    model['weights'] = {n: float(c) for n, c in zip(regs.names, coef)}


def tested_speeds(model: dict[str, Any], speed: np.ndarray, band_rad_s: float,
                  noise_std: float, window: int | None = None) -> list[list[float]]:
    """Return the signed speed intervals ``[[lo, hi], ...]`` where the nominal is tested.

    The nominal (the model refitted on ``|w| >= band_rad_s``, :func:`refit_outside_band`)
    is tested at a speed when the commissioning determined it there:

    - the speed lies on a side of zero the data saw, between the smallest and the
      largest ``|w|`` seen on that side outside the band (no extrapolation in speed);
    - its regressor row lies in the row space of the fit (else the prediction is not
      determined by the data at all: a piecewise-linear knot beyond the data);
    - the standard error of its prediction, ``noise_std sqrt(x^T (X^T X)^+ x)`` with the
      same column scaling and singular-value cut as the fit, is at most
      NOMINAL_SE_FRACTION ``noise_std / sqrt(window)``: the nominal is known at least as
      precisely as one test window's mean (``window``: the LLR's default).

    Evaluated every COVERAGE_STEP_RAD_S; a run of such speeds is one interval. Where
    commissioning passed only quickly (a zero crossing in a fast slew leaves a few
    samples per rad/s), the smooth-speed knots are pinned by a handful of samples and
    the nominal is off by a sizeable fraction of the noise: such speeds are not tested
    (docs/calibration.md, "Where the nominal is tested").
    """
    from rwa_monitor.core.identify.model import regressors_from_config
    from rwa_monitor.core.schema import LLR
    window = int(LLR['window'].default if window is None else window)
    limit = NOMINAL_SE_FRACTION * float(noise_std) / np.sqrt(window)
    speed = np.asarray(speed, dtype=float)
    speed = speed[np.isfinite(speed) & (np.abs(speed) >= band_rad_s) & (speed != 0.0)]
    regs = regressors_from_config(model)
    if speed.size < 2 * len(regs.names):
        return []
    x = regs.matrix(speed)
    scale = np.sqrt(np.mean(x ** 2, axis=0))
    keep = scale > 0
    _, sv, vt = np.linalg.svd(x[:, keep] / scale[keep], full_matrices=False)
    cut = sv > REFIT_RCOND * sv[0]
    basis, sv = vt[cut].T, sv[cut]
    out: list[list[float]] = []
    for side in (-1.0, 1.0):
        mags = np.abs(speed[np.sign(speed) == side])
        if mags.size == 0:
            continue
        lo, hi = float(np.min(mags)), float(np.max(mags))
        grid = np.unique(np.append(np.arange(lo, hi, COVERAGE_STEP_RAD_S), hi))
        rows = regs.matrix(side * grid)[:, keep] / scale[keep]
        coords = rows @ basis
        se = noise_std * np.sqrt(np.sum((coords / sv) ** 2, axis=1))
        off = np.linalg.norm(rows - coords @ basis.T, axis=1)
        ok = (se <= limit) & (off <= ESTIMABLE_TOLERANCE * np.linalg.norm(rows, axis=1))
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2] - 1):
            if b > a:
                ends = sorted((side * float(grid[a]), side * float(grid[b])))
                out.append(ends)
    return sorted(out)


def _keep_speed_effects(model: dict[str, Any], data: Any) -> list[str]:
    """Keep the effects that depend on speed only; refit the weights; return the dropped.

    A nominal model must hold on another day: effects of time (``drift``, ``periodic``)
    or of an auxiliary channel describe this record, not the wheel, and would be
    extrapolated. What they explained is mostly friction as a function of speed seen
    through the speed's own time history (on the bus the guidance is periodic), so the
    generic ``smooth_speed`` effect of the identification's vocabulary (its fallback
    candidate, knots at the speed quantiles and near zero) is added when absent, and the
    columns are refitted by least squares on the same data.
    """
    from rwa_monitor.core.identify import effects as fx
    from rwa_monitor.core.identify.model import regressors_from_config
    effects = model.get('effects') or []
    kept = [e for e in effects if e.get('kind') in SPEED_KINDS]
    dropped = [str(e.get('name', e.get('kind'))) for e in effects if e not in kept]
    if dropped and not any(e['kind'] == 'smooth_speed' for e in kept):
        fallback = fx.fallback_candidate(data)
        kept.append({'name': fallback.name, 'kind': fallback.kind,
                     'params': dict(fallback.grid[0])})
    model['effects'] = kept
    regs = regressors_from_config(model)
    coef = np.linalg.lstsq(regs.matrix(data.speed), data.friction, rcond=None)[0]
    model['weights'] = {n: float(c) for n, c in zip(regs.names, coef)}
    return dropped


def calibrate_gyro(time: np.ndarray, gyro: np.ndarray | None, quaternion: np.ndarray | None,
                   reference_rate: np.ndarray | None = None) -> dict[str, Any]:
    """Return the gyro block (per axis) from the gyro diagnosis' own calibration function.

    Empty when the record has no gyro and star tracker. ``reference_rate`` is not needed:
    the gyro-minus-star-tracker residual does not involve the guidance (docs/vsadc.md).
    """
    if gyro is None or quaternion is None:
        return {}
    from rwa_monitor.core.gyro_calibration import calibrate_gyro as fill
    return dict(fill(np.asarray(time, dtype=float), np.asarray(gyro, dtype=float),
                     np.asarray(quaternion, dtype=float)))
