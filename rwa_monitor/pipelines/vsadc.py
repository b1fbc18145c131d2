"""VSADC on a file: gyro drift/bias events per axis from gyro_*, q_* and ref_* columns.

Parameters are the ``vsadc_detector`` block of core/schema.py (VSADC), the node's names;
node-only ones are accepted and ignored, unknown ones refused. ``feature`` chooses the
detector (:func:`rwa_monitor.core.gyro_diagnosis.make_gyro_detector`): ``residual``
(default) the gyro-minus-star-tracker diagnosis, which needs no guidance reference, with
the thresholds of the ``calibration_file`` gyro block; ``paper`` the two residuals of the
paper; a file without ``ref_*`` columns then uses the ``reference_rate`` parameter. The
gyro runner (core/gyro_runner.py) pairs the streams and judges each axis.
"""

from __future__ import annotations

import time as _time
from typing import Any, Mapping, NamedTuple

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import VSADC, vsadc_kwargs
from rwa_monitor.pipelines import Detection
from rwa_monitor.pipelines.runners import gyro_columns, gyro_runner
from rwa_monitor.telemetry import Telemetry

SCHEMA = VSADC
NODE = VSADC.name
DEFAULTS: dict[str, Any] = {name: VSADC[name].default for name in VSADC.names(('all',))}


class LabelSeries(NamedTuple):
    """The state of each axis after each row (n, axes), the events and the detector."""

    labels: np.ndarray
    events: list[AnomalyEvent]
    detector: Any


def applies(tele: Telemetry) -> bool:
    """Return True if the record has gyro and star-tracker columns."""
    return tele.gyro is not None and tele.attitude is not None


def detector_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """Return VsadcDetector keywords from a parameter block (ConfigError names a bad one)."""
    return vsadc_kwargs(VSADC.validate(config))


def make_detector(config: Mapping[str, Any],
                  calibration: Mapping[str, Any] | None = None) -> Any:
    """Return the configured gyro detector (``feature``: residual or paper).

    ``calibration`` (axis -> dict of calibrate_gyro) wins over the ``calibration_file``
    parameter; both apply to the residual feature only.
    """
    return gyro_runner(VSADC.validate(config), calibration).detector


def label_series(tele: Telemetry, config: Mapping[str, Any],
                 calibration: Mapping[str, Any] | None = None) -> LabelSeries:
    """Run the gyro runner over the rows; return labels, events and the detector.

    Labels are the state after each row (held on rows the detector could not use, and on
    rows without a gyro sample in a multi-rate record). Event indices count gyro samples.
    """
    runner = gyro_runner(VSADC.validate(config), calibration)
    labels = np.zeros((len(tele), len(runner.detector.axes)), dtype=np.int8)
    events = runner.feed(gyro_columns(tele), labels)
    return LabelSeries(labels, events, runner.detector)


def run_with_summary(tele: Telemetry, config: Mapping[str, Any],
                     calibration: Mapping[str, Any] | None = None) -> Detection:
    """Run the gyro diagnosis on the three axes; return the events and a per-axis summary.

    A bad value of one gyro axis is rejected on that axis only (``bad_axis_<a>``
    counters); ``final_state`` is ``unknown`` for an axis that was not examined (never
    ready, or most of its samples rejected: core/gyro_runner.py ``axis_coverage``), whose
    ``verdict`` says which, with the counts.
    """
    start = _time.perf_counter()
    runner = gyro_runner(VSADC.validate(config), calibration)
    events = runner.feed(gyro_columns(tele)) + runner.finish()
    runtime = _time.perf_counter() - start
    facts = runner.facts()
    summary: dict[str, Any] = {}
    for part in facts.parts:
        entry = part.fields()
        summary[part.component] = {
            'events': sum(e.component == part.component for e in events),
            'final_state': entry['final_state'], 'ready': entry['ready'],
            'samples_used': entry['samples_used'], **part.verdict.fields()}
    summary['counters'] = dict(facts.rejected)
    summary['runtime_s'] = runtime
    return Detection(events, summary)


def run(tele: Telemetry, config: Mapping[str, Any],
        calibration: Mapping[str, Any] | None = None) -> list[AnomalyEvent]:
    """Run the gyro diagnosis on the three axes; return the events (DESIGN.md contract)."""
    return run_with_summary(tele, config, calibration).events
