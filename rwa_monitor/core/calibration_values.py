"""The values of a calibration and of a friction model: finite and in range, or refused.

A calibration edited to ``.nan`` (or fitted on data of 1e300) must not load: a NaN noise
or band would blind a wheel silently. :func:`check_values` walks the ``calibration``
mapping (docs/contracts.md, section Calibration) and raises ConfigError naming the first
key at fault; :func:`check_model_values` does the same for a ``friction_model`` block.
Used on load (telemetry/calibration_file.py) and before ``calibrate`` writes.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

from rwa_monitor.exceptions import ConfigError

# What evaluating a malformed model block may raise (turned into ConfigError by callers).
MALFORMED = (ConfigError, TypeError, ValueError, KeyError, AttributeError, IndexError)
# Keys that must be > 0 (a scale) or >= 0; every other number must only be finite.
_POSITIVE = {'std_nm', 'noise_std_nm', 'block_std_rad_s', 'block_s', 'block_samples',
             'level_threshold_rad_s', 'slope_threshold_rad_s2'}
_NON_NEGATIVE = {'speed_abs_below_rad_s', 'noise_std_rad_s', 'quiet_level_rad_s',
                 'correlation_time_s', 'samples', 'rms_nm', 'noise_band_rad_s',
                 'tested_samples'}
# Reported by the fit and read by nothing, or NaN by definition when not estimable.
_MAY_BE_NAN = {'viscous_se_nms', 'block_lag1_correlation', 'base_dry_window_std_nm'}


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _walk(value: Any, key: str, fail: Callable[[str, str], None]) -> None:
    """Check every number under ``value`` (``key``: its dotted name)."""
    if isinstance(value, Mapping):
        for name, item in value.items():
            _walk(item, f'{key}.{name}', fail)
        return
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _walk(item, f'{key}[{i}]', fail)
        return
    if not _number(value):
        return
    last = key.rsplit('.', 1)[-1].split('[')[0]
    if math.isnan(value) and last in _MAY_BE_NAN:
        return
    if not math.isfinite(value):
        fail(key, f'{value!r} is not a finite number')
    elif last in _POSITIVE and not value > 0:
        fail(key, f'{value!r} must be > 0')
    elif last in _NON_NEGATIVE and value < 0:
        fail(key, f'{value!r} must be >= 0')


def _failer(source: str) -> Callable[[str, str], None]:
    def fail(key: str, message: str) -> None:
        raise ConfigError(f'{source}: key {key}: {message}')
    return fail


def check_values(inner: Mapping[str, Any], source: str = 'calibration') -> None:
    """Raise ConfigError naming the first non-finite or out-of-range value of a calibration.

    ``inner``: the mapping under ``calibration:``. The wheels' friction model, noise,
    speed range and FSS reference, and the gyro blocks, are checked; the speed range
    must be ``[lo, hi]`` with lo <= hi.
    """
    fail = _failer(source)
    for part in ('wheels', 'gyro'):
        block = inner.get(part)
        if block is not None and not isinstance(block, Mapping):
            fail(f'calibration.{part}', 'expected a mapping')
        for name, wheel in (block or {}).items():
            key = f'calibration.{part}.{name}'
            if not isinstance(wheel, Mapping):
                fail(key, 'expected a mapping')
            _walk(wheel, key, fail)
            if part == 'wheels':
                _check_wheel_shape(wheel, key, fail)


def _check_wheel_shape(wheel: Mapping[str, Any], key: str,
                       fail: Callable[[str, str], None]) -> None:
    for name in ('friction_model', 'noise', 'fss'):
        if name in wheel and not isinstance(wheel[name], Mapping):
            fail(f'{key}.{name}', 'expected a mapping')
    noise = wheel.get('noise') or {}
    if not _number(noise.get('std_nm')):
        fail(f'{key}.noise.std_nm', 'missing (a number > 0 is needed)')
    band = noise.get('low_speed_band', {})
    if not isinstance(band, Mapping):
        fail(f'{key}.noise.low_speed_band', 'expected a mapping')
    tested = wheel.get('tested_speeds_rad_s', [])
    if not isinstance(tested, (list, tuple)) or not all(
            isinstance(v, (list, tuple)) and len(v) == 2 and all(map(_number, v))
            and v[0] <= v[1] for v in tested):
        fail(f'{key}.tested_speeds_rad_s', 'expected a list of [lo, hi] with lo <= hi')


def check_model_values(model: Mapping[str, Any], source: str = 'friction_model') -> None:
    """Raise ConfigError naming the first non-finite or out-of-range value of a model."""
    _walk(model, 'friction_model', _failer(source))
