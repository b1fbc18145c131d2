"""Runners made from a parameter block and the files it names (calibration, refined model).

One place turns the ``llr_detector`` and ``vsadc_detector`` blocks (core/schema.py; the
``calibration_file`` and ``friction_model_file`` they name) into the core's runners
(core/wheel_runner.py, core/gyro_runner.py): ``detect``, the demo, the benchmarks and the
fleet call these, so a record gives the same events everywhere. Files are read and
checked once per set-up (:class:`WheelSetup`); each runner gets its own detector.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, NamedTuple

import numpy as np

from rwa_monitor.core.friction import RegressorSet
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
    _nominals: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def setup(self) -> str:
        """Return ``calibrated``, ``refined`` or ``plain``."""
        return ('calibrated' if self.calibration is not None else
                'refined' if self.refined is not None else 'plain')

    def runner(self, wheel: str) -> WheelRunner:
        """Return a fresh runner of ``wheel``."""
        if self.calibration is not None:
            return WheelRunner(wheel, self.values, nominal=self._nominal(wheel))
        if self.refined is not None and self.refined.wheel in (None, wheel):
            return WheelRunner(wheel, self.values, regressors=self.refined.regressors)
        return WheelRunner(wheel, self.values)

    def _nominal(self, wheel: str) -> Any:
        """Return a fresh nominal model of ``wheel``: a copy of one built once.

        Building one tables the nominal friction over the calibrated speeds (tens of
        milliseconds with a smooth speed effect, more than a pass's detection); a copy
        gets its own table, whose slots count the samples its runner leaves untested.
        """
        if wheel not in self._nominals:
            from rwa_monitor.core.nominal import NominalWheel
            self._nominals[wheel] = NominalWheel(self.calibration['wheels'][wheel])
        fresh = copy.copy(self._nominals[wheel])
        fresh.table = fresh.table.copy()
        return fresh

    def reads_aux(self, wheel: str) -> bool:
        """Return True if ``wheel``'s runner reads auxiliary channels (a refined model)."""
        return self.calibration is None and self.refined is not None and \
            self.refined.wheel in (None, wheel)


class RefinedModel(NamedTuple):
    """A refined friction model: the wheel it names (None: every wheel) and its regressors."""

    wheel: str | None
    regressors: RegressorSet


def friction_model(path: str, tele: Telemetry) -> RefinedModel | None:
    """Return the refined model of a file written by identify for a record, or None."""
    return refined_model(path, tele.wheels, set(tele.aux))


def refined_model(path: str, wheels: Iterable[str], aux: set[str]) -> RefinedModel | None:
    """Return the refined model of a file written by identify, or None if unset.

    ``wheels``: the record's wheels; ``aux``: its auxiliary channels. Raise ConfigError
    if the file cannot be read or the record lacks a channel it reads.
    """
    if not path:
        return None
    from rwa_monitor.core.calibration_values import check_model_values, MALFORMED
    from rwa_monitor.core.identify.model import aux_channels, regressors_from_config
    from rwa_monitor.telemetry.yaml_file import read_yaml
    cfg = read_yaml(path)
    if not isinstance(cfg, Mapping) or not isinstance(cfg.get('friction_model', cfg),
                                                      Mapping):
        raise ConfigError(f'{MODEL_KEY} {path!r}: expected a friction_model mapping')
    check_model_values(cfg.get('friction_model', cfg), f'{MODEL_KEY} {path!r}')
    try:
        missing = [c for c in aux_channels(cfg) if c not in aux]
        if missing:
            raise ConfigError(f'{MODEL_KEY} {path!r} reads channel(s) the file lacks: '
                              f'{", ".join(map(str, missing))}')
        regressors = regressors_from_config(cfg)
        regressors.matrix(np.array([1.0, -1.0]), np.zeros(2),
                          {c: np.zeros(2) for c in aux})
    except MALFORMED as err:
        if isinstance(err, ConfigError):
            raise
        raise ConfigError(f'{MODEL_KEY} {path!r}: malformed friction_model: {err!r}') from None
    wheel = cfg.get('friction_model', cfg).get('wheel')
    return RefinedModel(wheel if isinstance(wheel, str) and wheel in set(wheels) else None,
                        regressors)


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
