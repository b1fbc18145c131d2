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

Friction changes inside the calibration data are found by the identification's jump
detector (baseline.py); each is reported in ``warnings`` with wheel and time, and the
model then describes the data after the last change (see :func:`calibrate_wheel`).

The gyro block is filled by ``rwa_monitor.core.vsadc.calibrate_gyro`` when that function
exists (it takes time, gyro (n, 3), star-tracker quaternion (n, 4, scalar last) and the
reference rate (n, 3) or None, and returns a plain dict per axis); otherwise it is empty.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from rwa_monitor.exceptions import ConfigError

VERSION = 1
# |speed| bin edges (rad/s) of the noise profile; the last bin is open.
BAND_EDGES = (0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0)
# Level of the test "this bin's residual is larger than the reference noise".
BAND_LEVEL = 1.0e-3
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
    upper edge of the highest larger bin below the reference region (0: no band).
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
    bounds = list(edges) + [np.inf]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if lo >= ref_from:
            break
        part = residual[(speed >= lo) & (speed < min(hi, ref_from))]
        if part.size < 2:
            continue
        rms = float(np.sqrt(np.mean(part ** 2)))
        limit = std * np.sqrt(stats.chi2.isf(level, part.size) / part.size)
        larger = bool(rms > limit)
        profile.append({'speed_abs_from_rad_s': float(lo),
                        'speed_abs_to_rad_s': float(min(hi, ref_from)),
                        'samples': int(part.size), 'rms_nm': rms, 'larger': larger})
        if larger:
            band = float(min(hi, ref_from))
    inside = residual[speed < band]
    return {'std_nm': std,
            'reference_speed_abs_from_rad_s': float(ref_from),
            'low_speed_band': {'speed_abs_below_rad_s': band,
                               'std_nm': float(np.sqrt(np.mean(inside ** 2)))
                               if inside.size else std,
                               'samples': int(inside.size)},
            'profile': profile}


def calibrate_wheel(wheel: str, time: np.ndarray, speed: np.ndarray, friction: np.ndarray,
                    jumps: bool = True) -> tuple[dict[str, Any], list[str]]:
    """Return (the wheel's calibration block, warnings) from fault-free telemetry.

    Non-finite rows are dropped. A friction change found in the data (identify's jump
    detector) is a warning naming the wheel and the time; the model's weights are then
    those of the last segment (identify's snippet), the noise is measured on that
    segment. Raise NotIdentifiableError when the data cannot separate dry from viscous.
    """
    from rwa_monitor.core.identify.data import IdentData
    from rwa_monitor.core.identify.differentiate import local_noise_std
    from rwa_monitor.core.identify.model import snippet
    from rwa_monitor.core.identify.select import identify
    time = np.asarray(time, dtype=float)
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    ok = np.isfinite(time) & np.isfinite(speed) & np.isfinite(friction)
    t, w, f = time[ok], speed[ok], friction[ok]
    sign_change = np.zeros(len(w), dtype=bool)
    flips = np.flatnonzero(np.sign(w[1:]) != np.sign(w[:-1]))
    for k in flips:
        sign_change[max(0, k - 5):k + 7] = True
    noise = local_noise_std(t, f, 5, 2, max(200, len(t) // 20), exclude=sign_change)
    data = IdentData(wheel=wheel, time=t, speed=w, friction=f, noise_std=noise,
                     counts={'rows': int(len(time)), 'non_finite_rows': int(np.sum(~ok))})
    selection = identify(data, jumps=jumps)
    model = snippet(selection)['friction_model']
    warnings = []
    starts = [int(k) for k in selection.segments.starts[1:]]
    for k in starts:
        warnings.append(f'{wheel}: a friction change at t = {t[k]:.1f} s in the '
                        f'calibration data (the model describes the data after the last '
                        f'one)')
    last = starts[-1] if starts else 0
    residual = f[last:] - nominal_prediction(model, w[last:], t[last:])
    noise_model = noise_profile(w[last:], residual)
    model['noise_std_nm'] = noise_model['std_nm']
    block = {
        'friction_model': model,
        'noise': noise_model,
        'speed_range_rad_s': [float(np.min(w)), float(np.max(w))],
        'fss': {'base_dry_nm': float(model['weights']['dry']),
                'viscous_nms': float(model['weights']['viscous']),
                'noise_std_nm': noise_model['std_nm']},
        'samples': int(len(t)),
        'changes_found_s': [float(t[k]) for k in starts],
    }
    return block, warnings


def calibrate_gyro(time: np.ndarray, gyro: np.ndarray | None, quaternion: np.ndarray | None,
                   reference_rate: np.ndarray | None) -> dict[str, Any]:
    """Return the gyro block (per axis) from the gyro diagnosis' own calibration function.

    Empty when the record has no gyro and star tracker, or while core.vsadc provides no
    ``calibrate_gyro``.
    """
    if gyro is None or quaternion is None:
        return {}
    from rwa_monitor.core import vsadc
    fill = getattr(vsadc, 'calibrate_gyro', None)
    if fill is None:
        return {}
    return dict(fill(time, gyro, quaternion, reference_rate))


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
        except ConfigError as err:
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
    """

    def __init__(self, block: Mapping[str, Any]) -> None:
        self.block = block
        self.friction_model = block['friction_model']
        band = (block.get('noise') or {}).get('low_speed_band') or {}
        self.band_rad_s = float(band.get('speed_abs_below_rad_s', 0.0))
        lo, hi = block['speed_range_rad_s']
        self.speed_range = (float(lo), float(hi))

    def residual(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray
                 ) -> tuple[np.ndarray, dict[str, int]]:
        """Return (friction - nominal, NaN where not tested) and the counts by reason."""
        speed = np.asarray(speed, dtype=float)
        friction = np.asarray(friction, dtype=float)
        time = np.asarray(time, dtype=float)
        valid = np.isfinite(speed) & np.isfinite(friction) & np.isfinite(time)
        with np.errstate(invalid='ignore'):
            low = valid & (np.abs(speed) < self.band_rad_s)
            outside = valid & ((speed < self.speed_range[0]) | (speed > self.speed_range[1]))
        safe = np.where(np.isfinite(speed), speed, 0.0)
        out = friction - nominal_prediction(self.friction_model, safe, time)
        out[low | outside] = np.nan
        out[~np.isfinite(speed)] = np.nan
        return out, {'low_speed_band': int(np.sum(low)),
                     'outside_calibrated_range': int(np.sum(outside & ~low))}
