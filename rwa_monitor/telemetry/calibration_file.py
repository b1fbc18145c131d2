"""Reading a calibration file (``rwa-monitor calibrate`` DIR/calibration.yaml).

The shape is checked by core/calibrate.py ``check_calibration``; every error names the
file and the key (docs/contracts.md, section Calibration). The ``gyro:`` block alone
(axis -> dict of :func:`rwa_monitor.core.gyro_calibration.calibrate_gyro`) is what the
gyro diagnosis reads (``detect`` and the ``vsadc_detector`` node).
"""

from __future__ import annotations

import os
from typing import Any

from rwa_monitor.core.calibrate import check_calibration
from rwa_monitor.core.calibration_values import check_values
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.yaml_file import read_yaml

AXES = ('x', 'y', 'z')


def _read(path: str | os.PathLike) -> Any:
    return read_yaml(path)


def load(path: str | os.PathLike) -> dict[str, Any]:
    """Return the checked calibration mapping of a file (ConfigError naming file and key)."""
    return check_calibration(_read(path), str(path))


def load_gyro_calibration(path: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """Return the ``calibration.gyro`` block (axis -> dict) of a calibration.yaml file.

    ConfigError (a ValueError) with the file name when it cannot be read or has no usable
    gyro block.
    """
    data = _read(path)
    block = None
    if isinstance(data, dict) and isinstance(data.get('calibration'), dict):
        block = data['calibration'].get('gyro')
    if not isinstance(block, dict) or not block:
        raise ConfigError(f'{path}: no calibration.gyro block')
    bad = [a for a in block if a not in AXES or not isinstance(block[a], dict)]
    if bad:
        raise ConfigError(f'{path}: calibration.gyro: unknown axis entries {bad}')
    check_values({'gyro': block}, str(path))
    return block
