"""Gyro drift/bias diagnosis on a file: events per axis from gyro_* and q_* columns.

Parameters are the ``vsadc_detector`` node's block of config/rwa_monitor.yaml, same names
(see :data:`DEFAULTS`); other keys of the block (node-only ones) are ignored.
``feature`` chooses the detector: ``residual`` (default) the gyro-minus-star-tracker
diagnosis of :mod:`rwa_monitor.core.gyro_diagnosis`, which needs no guidance reference;
``paper`` the two residuals of the paper against ``ref_*`` (or the ``reference_rate``
parameter) in :class:`rwa_monitor.core.vsadc.VsadcDetector`. ``calibration_file`` names a
calibration.yaml whose ``gyro:`` block sets the residual thresholds (DESIGN.md).
"""

from __future__ import annotations

import pathlib
import time as _time
from typing import Any, Mapping

import numpy as np
import yaml

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_diagnosis import AXIS_DEFAULTS, DEFAULT_SATURATION_RAD_S, \
    GyroDiagnosis
from rwa_monitor.core.params import check_choice, check_int, check_real
from rwa_monitor.core.vsadc import AXES, STATE_NAMES, VsadcDetector
from rwa_monitor.telemetry import Telemetry

NODE = 'vsadc_detector'
DEFAULTS: dict[str, Any] = {
    'window': 200, 'sigma_window': 200, 'distance_threshold': 1.5e-5,
    'reference_window': 1200, 'margin': 1.5, 'exit_limit': 'max', 'exit_margin': 1.25,
    'hold': 1, 'nominal_tracking': 0, 'freeze_fraction': 0.5, 'adaptive': True,
    'recovery_fraction': 0.75,
    'max_gap': 1.0,
    'norm_tolerance': 0.1, 'reference_rate': [0.0, 0.0, 0.0], 'axes': 'x,y,z',
    'feature': 'residual', 'calibration_file': '',
    'saturation_rad_s': DEFAULT_SATURATION_RAD_S,
    **{f'residual_{k}': v for k, v in AXIS_DEFAULTS.items()},
}
FEATURES = ('residual', 'paper')


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


def load_gyro_calibration(path: str | pathlib.Path) -> dict[str, dict[str, Any]]:
    """Return the ``calibration.gyro`` block (axis -> dict) of a calibration.yaml file.

    ValueError with the file name when it cannot be read or has no gyro block.
    """
    try:
        data = yaml.safe_load(pathlib.Path(path).read_text())
    except OSError as err:
        raise ValueError(f'{path}: cannot read: {err.strerror}') from None
    except yaml.YAMLError as err:
        raise ValueError(f'{path}: not valid YAML: {err}') from None
    block = ((data or {}).get('calibration') or {}).get('gyro') if isinstance(data, dict) \
        else None
    if not isinstance(block, dict) or not block:
        raise ValueError(f'{path}: no calibration.gyro block')
    bad = [a for a in block if a not in AXES or not isinstance(block[a], dict)]
    if bad:
        raise ValueError(f'{path}: calibration.gyro: unknown axis entries {bad}')
    return block


def make_detector(config: Mapping[str, Any],
                  calibration: Mapping[str, Any] | None = None
                  ) -> GyroDiagnosis | VsadcDetector:
    """Return the configured gyro detector (``feature``: residual or paper).

    ``calibration`` (axis -> dict of calibrate_gyro) wins over the ``calibration_file``
    parameter; both apply to the residual feature only.
    """
    p = {**DEFAULTS, **{k: v for k, v in config.items() if k in DEFAULTS}}
    feature = check_choice('feature', p['feature'], FEATURES)
    paper = VsadcDetector(**detector_kwargs(config))    # checks the whole block either way
    if feature == 'paper':
        return paper
    if calibration is None and p['calibration_file']:
        calibration = load_gyro_calibration(p['calibration_file'])
    axes = tuple(a.strip() for a in str(p['axes']).split(',') if a.strip())
    for a in axes:
        check_choice('axes', a, AXES)
    return GyroDiagnosis(
        calibration=calibration,
        saturation_rad_s=check_real('saturation_rad_s', p['saturation_rad_s'], 0.0,
                                    low_open=True),
        max_gap=p['max_gap'], norm_tolerance=p['norm_tolerance'], axes=axes,
        **{k: p[f'residual_{k}'] for k in AXIS_DEFAULTS})


def reference_of(config: Mapping[str, Any]) -> np.ndarray:
    """Return the constant reference rate parameter as a checked (3,) array (rad/s)."""
    ref = config.get('reference_rate', DEFAULTS['reference_rate'])
    if not isinstance(ref, (list, tuple)) or len(ref) != 3:
        raise ValueError(f'reference_rate must be 3 numbers (rad/s), got {ref!r}')
    return np.array([check_real('reference_rate', v) for v in ref])


def label_series(tele: Telemetry, config: Mapping[str, Any],
                 calibration: Mapping[str, Any] | None = None
                 ) -> tuple[np.ndarray, list[AnomalyEvent], GyroDiagnosis | VsadcDetector]:
    """Run the streaming detector over the rows; return (labels (n, axes), events, detector).

    Labels are the state after each row (held on rows the detector could not use).
    """
    det = make_detector(config, calibration)
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


def run_with_summary(tele: Telemetry, config: Mapping[str, Any],
                     calibration: Mapping[str, Any] | None = None
                     ) -> tuple[list[AnomalyEvent], dict[str, Any]]:
    """Run the gyro diagnosis on the three axes; return (events, per-axis summary)."""
    start = _time.perf_counter()
    labels, events, det = label_series(tele, config, calibration)
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


def run(tele: Telemetry, config: Mapping[str, Any],
        calibration: Mapping[str, Any] | None = None) -> list[AnomalyEvent]:
    """Run the gyro diagnosis on the three axes; return the events (DESIGN.md contract)."""
    return run_with_summary(tele, config, calibration)[0]
