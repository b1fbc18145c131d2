"""The ``gyro:`` block of a commissioning calibration.yaml (DESIGN.md, Calibration).

Read by ``rwa-monitor detect`` (``calibration_file`` parameter) and the ``vsadc_detector``
node; written by the calibration command from
:func:`rwa_monitor.core.gyro_calibration.calibrate_gyro` (axis -> dict).
"""

from __future__ import annotations

import pathlib
from typing import Any

import yaml

AXES = ('x', 'y', 'z')


def load_gyro_calibration(path: str | pathlib.Path) -> dict[str, dict[str, Any]]:
    """Return the ``calibration.gyro`` block (axis -> dict) of a calibration.yaml file.

    ValueError with the file name when it cannot be read or has no usable gyro block.
    """
    try:
        data = yaml.safe_load(pathlib.Path(path).read_text())
    except OSError as err:
        raise ValueError(f'{path}: cannot read: {err.strerror}') from None
    except yaml.YAMLError as err:
        raise ValueError(f'{path}: not valid YAML: {err}') from None
    block = None
    if isinstance(data, dict) and isinstance(data.get('calibration'), dict):
        block = data['calibration'].get('gyro')
    if not isinstance(block, dict) or not block:
        raise ValueError(f'{path}: no calibration.gyro block')
    bad = [a for a in block if a not in AXES or not isinstance(block[a], dict)]
    if bad:
        raise ValueError(f'{path}: calibration.gyro: unknown axis entries {bad}')
    return block
