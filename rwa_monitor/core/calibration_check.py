"""The shape of calibration.yaml, version 1 (docs/contracts.md): checked on every load.

Every error names the file and the key at fault (telemetry/calibration_file.py reads the
file; this checks what it holds).
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.core.calibration_values import check_values, MALFORMED
from rwa_monitor.core.nominal import nominal_prediction
from rwa_monitor.exceptions import ConfigError

VERSION = 1


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
