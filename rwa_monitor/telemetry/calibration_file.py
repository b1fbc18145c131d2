"""Reading a calibration file (``rwa-monitor calibrate`` DIR/calibration.yaml).

The shape is checked by core/calibrate.py ``check_calibration``; every error names the
file and the key (docs/contracts.md, section Calibration).
"""

from __future__ import annotations

import os
import pathlib
from typing import Any

import yaml

from rwa_monitor.core.calibrate import check_calibration
from rwa_monitor.exceptions import ConfigError


def load(path: str | os.PathLike) -> dict[str, Any]:
    """Return the checked calibration mapping of a file (ConfigError naming file and key)."""
    try:
        text = pathlib.Path(path).read_text()
    except OSError as err:
        raise ConfigError(f'{path}: cannot read: {err.strerror}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f'{path}: not valid YAML: {err}') from None
    return check_calibration(data, str(path))
