"""The LLR friction detector on a file: one wheel runner per wheel with a friction column.

Parameters are the ``llr_detector`` block of core/schema.py (LLR), the node's names;
node-only ones are accepted and ignored, unknown ones refused. ``calibration_file``
names a commissioning calibration (the wheels are tested against its nominal friction);
``friction_model_file`` a refined friction model written by ``rwa-monitor identify``
(its ``friction_model.yaml``; empty = model (1)), which applies to the wheel it names
when the file has that wheel, else to every wheel. The runners (core/wheel_runner.py,
made by pipelines/runners.py) hold the rules of feeding, not-tested samples and verdicts.
"""

from __future__ import annotations

import time as _time
from typing import Any, Iterable, Mapping, NamedTuple

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import RegressorSet
from rwa_monitor.core.schema import LLR, llr_kwargs
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.pipelines import Detection
from rwa_monitor.pipelines.runners import CALIBRATION_KEY, MODEL_KEY, wheel_setup
from rwa_monitor.telemetry import Telemetry

SCHEMA = LLR
NODE = LLR.name
DEFAULTS = {name: LLR[name].default for name in LLR.names(('all',))}


class RefinedModel(NamedTuple):
    """A refined friction model: the wheel it names (None: every wheel) and its regressors."""

    wheel: str | None
    regressors: RegressorSet


def applies(tele: Telemetry) -> bool:
    """Return True if some wheel of the record has a friction column."""
    return any(w.friction is not None for w in tele.wheels.values())


def detector_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """Return the detector keywords for a parameter block (ConfigError names a bad one)."""
    return llr_kwargs(LLR.validate(config))


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


def run_with_summary(tele: Telemetry, config: Mapping[str, Any]) -> Detection:
    """Run one wheel runner per wheel with a friction column, to the end of the record.

    Returns the events and per wheel its summary: events, the runner's facts (samples,
    rejected samples by reason, samples not tested with a calibration, the verdict of
    core/coverage.py) and its run time.
    """
    values = LLR.validate(config)
    tele = tele.only('wheels')  # a multi-rate record: the wheel stream's own samples
    wheels = [w for w, ch in tele.wheels.items() if ch.friction is not None]
    setup = wheel_setup(values, wheels, tele.aux)
    events: list[AnomalyEvent] = []
    summary: dict[str, Any] = {}
    for wheel_id in wheels:
        start = _time.perf_counter()
        runner = setup.runner(wheel_id)
        ch = tele.wheels[wheel_id]
        found = runner.feed(tele.time, ch.speed, ch.friction,
                            tele.aux if setup.reads_aux(wheel_id) else None)
        found += runner.finish()
        entry = {'events': len(found), **runner.facts().fields()}
        if setup.calibration is not None:
            entry['calibration'] = setup.calibration_path
        entry['runtime_s'] = _time.perf_counter() - start
        summary[wheel_id] = entry
        events.extend(found)
    return Detection(events, summary)


def run(tele: Telemetry, config: Mapping[str, Any]) -> list[AnomalyEvent]:
    """Return the events of one LLR detector per wheel with a friction column."""
    return run_with_summary(tele, config).events


__all__ = ['applies', 'CALIBRATION_KEY', 'detector_kwargs', 'friction_model', 'MODEL_KEY',
           'RefinedModel', 'refined_model', 'run', 'run_with_summary']
