"""The calibration in force in a detector node (parameter ``calibration_file``).

One holder per node. The parameter (core/schema.py ``CALIBRATION_FILE``) is checked by
loading the file (telemetry/calibration_file.py ``load``, from the node's check of its
parameters), so a missing or malformed file is refused with the reason naming the file and
the key: at start-up the node does not start (ConfigError), at run time the set request
is rejected and the node keeps its last good calibration. An accepted change reloads
the file (setting the same path again reloads it too), is logged, counted and shown on
/diagnostics (``calibration_file``, ``calibration_wheels``, ``calibration_loads``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rwa_monitor.core.calibrate import NominalWheel
from rwa_monitor.telemetry.calibration_file import load

NAME = 'calibration_file'


def check(values: dict[str, Any]) -> None:
    """Load the proposed ``calibration_file`` (ValueError naming the file and the key)."""
    if values.get(NAME):
        load(values[NAME])


class CalibrationInForce:
    """The loaded calibration and what it did: samples not tested, wheels refused."""

    def __init__(self, path: str = '') -> None:
        self.path = ''
        self.document: dict[str, Any] | None = None
        self.loads = 0
        self._wheels: dict[str, NominalWheel] = {}
        self.not_tested: dict[str, dict[str, int]] = {}
        self.set(path)

    def set(self, path: str) -> str:
        """Load ``path`` ('' = none); return a one-line description (ConfigError if bad)."""
        document = load(path) if path else None
        self.path, self.document = path, document
        self._wheels = ({w: NominalWheel(b) for w, b in document['wheels'].items()}
                        if document else {})
        self.loads += 1
        return self.describe()

    def describe(self) -> str:
        """Return the calibration in force in one line."""
        if self.document is None:
            return 'no calibration: model (1) of the paper'
        return f'calibration {self.path} in force (wheels {", ".join(self._wheels)})'

    @property
    def active(self) -> bool:
        """Return True when a calibration is loaded."""
        return self.document is not None

    def covers(self, wheel_id: str) -> bool:
        """Return True when no calibration is loaded or it calibrates ``wheel_id``."""
        return self.document is None or wheel_id in self._wheels

    def block(self, wheel_id: str) -> dict[str, Any] | None:
        """Return the wheel's calibration block, or None (no calibration or wheel)."""
        return None if self.document is None else self.document['wheels'].get(wheel_id)

    def residual(self, wheel_id: str, t: float, speed: float, friction: float) -> float:
        """Return the friction to test: itself, or the residual against the nominal.

        The residual is NaN inside the low-speed band or outside the calibrated speed
        range (counted per reason).
        """
        nominal = self._wheels.get(wheel_id)
        if nominal is None:
            return friction
        out, skipped = nominal.residual(np.array([t]), np.array([speed]),
                                        np.array([friction]))
        counts = self.not_tested.setdefault(wheel_id, {k: 0 for k in skipped})
        for reason, n in skipped.items():
            counts[reason] += n
        return float(out[0])

    def values(self, wheel_id: str | None = None) -> dict[str, Any]:
        """Return the diagnostics KeyValues of the calibration (per wheel if given)."""
        out: dict[str, Any] = {NAME: self.path or 'none', 'calibration_loads': self.loads,
                               'calibration_wheels': ','.join(self._wheels)}
        if wheel_id is not None:
            for reason, n in self.not_tested.get(wheel_id, {}).items():
                out[f'not_tested_{reason}'] = n
        return out
