"""Runners made from a parameter block and the files it names (calibration, refined model).

One place turns the ``llr_detector`` and ``vsadc_detector`` blocks (core/schema.py; the
``calibration_file`` and ``friction_model_file`` they name) into the core's runners
(core/wheel_runner.py, core/gyro_runner.py): ``detect``, the demo, the benchmarks and the
fleet call these, so a record gives the same events everywhere. Files are read and
checked once per set-up (:class:`WheelSetup`); each runner gets its own detector.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Mapping

from rwa_monitor.core.gyro_runner import GyroColumns, GyroRunner
from rwa_monitor.core.wheel_runner import WheelRunner
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry import Telemetry

CALIBRATION_KEY = 'calibration_file'
MODEL_KEY = 'friction_model_file'


@dataclass(frozen=True)
class WheelSetup:
    """The wheels' set-up of one record or spacecraft: parameters and the files' contents.

    ``calibration``: the checked calibration document (wheel blocks), or None;
    ``refined``: the refined model's regressors and the wheel it names (None: every
    wheel), or None. A calibration wins over a refined model (the calibration's nominal
    model is the reference then; docs/calibration.md).
    """

    values: Mapping[str, Any]
    calibration: Mapping[str, Any] | None = None
    calibration_path: str = ''
    refined: Any = None

    @property
    def setup(self) -> str:
        """Return ``calibrated``, ``refined`` or ``plain``."""
        return ('calibrated' if self.calibration is not None else
                'refined' if self.refined is not None else 'plain')

    def runner(self, wheel: str) -> WheelRunner:
        """Return a fresh runner of ``wheel``."""
        if self.calibration is not None:
            from rwa_monitor.core.nominal import NominalWheel
            return WheelRunner(wheel, self.values,
                               nominal=NominalWheel(self.calibration['wheels'][wheel]))
        if self.refined is not None and self.refined.wheel in (None, wheel):
            return WheelRunner(wheel, self.values, regressors=self.refined.regressors)
        return WheelRunner(wheel, self.values)

    def reads_aux(self, wheel: str) -> bool:
        """Return True if ``wheel``'s runner reads auxiliary channels (a refined model)."""
        return self.calibration is None and self.refined is not None and \
            self.refined.wheel in (None, wheel)


def wheel_setup(values: Mapping[str, Any], wheels: Iterable[str],
                aux: Iterable[str]) -> WheelSetup:
    """Return the set-up of a record's wheels (ConfigError naming a bad file or wheel).

    ``values``: checked LLR block; ``wheels``: the wheels with a friction column;
    ``aux``: the record's auxiliary channels (a refined model must find what it reads).
    """
    wheels = list(wheels)
    path = values.get(CALIBRATION_KEY) or ''
    if path:
        from rwa_monitor.core.calibration_check import check_wheels
        from rwa_monitor.telemetry.calibration_file import load
        document = load(path)
        check_wheels(document, wheels, str(path))
        return WheelSetup(values, document, str(path))
    from rwa_monitor.pipelines.llr import refined_model
    refined = refined_model(values.get(MODEL_KEY) or '', wheels, set(aux))
    return WheelSetup(values, refined=refined)


def gyro_runner(values: Mapping[str, Any],
                calibration: Mapping[str, Any] | None = None) -> GyroRunner:
    """Return a gyro runner; ``calibration`` (gyro block) wins over ``calibration_file``."""
    if calibration is None and values.get(CALIBRATION_KEY):
        from rwa_monitor.telemetry.calibration_file import load_gyro_calibration
        calibration = load_gyro_calibration(values[CALIBRATION_KEY])
    return GyroRunner(values, calibration)


def gyro_columns(tele: Telemetry) -> GyroColumns:
    """Return a record's gyro channels for the gyro runner (ConfigError if it has none)."""
    if tele.gyro is None:
        raise ConfigError(f'{tele.source}: no gyro_x/y/z columns')
    return GyroColumns(tele.time, tele.gyro, tele.attitude, tele.reference_rate,
                       {k: v for k, v in tele.present.items()
                        if k in ('gyro', 'star_tracker', 'reference_rate')})
