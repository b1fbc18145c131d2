"""VSADC on a file: gyro drift/bias events per axis from gyro_*, q_* and ref_* columns.

Parameters are the ``vsadc_detector`` node's block of config/rwa_monitor.yaml, same names
(see :data:`DEFAULTS`); other keys of the block (node-only ones) are ignored. A file
without ``ref_*`` columns uses the ``reference_rate`` parameter (rad/s, 3 values).
"""

from __future__ import annotations

import time as _time
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.params import check_choice, check_int, check_real
from rwa_monitor.core.vsadc import AXES, STATE_NAMES, VsadcDetector
from rwa_monitor.telemetry import Telemetry
from rwa_monitor.telemetry.streams import paired_gyro

NODE = 'vsadc_detector'
DEFAULTS: dict[str, Any] = {
    'window': 200, 'sigma_window': 200, 'distance_threshold': 1.5e-5,
    'reference_window': 1200, 'margin': 1.5, 'exit_limit': 'max', 'exit_margin': 1.25,
    'hold': 1, 'nominal_tracking': 0, 'freeze_fraction': 0.5, 'adaptive': True,
    'recovery_fraction': 0.75,
    'max_gap': 1.0,
    'norm_tolerance': 0.1, 'reference_rate': [0.0, 0.0, 0.0], 'axes': 'x,y,z',
}
# Seconds within which gyro and star-tracker stamps are one sample (multi-rate recordings;
# the node's pair_tolerance parameter).
PAIR_TOLERANCE = 1.0e-3


def applies(tele: Telemetry) -> bool:
    """Return True if the record has gyro and star-tracker columns."""
    return tele.gyro is not None and tele.attitude is not None


def detector_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """Return VsadcDetector keywords from a parameter block (ValueError names a bad one)."""
    p = {**DEFAULTS, **{k: v for k, v in config.items() if k in DEFAULTS}}
    axes = tuple(a.strip() for a in str(p['axes']).split(',') if a.strip())
    for a in axes:
        check_choice('axes', a, AXES)
    return dict(
        window=check_int('window', p['window'], 2),
        sigma_window=check_int('sigma_window', p['sigma_window'], 0) or None,
        distance_threshold=check_real('distance_threshold', p['distance_threshold'], 0.0,
                                      low_open=True),
        reference_window=check_int('reference_window', p['reference_window'], 0) or None,
        margin=p['margin'], exit_limit=p['exit_limit'], exit_margin=p['exit_margin'],
        hold=p['hold'], nominal_tracking=p['nominal_tracking'],
        freeze_fraction=p['freeze_fraction'], adaptive=p['adaptive'],
        recovery_fraction=p['recovery_fraction'], max_gap=p['max_gap'],
        norm_tolerance=p['norm_tolerance'], axes=axes)


def reference_of(config: Mapping[str, Any]) -> np.ndarray:
    """Return the constant reference rate parameter as a checked (3,) array (rad/s)."""
    ref = config.get('reference_rate', DEFAULTS['reference_rate'])
    if not isinstance(ref, (list, tuple)) or len(ref) != 3:
        raise ValueError(f'reference_rate must be 3 numbers (rad/s), got {ref!r}')
    return np.array([check_real('reference_rate', v) for v in ref])


def label_series(tele: Telemetry, config: Mapping[str, Any]
                 ) -> tuple[np.ndarray, list[AnomalyEvent], VsadcDetector]:
    """Run the streaming detector over the rows; return (labels (n, axes), events, detector).

    Labels are the state after each row (held on rows the detector could not use, and on
    rows without a gyro sample in a multi-rate record). Event indices count gyro samples.
    """
    det = VsadcDetector(**detector_kwargs(config))
    rows, quat, ref_rows = paired_gyro(tele, reference_of(config), check_real(
        'pair_tolerance', config.get('pair_tolerance', PAIR_TOLERANCE), 0.0))
    time, gyro = tele.time.tolist(), tele.gyro.tolist()
    labels = np.zeros((len(tele), len(det.axes)), dtype=np.int8)
    events: list[AnomalyEvent] = []
    state = [0] * len(det.axes)
    last = 0
    for index, (k, q, ref) in enumerate(zip(rows, quat, ref_rows)):
        labels[last:k] = state
        found = det.update(time[k], gyro[k], q, ref, index)
        if found:
            events.extend(found)
            state = [ch.state for ch in det.channels]
        labels[k] = state
        last = k + 1
    labels[last:] = state
    return labels, events, det


def run_with_summary(tele: Telemetry, config: Mapping[str, Any]
                     ) -> tuple[list[AnomalyEvent], dict[str, Any]]:
    """Run VSADC on the three axes; return (events, per-axis summary with counters)."""
    start = _time.perf_counter()
    labels, events, det = label_series(tele, config)
    summary: dict[str, Any] = {}
    runtime = _time.perf_counter() - start
    for i, axis in enumerate(det.axes):
        summary[f'gyro_{axis}'] = {
            'events': sum(e.component == f'gyro_{axis}' for e in events),
            'final_state': STATE_NAMES[int(labels[-1, i])] if len(tele) else STATE_NAMES[0],
            'ready': det.channels[i].ready}
    summary['counters'] = det.counters()
    summary['runtime_s'] = runtime
    return events, summary


def run(tele: Telemetry, config: Mapping[str, Any]) -> list[AnomalyEvent]:
    """Run VSADC on the three axes; return the events (DESIGN.md events contract)."""
    return run_with_summary(tele, config)[0]
