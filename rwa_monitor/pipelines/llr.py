"""The LLR friction detector on a file: one detector per wheel that has a friction column.

Parameters are the ``llr_detector`` block of core/schema.py (LLR), the node's names;
node-only ones are accepted and ignored, unknown ones refused. ``friction_model_file``
names a refined friction model written by ``rwa-monitor identify`` (its
``friction_model.yaml``); empty = model (1). The refined model applies to the wheel it
names when the file has that wheel, else to every wheel.
"""

from __future__ import annotations

import time as _time
from typing import Any, Mapping, NamedTuple

import numpy as np

from rwa_monitor.core.coverage import judge, llr_samples_needed
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import RegressorSet
from rwa_monitor.core.schema import LLR, llr_kwargs
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.pipelines import Detection
from rwa_monitor.telemetry import Telemetry

SCHEMA = LLR
NODE = LLR.name
DEFAULTS = {name: LLR[name].default for name in LLR.names(('all',))}
MODEL_KEY = 'friction_model_file'
CALIBRATION_KEY = 'calibration_file'


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
    """Return the refined model of a file written by identify, or None if unset.

    Raise ConfigError if the file cannot be read or the record lacks a channel it reads.
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
        missing = [c for c in aux_channels(cfg) if c not in tele.aux]
        if missing:
            raise ConfigError(f'{MODEL_KEY} {path!r} reads channel(s) the file lacks: '
                              f'{", ".join(map(str, missing))}')
        regressors = regressors_from_config(cfg)
        regressors.matrix(np.array([1.0, -1.0]), np.zeros(2),
                          {c: np.zeros(2) for c in tele.aux})
    except MALFORMED as err:
        if isinstance(err, ConfigError):
            raise
        raise ConfigError(f'{MODEL_KEY} {path!r}: malformed friction_model: {err!r}') from None
    wheel = cfg.get('friction_model', cfg).get('wheel')
    return RefinedModel(wheel if isinstance(wheel, str) and wheel in tele.wheels else None,
                        regressors)


def run_with_summary(tele: Telemetry, config: Mapping[str, Any]) -> Detection:
    """Run one detector per wheel (batch path); return the events and a per-wheel summary.

    The summary per wheel holds the number of events, samples, the detector's counters
    of rejected samples, its run time and its verdict (:func:`judge_wheels`).
    """
    from rwa_monitor.core.llr import detect_batch_with_counters
    values = LLR.validate(config)
    kwargs = llr_kwargs(values)
    tele = tele.only('wheels')  # a multi-rate record: the wheel stream's own samples
    if values[CALIBRATION_KEY]:
        from rwa_monitor.pipelines import calibrated
        events, summary = calibrated.run_llr(tele, kwargs, values[CALIBRATION_KEY])
        return Detection(events, judge_wheels(summary, llr_samples_needed(kwargs)))
    refined = friction_model(values[MODEL_KEY], tele)
    events: list[AnomalyEvent] = []
    summary: dict[str, Any] = {}
    for wheel_id, wheel in tele.wheels.items():
        if wheel.friction is None:
            continue
        start = _time.perf_counter()
        model = {}
        if refined and refined.wheel in (None, wheel_id):
            model = {'regressors': refined.regressors, 'aux': tele.aux}
        found, counters = detect_batch_with_counters(
            tele.time, wheel.speed, wheel.friction, component=wheel_id, **kwargs, **model)
        summary[wheel_id] = {'events': len(found), 'samples': len(tele),
                             'rejected': dict(counters),
                             'runtime_s': _time.perf_counter() - start}
        events.extend(found)
    return Detection(events, judge_wheels(summary, llr_samples_needed(kwargs)))


def judge_wheels(summary: dict[str, Any], needed: int) -> dict[str, Any]:
    """Add to each wheel's summary its verdict and counts (core/coverage.py); return it.

    Usable samples: the wheel's samples less those the detector rejected (non-finite, out
    of range, time not increasing, auxiliary channel missing) and those a calibration
    left untested (``not_tested``); tests skipped as ill-conditioned still used them.
    """
    for entry in summary.values():
        rejected = sum(v for k, v in entry['rejected'].items() if k != 'ill_conditioned')
        untested = sum(entry.get('not_tested', {}).values())
        usable = entry['samples'] - rejected - untested
        entry.update(judge(entry['samples'], usable, needed, 'the LLR test').fields())
    return summary


def run(tele: Telemetry, config: Mapping[str, Any]) -> list[AnomalyEvent]:
    """Return the events of one LLR detector per wheel with a friction column."""
    return run_with_summary(tele, config).events
