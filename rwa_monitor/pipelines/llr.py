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
from typing import Any, Mapping

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import LLR, llr_kwargs
from rwa_monitor.pipelines import Detection
from rwa_monitor.pipelines.runners import (CALIBRATION_KEY, friction_model, MODEL_KEY,
                                           refined_model, RefinedModel, wheel_setup)
from rwa_monitor.telemetry import Telemetry

SCHEMA = LLR
NODE = LLR.name
DEFAULTS = {name: LLR[name].default for name in LLR.names(('all',))}


def applies(tele: Telemetry) -> bool:
    """Return True if some wheel of the record has a friction column."""
    return any(w.friction is not None for w in tele.wheels.values())


def detector_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """Return the detector keywords for a parameter block (ConfigError names a bad one)."""
    return llr_kwargs(LLR.validate(config))


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
