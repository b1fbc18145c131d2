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

The gyro block is filled by :func:`rwa_monitor.core.gyro_calibration.calibrate_gyro` (the
gyro diagnosis' own commissioning: time, gyro (n, 3), star-tracker quaternion (n, 4,
scalar last); a plain dict per axis); it is empty for a record without gyro and star
tracker.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from rwa_monitor.core import llr_kernel
from rwa_monitor.core.calibration_values import check_values, MALFORMED
from rwa_monitor.exceptions import ConfigError

VERSION = 1
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
# Speed step (rad/s) of the nominal model's table (NominalWheel); knots are added to it.
TABLE_STEP_RAD_S = 0.01
# Reasons of a sample not tested, by the code of llr_kernel.nominal_residual.
_REASONS = (None, 'low_speed_band', 'outside_calibrated_range')
_nominal_residual = llr_kernel.nominal_residual
# Relative singular-value cut-off of the refit outside the low-speed band.
REFIT_RCOND = 1.0e-9
# Speeds above this fraction of the largest |speed| seen form the reference region.
REFERENCE_FRACTION = 0.3


def nominal_prediction(friction_model: Mapping[str, Any], speed: np.ndarray,
                       time: np.ndarray | None = None,
                       aux: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """Return the nominal friction (N m, project sign) of a ``friction_model`` block.

    The regressor columns are identify's (model.regressors_from_config, eq. (1) sign:
    ``h = -[sign(w), w, ...]``) times the block's weights. Raise ConfigError naming a
    missing weight.
    """
    from rwa_monitor.core.identify.model import regressors_from_config
    block = friction_model.get('friction_model', friction_model)
    regs = regressors_from_config(block)
    weights = block.get('weights') or {}
    missing = [n for n in regs.names if n not in weights]
    if missing:
        raise ConfigError(f'friction_model.weights lacks {", ".join(missing)}')
    x = np.array([float(weights[n]) for n in regs.names])
    return regs.matrix(np.asarray(speed, dtype=float), time, aux) @ x


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
    up to MAX_BAND_RAD_S, until that self-check is silent; at each width the weights are
    refitted on the samples outside the band (:func:`refit_outside_band`): the residual of a static
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
    for width in widths:
        band['speed_abs_below_rad_s'] = float(width)
        refit_outside_band(model, w, f, width)
        residual, _ = NominalWheel(block).residual(t, w, f)
        events = [e for e in detect_batch(t, w, residual, component=wheel,
                                          false_alarm_rate=false_alarm_rate)
                  if e.revision == 0]
        if not events:
            break
    inside = np.abs(w) < band['speed_abs_below_rad_s']
    band['std_nm'] = float(np.sqrt(np.mean(fitted_everywhere[inside] ** 2))
                           if inside.any() else noise_model['std_nm'])
    band['samples'] = int(np.sum(inside))
    band['noise_band_rad_s'] = float(widths[0])
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


def fss_reference(speed: np.ndarray, friction: np.ndarray, friction_model: Mapping[str, Any],
                  noise: Mapping[str, Any], window_samples: int | None = None
                  ) -> dict[str, Any]:
    """Return the window diagnoser's nominal reference of one wheel.

    The diagnoser knows model (1) and the FSSs (the FSS paper's eq. (4)); what the wheel's
    nominal holds beyond model (1) is removed from its friction first. That part is not
    the nominal model's own extra columns as identification fitted them: identification
    knows no FSS, and on a wheel with FSS jumps it takes them for effects of speed (on
    the paper's Examples 1-2: drag and smooth_speed, a reference base dry 1.6 x the true
    one). So the extra columns are refitted together with the FSS jumps, in the
    diagnoser's own stage 2 (eq. 14: one dry coefficient per interval between the
    changepoints of stages 1-3, one viscous coefficient) plus the columns
    (core/fss/segments.py ``fit_extra_columns``), twice: the changepoints are found
    again once the first fit's extra part is removed. ``extra_weights``: that part as
    weights of the nominal model's columns (``nominal_prediction`` with them is what
    :func:`fss_inputs` removes). ``base_dry_nm``, ``viscous_nms``, ``noise_std_nm``:
    what the diagnoser's extraction (core/fss/pipeline.py, stages 1-3) reports on the
    calibration data given as :func:`fss_inputs` gives a window, so that a nominal window
    is judged against the same estimator's nominal values. ``model1_*``: the plain
    least-squares fit of model (1) outside the low-speed band (for reading only).

    A record of two or more diagnosed windows (``window_samples``, default the node's
    ``window_length``) gets the median of the base dry of each window-long piece
    (``base_dry_windows`` pieces, their std ``base_dry_window_std_nm``) and the mean of
    their viscous coefficients (standard error from theirs): the reference is that of a
    window, as the diagnosed ones are. Algorithm 1's base is a one-window estimate, and
    on a longer record its running sums of jumps drift down with every jump given to the
    wrong FSS (docs/fss.md, "Calibrated": a three-window record read 0.54 x the true
    base dry). When the refitted
    columns leave no positive base dry (they took the dry friction itself), they are
    dropped and ``extra_refit_dropped`` is set: the reference is model (1) alone.
    """
    from rwa_monitor.core.fss.pipeline import extract, FssConfig, normalise
    from rwa_monitor.core.fss.segments import fit_extra_columns
    from rwa_monitor.core.identify.model import regressors_from_config
    from rwa_monitor.core.schema import FSS
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    band = float(noise['low_speed_band']['speed_abs_below_rad_s'])
    with np.errstate(invalid='ignore'):
        out = np.isfinite(speed) & np.isfinite(friction) & (np.abs(speed) >= band)
    h = -np.column_stack([np.sign(speed[out]), speed[out]])
    dry, viscous = np.linalg.lstsq(h, friction[out], rcond=None)[0]
    ref = {'model1_dry_nm': float(dry), 'model1_viscous_nms': float(viscous),
           'speed_abs_below_rad_s': band}
    block = friction_model.get('friction_model', friction_model)
    regs = regressors_from_config(block)
    names = list(regs.names)
    extra = [i for i, n in enumerate(names) if n not in ('dry', 'viscous')]
    config = FssConfig()
    weights = dict.fromkeys(names, 0.0)
    safe = np.where(out, speed, 0.0)
    columns = regs.matrix(safe)[:, extra] if extra else np.zeros((speed.size, 0))
    given = np.where(out, friction, np.nan)
    for _ in range(2 if extra else 0):
        ext = extract(*normalise(speed, given, config), config)
        c, d = fit_extra_columns(friction, np.where(out, speed, np.nan), ext.accepted,
                                 columns, dk_error=config.dk_error)
        # columns @ c + d[0] sign(w) + d[1] w; model (1)'s columns are -sign(w), -w.
        weights = dict.fromkeys(names, 0.0)
        weights.update({names[i]: float(v) for i, v in zip(extra, c)})
        weights['dry'], weights['viscous'] = float(-d[0]), float(-d[1])
        given = np.where(out, friction - nominal_prediction(
            {'effects': block.get('effects') or [], 'weights': weights}, safe), np.nan)
    ext = extract(*normalise(speed, given, config), config)
    if extra and not ext.base_dry > 0.0:
        # The refitted columns took the dry friction itself (nearly collinear with the
        # interval levels when few intervals hold both signs of the speed): a reference
        # with no positive base dry is never right, so the nominal is model (1) alone.
        weights = dict.fromkeys(names, 0.0)
        given = np.where(out, friction, np.nan)
        ext = extract(*normalise(speed, given, config), config)
        ref['extra_refit_dropped'] = True
    tq = config.torque_scale_nm
    base, viscous, viscous_se = ext.base_dry, ext.viscous, ext.viscous_se
    length = int(window_samples or FSS['window_length'].default)
    pieces = speed.size // length
    if pieces >= 2:
        parts = [extract(*normalise(speed[k * length:(k + 1) * length],
                                    given[k * length:(k + 1) * length], config), config)
                 for k in range(pieces)]
        bases = [p.base_dry for p in parts]
        base = float(np.median(bases))
        viscous = float(np.mean([p.viscous for p in parts]))
        viscous_se = float(np.sqrt(np.sum([p.viscous_se ** 2 for p in parts]))) / pieces
        ref.update(base_dry_windows=pieces,
                   base_dry_window_std_nm=float(np.std(bases, ddof=1) * tq))
    ref.update(base_dry_nm=float(base * tq),
               viscous_nms=float(viscous * tq / config.speed_scale_rad_s),
               viscous_se_nms=float(viscous_se * tq / config.speed_scale_rad_s)
               if np.isfinite(viscous_se) else float('nan'),
               noise_std_nm=float(ext.sigma * tq), extra_weights=weights,
               samples=int(np.count_nonzero(out)))
    return ref


def fss_extra(block: Mapping[str, Any], speed: np.ndarray) -> np.ndarray:
    """Return what the wheel's nominal holds beyond model (1), as the FSS reference fitted.

    ``fss.extra_weights`` on the nominal model's columns (:func:`fss_reference`); a
    calibration written before they existed gives the nominal model minus the
    reference's model-(1) fit.
    """
    ref = block['fss']
    model = block['friction_model']
    if 'extra_weights' in ref:
        return nominal_prediction({'effects': model.get('effects') or [],
                                   'weights': ref['extra_weights']}, speed)
    model1 = -ref['model1_dry_nm'] * np.sign(speed) - ref['model1_viscous_nms'] * speed
    return nominal_prediction(model, speed) - model1


def fss_inputs(block: Mapping[str, Any], speed: np.ndarray, friction: np.ndarray
               ) -> tuple[np.ndarray, dict[str, float]]:
    """Return (friction for the diagnoser, its scales) relative to the wheel's nominal.

    The friction loses what the nominal holds beyond model (1) (:func:`fss_extra`),
    samples inside the low-speed band or outside the calibrated speed range become NaN
    (the stages skip them), and the normalising scales are the reference's base dry
    friction and base dry / viscous, so that the nominal wheel is (1, 1) in the
    diagnoser's units, where its classifier was trained (docs/fss.md, "Calibrated").
    """
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    ref = block['fss']
    safe = np.where(np.isfinite(speed), speed, 0.0)
    out = friction - fss_extra(block, safe)
    lo, hi = block['speed_range_rad_s']
    with np.errstate(invalid='ignore'):
        skip = (np.abs(speed) < ref['speed_abs_below_rad_s']) | (speed < lo) | (speed > hi)
    out[skip | ~np.isfinite(speed)] = np.nan
    scales = {}
    if ref['base_dry_nm'] > 0:
        scales['torque_scale_nm'] = float(ref['base_dry_nm'])
        if ref['viscous_nms'] > 0:
            scales['speed_scale_rad_s'] = float(ref['base_dry_nm'] / ref['viscous_nms'])
    return out, scales


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
    if not any(e['kind'] == 'smooth_speed' for e in kept):
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


def check_calibration(cal: Any, source: str = 'calibration') -> dict[str, Any]:
    """Return the inner ``calibration`` mapping after checking its shape.

    Raise ConfigError naming the file (``source``) and the key at fault.
    """
    if not isinstance(cal, Mapping) or not isinstance(cal.get('calibration'), Mapping):
        raise ConfigError(f'{source}: key calibration: expected a mapping')
    inner = cal['calibration']
    if inner.get('version') != VERSION:
        raise ConfigError(f'{source}: key calibration.version: expected {VERSION}, got '
                          f'{inner.get("version")!r}')
    wheels = inner.get('wheels')
    if not isinstance(wheels, Mapping):
        raise ConfigError(f'{source}: key calibration.wheels: expected a mapping')
    check_values(inner, source)
    for name, block in wheels.items():
        key = f'calibration.wheels.{name}'
        if not isinstance(block, Mapping):
            raise ConfigError(f'{source}: key {key}: expected a mapping')
        for part in ('friction_model', 'noise', 'speed_range_rad_s', 'fss'):
            if part not in block:
                raise ConfigError(f'{source}: key {key}.{part}: missing')
        rng = block['speed_range_rad_s']
        if (not isinstance(rng, Sequence) or len(rng) != 2
                or not all(isinstance(v, (int, float)) for v in rng) or rng[0] > rng[1]):
            raise ConfigError(f'{source}: key {key}.speed_range_rad_s: expected [lo, hi]')
        band = (block['noise'] or {}).get('low_speed_band', {})
        if not isinstance(band.get('speed_abs_below_rad_s', 0.0), (int, float)):
            raise ConfigError(f'{source}: key {key}.noise.low_speed_band.'
                              f'speed_abs_below_rad_s: expected a number')
        try:
            nominal_prediction(block['friction_model'], np.array([1.0, -1.0]))
        except MALFORMED as err:
            raise ConfigError(f'{source}: key {key}.friction_model: {err}') from None
    return dict(inner)


def check_wheels(cal: Mapping[str, Any], wheels: Sequence[str], source: str) -> None:
    """Raise ConfigError naming the record's wheels the calibration does not cover."""
    missing = [w for w in wheels if w not in cal['wheels']]
    if missing:
        raise ConfigError(f'{source}: no calibration for wheel(s) {", ".join(missing)}; it '
                          f'calibrates {", ".join(cal["wheels"]) or "none"}')


class NominalWheel:
    """One wheel's calibration in force: nominal prediction, low-speed band, speed range.

    The calibrated LLR path (docs/llr.md, section "Calibrated") feeds the unchanged
    model-(1) detector with ``friction - nominal(speed)``; samples inside the low-speed
    band or outside the calibrated speed range are given as NaN (the detector drops and
    counts them as non-finite, and the row index of every event stays the file's row) and
    counted here by reason.

    The nominal model is evaluated from a table built once per calibration: on each side
    of zero, the tested speeds (band edge to the end of the calibrated range) at every
    TABLE_STEP_RAD_S plus the knots of a piecewise-linear effect, interpolated linearly.
    The batch path (:meth:`residual`) and the streaming path (:meth:`residual_one`, a
    node's per-sample call) do the same floating-point operations, so a node and
    ``detect --calibration`` give the same events; a per-sample evaluation of the
    regressors costs milliseconds, the table about a microsecond. ``table_error_nm`` is
    the largest difference from the exact model at the midpoints of the table.
    """

    def __init__(self, block: Mapping[str, Any]) -> None:
        self.block = block
        self.friction_model = block['friction_model']
        band = (block.get('noise') or {}).get('low_speed_band') or {}
        self.band_rad_s = float(band.get('speed_abs_below_rad_s', 0.0))
        lo, hi = block['speed_range_rad_s']
        self.speed_range = (float(lo), float(hi))
        knots = [float(k) for e in self.friction_model.get('effects') or []
                 for k in (e.get('params') or {}).get('knots_rad_s', [])]
        self._tables = {side: self._table(side, knots) for side in (1.0, -1.0)}
        self.at_zero = float(nominal_prediction(self.friction_model, np.zeros(1))[0])
        # Both sides packed for the compiled lookup (also LLRDetector.update_nominal's).
        self.table = llr_kernel.pack_table(
            self.band_rad_s, self.speed_range, self.at_zero, 1.0 / TABLE_STEP_RAD_S,
            _lookup(*self._tables[1.0]), _lookup(*self._tables[-1.0]))

    def _table(self, side: float, knots: list[float]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (|w| grid, nominal, slope to the next point) of one side of zero."""
        end = self.speed_range[1] if side > 0 else -self.speed_range[0]
        start = max(self.band_rad_s, TABLE_STEP_RAD_S * 1e-3)
        if end <= start:
            grid = np.array([start, start])
        else:
            grid = np.unique(np.concatenate([
                np.arange(start, end, TABLE_STEP_RAD_S), [end],
                [abs(k) for k in knots if start < abs(k) < end and k * side > 0]]))
        values = nominal_prediction(self.friction_model, side * grid)
        step = np.diff(grid)
        slope = np.append(np.divide(np.diff(values), step, out=np.zeros_like(step),
                                    where=step > 0), 0.0)
        return grid, values, slope

    @property
    def table_error_nm(self) -> float:
        """Return the largest |table - exact model| at the table's midpoints (N m)."""
        worst = 0.0
        for side, (grid, _, _) in self._tables.items():
            if len(grid) > 1:
                mid = 0.5 * (grid[1:] + grid[:-1]) * side
                exact = nominal_prediction(self.friction_model, mid)
                worst = max(worst, float(np.max(np.abs(self.nominal(mid) - exact))))
        return worst

    def nominal(self, speed: np.ndarray) -> np.ndarray:
        """Return the tabled nominal friction (NaN outside the tables' speeds, except 0)."""
        speed = np.asarray(speed, dtype=float)
        out = np.full(speed.shape, np.nan)
        out[speed == 0.0] = self.at_zero
        for side, (grid, values, slope) in self._tables.items():
            with np.errstate(invalid='ignore'):
                mag = speed * side
                on = (mag >= grid[0]) & (mag <= grid[-1])
            j = np.searchsorted(grid, mag[on], side='right') - 1
            j = np.minimum(j, len(grid) - 1)
            out[on] = values[j] + (mag[on] - grid[j]) * slope[j]
        return out

    def residual(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray
                 ) -> tuple[np.ndarray, dict[str, int]]:
        """Return (friction - nominal, NaN where not tested) and the counts by reason.

        Each side's table is evaluated by ``numpy.interp`` (NaN off the table), which forms
        ``slope_j (|w| - grid_j) + nominal_j`` with the slope computed as in the table: the
        floats of :meth:`residual_one` (test_calibrate checks it point by point); few
        temporaries, as fresh large arrays cost page faults.
        """
        speed = np.asarray(speed, dtype=float)
        friction = np.asarray(friction, dtype=float)
        time = np.asarray(time, dtype=float)
        finite = np.isfinite(speed)
        valid = finite & np.isfinite(friction) & np.isfinite(time)
        mag = np.abs(speed)
        with np.errstate(invalid='ignore'):
            low = valid & (mag < self.band_rad_s)
            outside = valid & ((speed < self.speed_range[0]) | (speed > self.speed_range[1]))
        (grid, values, _), (grid_below, values_below, _) = (self._tables[1.0],
                                                            self._tables[-1.0])
        out = np.interp(mag, grid, values, np.nan, np.nan)
        np.copyto(out, np.interp(mag, grid_below, values_below, np.nan, np.nan),
                  where=~(speed > 0.0))
        out[speed == 0.0] = self.at_zero
        np.subtract(friction, out, out=out)
        out[low | outside | ~finite] = np.nan
        return out, {'low_speed_band': int(np.count_nonzero(low)),
                     'outside_calibrated_range': int(np.count_nonzero(outside & ~low))}

    def residual_one(self, time: float, speed: float, friction: float
                     ) -> tuple[float, str | None]:
        """Return (friction - nominal, reason not tested or None) of one sample.

        The same arithmetic as :meth:`residual` on one sample (a node's per-sample call):
        core/llr_kernel.py ``nominal_residual`` on :attr:`table`, which also counts the
        samples not tested by reason (:attr:`not_tested`).
        """
        table = self.table
        try:
            out = _nominal_residual(table, time, speed, friction)
        except TypeError:
            out = _nominal_residual(table, float(time), float(speed), float(friction))
        code = table[0]
        return out, (None if code == 0.0 else _REASONS[int(code)])

    @property
    def not_tested(self) -> dict[str, int]:
        """Samples not tested since construction, by reason, through :attr:`table`."""
        return {name: int(self.table[llr_kernel.T_COUNTS + code - 1])
                for code, name in enumerate(_REASONS) if code}


def _lookup(grid: np.ndarray, values: np.ndarray, slope: np.ndarray) -> tuple:
    """Return one side's table with a bucket index for the binary search.

    ``first[b]`` counts the grid points at or below ``grid[0] + (b - 1) h`` (``h`` =
    TABLE_STEP_RAD_S); a speed ``m`` on the table falls in bucket ``b = int((m - grid[0]) /
    h)`` (within one bucket after rounding), so its interval lies between ``first[b]`` and
    ``first[b + 3]``: the search sees a few points, with the answer of a full one.
    """
    count = int((grid[-1] - grid[0]) / TABLE_STEP_RAD_S) + 6   # b + 3 < count on the table
    edges = grid[0] + (np.arange(count) - 1.0) * TABLE_STEP_RAD_S
    first = np.searchsorted(grid, edges, side='right')
    return grid, values, slope, first


def diagnose_fss(block: Mapping[str, Any], time: np.ndarray, speed: np.ndarray,
                 friction: np.ndarray, classifier: Any, config: Any) -> dict[str, Any]:
    """Return the window diagnosis of one wheel relative to its calibrated nominal.

    :func:`fss_inputs` (nominal's non-model-(1) part removed, band and out-of-range
    samples skipped, scales from the reference), the four stages (core/fss/pipeline.py
    ``diagnose``), then core/fss/classify.py ``relative_verdict`` (``status``: nominal,
    anomalous or unknown, with ``unknown_reason``) with the classifier's noise-ratio
    bound (``noise_ratio_bound`` of its spec's ``noise_ratio``). A viscous flag stands only
    when the window's viscous coefficient is also significantly above the reference's
    (``viscous_z`` > the one-sided quantile at VISCOUS_LEVEL, both standard errors of
    least squares): the classifier's threshold is a size (x1.14 on the shipped model),
    learned where the estimate is ten times more precise than on a 3-hour bus record;
    ``calibration.viscous_z`` keeps the value.
    """
    from dataclasses import replace

    from rwa_monitor.core.fss.classify import (noise_ratio_bound, relative_verdict,
                                               viscous_significant, viscous_z)
    from rwa_monitor.core.fss.pipeline import diagnose
    given, scales = fss_inputs(block, speed, friction)
    result = diagnose(speed, given, time, classifier, replace(config, **scales))
    spec = getattr(classifier, 'spec', None) or {}
    bound = noise_ratio_bound(spec.get('noise_ratio'))
    est, ref = result['estimates'], block['fss']
    se = est.get('viscous_se_nms')
    z = viscous_z(est['viscous_nms'], float('inf') if se is None else se,
                  ref['viscous_nms'], ref.get('viscous_se_nms', float('nan')))
    if result['anomalies'].get('viscous') and not viscous_significant(z):
        result['anomalies']['viscous'] = False
        result['viscous_not_significant'] = True
    status, flags, reason = relative_verdict(result['anomalies'], est['noise_std_nm'],
                                             ref['noise_std_nm'], bound)
    result['anomalies'] = flags
    result['status'] = status
    if reason:
        result['unknown_reason'] = reason
    skipped = int(np.sum(~np.isfinite(given) & np.isfinite(np.asarray(friction, float))))
    result['calibration'] = {**scales, 'samples_not_tested': skipped,
                             'viscous_z': z if np.isfinite(z) else None}
    return result
