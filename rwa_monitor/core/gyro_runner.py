"""The runner of the gyro: what detect, the node, the demo and the fleet call.

The gyro diagnosis (the gyro-minus-star-tracker residual by default, the paper's VSADC
features with ``feature: paper``; core/gyro_diagnosis.py) takes one gyro row at a time
with the star-tracker quaternion of the same instant and the guidance reference rate in
force. The rules every entry point used to repeat live here once:

- pairing (:func:`pair_rows`): in a multi-rate record each stream keeps its own stamps; a
  gyro sample is paired with the closest star-tracker sample within ``pair_tolerance``
  s (None if there is none: the diagnosis then holds the axes), and with the last
  reference-rate sample stamped at or before the gyro stamp plus the tolerance; before
  the first one, the last one of an earlier call, else the ``reference_rate`` parameter.
  A single-rate record (a CSV file) pairs row with row. The node pairs live with the
  same tolerance (core/streams.py StampPairer);
- row numbers: events count the gyro rows fed, across calls;
- facts: per axis the coverage verdict (:func:`axis_coverage`) and the final state;
- state: :meth:`GyroRunner.state` / :meth:`GyroRunner.restore` (typed records).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from rwa_monitor.core.coverage import Coverage, judge, NOT_EXAMINED
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_diagnosis import make_gyro_detector
from rwa_monitor.core.gyro_state import GyroDiagnosisState, VsadcState
from rwa_monitor.core.records import RecordError
from rwa_monitor.core.runner_facts import ComponentFacts
from rwa_monitor.core.schema import VSADC
from rwa_monitor.core.vsadc import STATE_NAMES

FAMILY = 'vsadc'
COMPONENT = 'gyro'
UNKNOWN = 'unknown'


@dataclass(frozen=True)
class GyroColumns:
    """A record's gyro, star-tracker and reference-rate channels on one time base.

    ``present`` maps a stream (``gyro``, ``star_tracker``, ``reference_rate``) to the rows
    where it has a sample; a stream without an entry has one on every row.
    """

    time: np.ndarray
    gyro: np.ndarray
    attitude: np.ndarray | None = None
    reference_rate: np.ndarray | None = None
    present: Mapping[str, np.ndarray] = field(default_factory=dict)

    def rows(self, stream: str) -> np.ndarray:
        """Return the indices of the rows where ``stream`` has a sample."""
        mask = self.present.get(stream)
        return np.arange(len(self.time)) if mask is None else np.flatnonzero(mask)


def pair_rows(cols: GyroColumns, reference: Sequence[float], tolerance_s: float
              ) -> tuple[list[int], list[Sequence[float] | None], list[Sequence[float]]]:
    """Return (gyro rows, quaternion or None per row, reference rate per row).

    ``reference``: the rate before the record's first reference-rate sample (3 floats).
    """
    gyro_rows = cols.rows('gyro')
    time = cols.time
    fixed = [float(v) for v in reference]
    if cols.attitude is None:
        quats: list[Sequence[float] | None] = [None] * len(gyro_rows)
    elif 'gyro' not in cols.present and 'star_tracker' not in cols.present:
        attitude = cols.attitude.tolist()
        quats = [attitude[k] for k in gyro_rows.tolist()]
    else:
        attitude = cols.attitude.tolist()
        star_rows = cols.rows('star_tracker')
        star_time = time[star_rows]
        quats = []
        for k in gyro_rows.tolist():
            j = int(np.searchsorted(star_time, time[k]))
            near = [i for i in (j - 1, j) if 0 <= i < len(star_time)
                    and abs(star_time[i] - time[k]) <= tolerance_s]
            best = min(near, key=lambda i: abs(star_time[i] - time[k]), default=None)
            quats.append(None if best is None else attitude[star_rows[best]])
    ref_mask = cols.present.get('reference_rate')
    if cols.reference_rate is None:
        refs = [fixed] * len(gyro_rows)
    elif ref_mask is None:
        refs = cols.reference_rate[gyro_rows].tolist()
    else:
        ref_rows = np.flatnonzero(ref_mask)
        ref_values = cols.reference_rate.tolist()
        at = np.searchsorted(time[ref_rows], time[gyro_rows] + tolerance_s, side='right') - 1
        refs = [ref_values[ref_rows[a]] if a >= 0 else fixed for a in at.tolist()]
    return gyro_rows.tolist(), quats, refs


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


@dataclass(frozen=True)
class GyroRunnerState:
    """A gyro runner's state: the detector's record, rows fed, the reference in force."""

    VERSION: ClassVar[int] = 1
    feature: str
    residual: GyroDiagnosisState | None
    paper: VsadcState | None
    rows: int
    last_reference: tuple[float, float, float] | None


class GyroRunner:
    """The gyro diagnosis of three axes with its pairing, row numbers and verdicts.

    Parameters
    ----------
    values : mapping
        Checked parameters of the ``vsadc_detector`` block (core/schema.py VSADC).
    calibration : mapping or None
        The gyro block of a commissioning calibration (axis -> thresholds), for the
        residual feature.
    """

    def __init__(self, values: Mapping[str, Any],
                 calibration: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        self._detector = make_gyro_detector(values, calibration)
        self.feature = str(values['feature'])
        # Node-level parameters: a node pairs live (core/streams.py), with its own values.
        self._tolerance = float(values.get('pair_tolerance', VSADC['pair_tolerance'].default))
        self._fixed = tuple(float(v) for v in values.get('reference_rate',
                                                         VSADC['reference_rate'].default))
        self._last_ref: tuple[float, float, float] | None = None
        self._rows = 0

    @property
    def detector(self) -> Any:
        """Return the gyro detector, to read its channels; feed it through the runner."""
        return self._detector

    @property
    def rows(self) -> int:
        """Gyro rows fed so far (the next event's row number)."""
        return self._rows

    def feed(self, cols: GyroColumns, labels: np.ndarray | None = None
             ) -> list[AnomalyEvent]:
        """Give a record's rows (after the last ones fed); return the events.

        ``labels``: if given, an int array (rows, axes) filled with each axis's state after
        each row (held on rows without a gyro sample).
        """
        reference = self._last_ref if self._last_ref is not None else self._fixed
        rows, quats, refs = pair_rows(cols, reference, self._tolerance)
        time, gyro = cols.time.tolist(), cols.gyro.tolist()
        events: list[AnomalyEvent] = []
        state = [ch.state for ch in self._detector.channels]
        last = 0
        for k, q, ref in zip(rows, quats, refs):
            if labels is not None:
                labels[last:k] = state
            found = self._detector.update(time[k], gyro[k], q, ref, self._rows)
            self._rows += 1
            if found:
                events.extend(found)
                state = [ch.state for ch in self._detector.channels]
            if labels is not None:
                labels[k] = state
                last = k + 1
        if labels is not None:
            labels[last:] = state
        if cols.reference_rate is not None:
            present = cols.rows('reference_rate')
            if len(present):
                self._last_ref = tuple(float(v) for v in cols.reference_rate[present[-1]])
        return events

    def update(self, t: float, gyro: Sequence[float], q: Sequence[float] | None,
               ref: Sequence[float] | None = None) -> list[AnomalyEvent]:
        """Give one paired row (a node's call); return the events."""
        index = self._rows
        self._rows += 1
        return self._detector.update(t, gyro, q, ref, index)

    def finish(self) -> list[AnomalyEvent]:
        """End of record: the gyro diagnosis holds nothing open (no events)."""
        return []

    def facts(self) -> ComponentFacts:
        """Return the gyro's counters and, per axis, the verdict and the final state."""
        det = self._detector
        counters = det.counters
        offered = rows_offered(counters)
        parts = []
        for axis, channel in zip(det.axes, det.channels):
            verdict = axis_coverage(offered, channel)
            state = STATE_NAMES[channel.state] if verdict.examined else UNKNOWN
            parts.append(ComponentFacts(
                f'gyro_{axis}', FAMILY, offered, {}, {}, verdict,
                {'final_state': state, 'ready': bool(channel.ready),
                 'samples_used': int(channel.samples)}))
        return ComponentFacts(COMPONENT, FAMILY, int(counters['rows']), counters,
                              parts=tuple(parts))

    def state(self) -> GyroRunnerState:
        """Return the runner's state as a typed record (a copy)."""
        record = self._detector.state()
        paper = self.feature == 'paper'
        return GyroRunnerState(self.feature, None if paper else record,
                               record if paper else None, self._rows, self._last_ref)

    def restore(self, state: GyroRunnerState) -> None:
        """Resume from ``state`` (made by a runner with the same parameters and calibration).

        Raise RecordError naming what differs; the runner is then unchanged.
        """
        record = state.paper if self.feature == 'paper' else state.residual
        other = state.residual if self.feature == 'paper' else state.paper
        if state.feature != self.feature or record is None or other is not None:
            raise RecordError(f'gyro state of feature {state.feature!r} given to a runner '
                              f'of feature {self.feature!r}')
        if state.rows < 0:
            raise RecordError(f'gyro state: rows {state.rows} < 0')
        self._detector.restore(record)
        self._rows = state.rows
        self._last_ref = state.last_reference
