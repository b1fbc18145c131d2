"""VSADC on a file: gyro drift/bias events per axis from gyro_*, q_* and ref_* columns.

Parameters are the ``vsadc_detector`` block of core/schema.py (VSADC), the node's names;
node-only ones are accepted and ignored, unknown ones refused. ``feature`` chooses the
detector (:func:`rwa_monitor.core.gyro_diagnosis.make_gyro_detector`): ``residual``
(default) the gyro-minus-star-tracker diagnosis, which needs no guidance reference, with
the thresholds of the ``calibration_file`` gyro block; ``paper`` the two residuals of the
paper; a file without ``ref_*`` columns then uses the ``reference_rate`` parameter.
"""

from __future__ import annotations

import time as _time
from typing import Any, Mapping, NamedTuple

import numpy as np

from rwa_monitor.core.coverage import Coverage, judge, NOT_EXAMINED
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_diagnosis import make_gyro_detector
from rwa_monitor.core.schema import VSADC, vsadc_kwargs
from rwa_monitor.core.vsadc import STATE_NAMES
from rwa_monitor.pipelines import Detection
from rwa_monitor.telemetry import Telemetry
from rwa_monitor.telemetry.calibration_file import load_gyro_calibration
from rwa_monitor.telemetry.streams import paired_gyro

SCHEMA = VSADC
NODE = VSADC.name
UNKNOWN = 'unknown'
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
    values = VSADC.validate(config)
    if calibration is None and values['calibration_file']:
        calibration = load_gyro_calibration(values['calibration_file'])
    return make_gyro_detector(values, calibration)


def reference_of(config: Mapping[str, Any]) -> np.ndarray:
    """Return the constant reference rate parameter as a checked (3,) array (rad/s)."""
    return np.array(VSADC.validate(config)['reference_rate'], dtype=float)


def label_series(tele: Telemetry, config: Mapping[str, Any],
                 calibration: Mapping[str, Any] | None = None) -> LabelSeries:
    """Run the streaming detector over the rows; return labels, events and the detector.

    Labels are the state after each row (held on rows the detector could not use, and on
    rows without a gyro sample in a multi-rate record). Event indices count gyro samples.
    """
    det = make_detector(config, calibration)
    tolerance = VSADC['pair_tolerance'].default  # the node's pairing rule (multi-rate)
    rows, quat, ref_rows = paired_gyro(tele, reference_of(config),
                                       float(config.get('pair_tolerance', tolerance)))
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
    return LabelSeries(labels, events, det)


def run_with_summary(tele: Telemetry, config: Mapping[str, Any],
                     calibration: Mapping[str, Any] | None = None) -> Detection:
    """Run the gyro diagnosis on the three axes; return the events and a per-axis summary.

    A bad value of one gyro axis is rejected on that axis only (``bad_axis_<a>``
    counters); ``final_state`` is ``unknown`` for an axis that was not examined (never
    ready, or most of its samples rejected: :func:`axis_coverage`), whose ``verdict`` says
    which, with the counts.
    """
    start = _time.perf_counter()
    labels, events, det = label_series(tele, config, calibration)
    summary: dict[str, Any] = {}
    runtime = _time.perf_counter() - start
    for i, axis in enumerate(det.axes):
        channel = det.channels[i]
        verdict = axis_coverage(rows_offered(det.counters), channel)
        # An axis that never became ready, or whose samples were mostly rejected, was not
        # examined: its state is unknown, never "healthy" (issues 17, 24).
        state = STATE_NAMES[int(labels[-1, i])] if verdict.examined else UNKNOWN
        summary[f'gyro_{axis}'] = {
            'events': sum(e.component == f'gyro_{axis}' for e in events),
            'final_state': state, 'ready': channel.ready,
            'samples_used': channel.samples, **verdict.fields()}
    summary['counters'] = det.counters
    summary['runtime_s'] = runtime
    return Detection(events, summary)


def samples_needed(channel: Any) -> int:
    """Return the usable samples an axis needs before its first verdict.

    The residual feature learns its nominal class from ``nominal_blocks`` blocks of
    ``block`` samples; the paper's features from the two windows and the sigma window,
    then ``reference_window`` sigmas (docs/vsadc.md).
    """
    if hasattr(channel, 'nominal_blocks'):
        return int(channel.block * channel.nominal_blocks)
    return int(2 * channel.window + channel.sigma_window + channel.reference_window - 1)


def rows_offered(counters: Mapping[str, int]) -> int:
    """Return the gyro rows offered to each axis (see :func:`axis_coverage`)."""
    return counters['rows'] - counters['held'] + counters['invalid_quaternions']


def axis_coverage(rows: int, channel: Any) -> Coverage:
    """Return the verdict of one axis: ``rows`` offered, the channel's samples used.

    Rows offered: every gyro row but those held for want of a star-tracker sample to pair
    with (in a multi-rate record most gyro rows are, by design); a row held because its
    quaternion was invalid is offered and unusable. An axis that never became ready is
    not examined whatever its count.
    """
    verdict = judge(rows, channel.samples, samples_needed(channel), 'the gyro diagnosis')
    if not channel.ready and verdict.verdict != NOT_EXAMINED:
        verdict = verdict._replace(
            verdict=NOT_EXAMINED, reason=f'never ready: {channel.samples} usable samples '
                                         f'of {rows} did not learn the nominal class')
    return verdict


def run(tele: Telemetry, config: Mapping[str, Any],
        calibration: Mapping[str, Any] | None = None) -> list[AnomalyEvent]:
    """Run the gyro diagnosis on the three axes; return the events (DESIGN.md contract)."""
    return run_with_summary(tele, config, calibration).events
