"""The calibration in force in a detector node (parameter ``calibration_file``).

One holder per node. The parameter (core/schema.py ``CALIBRATION_FILE``) is checked by
loading the file (telemetry/calibration_file.py ``load``, from the node's check of its
parameters), so a missing or malformed file is refused with the reason naming the file and
the key: at start-up the node does not start (ConfigError), at run time the set request
is rejected and the node keeps its last good calibration. An accepted change reloads
the file (setting the same path again reloads it too), is logged and counted; a node
publishes it on ``anomalies`` as one event of kind ``calibration_changed`` (level OK,
not an alarm; :meth:`CalibrationInForce.change_status`, docs/contracts.md "Event
fields") and shows the calibration in force on /diagnostics (``calibration_file``,
``calibration_sha256``, ``calibration_loaded_unix_s``, ``calibration_wheels``,
``calibration_loads``).
"""

from __future__ import annotations

import hashlib
import math
import pathlib
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus

from rwa_monitor.core import keys
from rwa_monitor.core.calibrate import NominalWheel
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.telemetry.calibration_file import load
from rwa_monitor.telemetry.codecs import key_values

NAME = keys.CALIBRATION_FILE
COMPONENT = 'calibration'   # the component of the change events and of the health status


def check(values: dict[str, Any]) -> None:
    """Load the proposed ``calibration_file`` (ValueError naming the file and the key)."""
    if values.get(NAME):
        load(values[NAME])


def _sha256(path: str) -> str:
    try:
        return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()
    except OSError:
        return ''


class CalibrationInForce:
    """The loaded calibration: its file, hash, load time and wheels; nominal models.

    The samples a calibration leaves untested are counted by each wheel's runner
    (core/wheel_runner.py) and shown by the node per wheel.
    """

    def __init__(self, path: str = '') -> None:
        self.path = ''
        self.previous = ''
        self.sha256 = ''
        self.loaded_unix_s = math.nan
        self.document: dict[str, Any] | None = None
        self.loads = 0
        self._wheels: list[str] = []
        self.set(path)

    def set(self, path: str) -> str:
        """Load ``path`` ('' = none); return a one-line description (ConfigError if bad).

        On an error nothing changes: the last good calibration stays in force.
        """
        document = load(path) if path else None
        wheels = list(document['wheels']) if document else []
        self.previous = self.path
        self.path, self.document, self._wheels = path, document, wheels
        self.sha256 = _sha256(path) if path else ''
        self.loaded_unix_s = time.time()
        self.loads += 1
        return self.describe()

    def describe(self) -> str:
        """Return the calibration in force in one line."""
        if self.document is None:
            return 'no calibration: model (1) of the paper'
        return (f'calibration {self.path} (sha256 {self.sha256[:12]}) in force (wheels '
                f'{", ".join(self._wheels)})')

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

    def nominal(self, wheel_id: str) -> NominalWheel | None:
        """Return a fresh nominal model of ``wheel_id`` for its runner, or None (plain).

        Each runner gets its own: the model's table counts the samples it leaves untested.
        """
        block = self.block(wheel_id)
        return None if block is None else NominalWheel(block)

    def values(self) -> dict[str, Any]:
        """Return the diagnostics KeyValues of the calibration in force."""
        return {NAME: self.path or 'none',
                keys.CALIBRATION_SHA256: self.sha256 or 'none',
                keys.CALIBRATION_LOADED: self.loaded_unix_s,
                keys.CALIBRATION_LOADS: self.loads,
                keys.CALIBRATION_WHEELS: ','.join(self._wheels)}

    def change_event(self, detector: str, time_s: float) -> AnomalyEvent:
        """Return the event of the change just made (kind ``calibration_changed``).

        ``time_s`` is the node clock (telemetry time under a replay); change and
        declaration indices are -1 (no telemetry row); the details name the file in force,
        its hash, load time and wheels, and the file it replaced ('none': no calibration).
        """
        details = self.values()
        details[keys.PREVIOUS_CALIBRATION] = self.previous or 'none'
        return AnomalyEvent(detector=detector, component=COMPONENT,
                            kind=keys.CALIBRATION_KIND, time=float(time_s), index=-1,
                            declared_time=float(time_s), declared_index=-1,
                            details=details)

    def change_status(self, detector: str, time_s: float, node_name: str
                      ) -> DiagnosticStatus:
        """Return the ``anomalies`` status of the change just made (level OK)."""
        event = self.change_event(detector, time_s)
        return DiagnosticStatus(level=DiagnosticStatus.OK,
                                name=f'{node_name}: {COMPONENT}', hardware_id=COMPONENT,
                                message=self.describe(), values=key_values(event.fields()))

    def health(self) -> tuple[bytes, str, dict[str, Any]]:
        """Return the /diagnostics ``(level, message, values)`` of the calibration."""
        return DiagnosticStatus.OK, self.describe(), self.values()
