"""VSADC on a file: gyro drift/bias events per axis from gyro_*, q_* and ref_* columns.

Parameters are the ``vsadc_detector`` block of core/schema.py (VSADC), the node's names;
node-only ones are accepted and ignored, unknown ones refused. A file without ``ref_*``
columns uses the ``reference_rate`` parameter (rad/s, 3 values).
"""

from __future__ import annotations

import time as _time
from typing import Any, Mapping, NamedTuple

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.schema import VSADC, vsadc_kwargs
from rwa_monitor.core.vsadc import STATE_NAMES, VsadcDetector
from rwa_monitor.pipelines import Detection
from rwa_monitor.telemetry import Telemetry

SCHEMA = VSADC
NODE = VSADC.name
DEFAULTS: dict[str, Any] = {name: VSADC[name].default for name in VSADC.names(('all',))}


class LabelSeries(NamedTuple):
    """The state of each axis after each row (n, axes), the events and the detector."""

    labels: np.ndarray
    events: list[AnomalyEvent]
    detector: VsadcDetector


def applies(tele: Telemetry) -> bool:
    """Return True if the record has gyro and star-tracker columns."""
    return tele.gyro is not None and tele.attitude is not None


def detector_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """Return VsadcDetector keywords from a parameter block (ConfigError names a bad one)."""
    return vsadc_kwargs(VSADC.validate(config))


def reference_of(config: Mapping[str, Any]) -> np.ndarray:
    """Return the constant reference rate parameter as a checked (3,) array (rad/s)."""
    return np.array(VSADC.validate(config)['reference_rate'], dtype=float)


def label_series(tele: Telemetry, config: Mapping[str, Any]) -> LabelSeries:
    """Run the streaming detector over the rows; return labels, events and the detector.

    Labels are the state after each row (held on rows the detector could not use).
    """
    det = VsadcDetector(**detector_kwargs(config))
    ref = tele.reference_rate
    if ref is None:
        ref = np.broadcast_to(reference_of(config), (len(tele), 3))
    time, gyro, quat = tele.time.tolist(), tele.gyro.tolist(), tele.attitude.tolist()
    ref_rows = ref.tolist()
    labels = np.zeros((len(tele), len(det.axes)), dtype=np.int8)
    events: list[AnomalyEvent] = []
    state = [0] * len(det.axes)
    for k in range(len(time)):
        found = det.update(time[k], gyro[k], quat[k], ref_rows[k], k)
        if found:
            events.extend(found)
            state = [ch.state for ch in det.channels]
        labels[k] = state
    return LabelSeries(labels, events, det)


def run_with_summary(tele: Telemetry, config: Mapping[str, Any]) -> Detection:
    """Run VSADC on the three axes; return the events and a per-axis summary."""
    start = _time.perf_counter()
    labels, events, det = label_series(tele, config)
    summary: dict[str, Any] = {}
    runtime = _time.perf_counter() - start
    for i, axis in enumerate(det.axes):
        summary[f'gyro_{axis}'] = {
            'events': sum(e.component == f'gyro_{axis}' for e in events),
            'final_state': STATE_NAMES[int(labels[-1, i])] if len(tele) else STATE_NAMES[0],
            'ready': det.channels[i].ready}
    summary['counters'] = det.counters
    summary['runtime_s'] = runtime
    return Detection(events, summary)


def run(tele: Telemetry, config: Mapping[str, Any]) -> list[AnomalyEvent]:
    """Run VSADC on the three axes; return the events (DESIGN.md events contract)."""
    return run_with_summary(tele, config).events
