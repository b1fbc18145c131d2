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

NODE = 'vsadc_detector'
UNKNOWN = 'unknown'
DEFAULTS: dict[str, Any] = {
    'window': 200, 'sigma_window': 200, 'distance_threshold': 1.5e-5,
    'reference_window': 1200, 'margin': 1.5, 'exit_limit': 'max', 'exit_margin': 1.25,
    'hold': 1, 'nominal_tracking': 0, 'freeze_fraction': 0.5, 'adaptive': True,
    'recovery_fraction': 0.75,
    'max_gap': 1.0,
    'norm_tolerance': 0.1, 'reference_rate': [0.0, 0.0, 0.0], 'axes': 'x,y,z',
}


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
    return labels, events, det


def run_with_summary(tele: Telemetry, config: Mapping[str, Any]
                     ) -> tuple[list[AnomalyEvent], dict[str, Any]]:
    """Run VSADC on the three axes; return (events, per-axis summary with counters).

    A bad value of one gyro axis is rejected on that axis only (``bad_axis_<a>``
    counters); ``final_state`` is ``unknown`` for an axis that never became ready.
    """
    start = _time.perf_counter()
    labels, events, det = label_series(tele, config)
    summary: dict[str, Any] = {}
    runtime = _time.perf_counter() - start
    for i, axis in enumerate(det.axes):
        ready = det.channels[i].ready
        # An axis that never became ready was not examined: its state is unknown, never
        # "healthy" (issue 17).
        state = STATE_NAMES[int(labels[-1, i])] if ready and len(tele) else UNKNOWN
        summary[f'gyro_{axis}'] = {
            'events': sum(e.component == f'gyro_{axis}' for e in events),
            'final_state': state, 'ready': ready,
            'samples_used': det.channels[i].samples}
    summary['counters'] = det.counters()
    summary['runtime_s'] = runtime
    return events, summary


def run(tele: Telemetry, config: Mapping[str, Any]) -> list[AnomalyEvent]:
    """Run VSADC on the three axes; return the events (DESIGN.md events contract)."""
    return run_with_summary(tele, config)[0]
