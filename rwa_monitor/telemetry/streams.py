"""Streams of a multi-rate record paired by stamp (docs/contracts.md, multi-rate).

A CSV row holds every channel at one time; a recording keeps each sensor's own stamps
(``Telemetry.present``). VSADC needs a gyro sample with the star-tracker quaternion of
the same instant and the guidance reference rate in force then: this module pairs them
with the node's rules (nodes/vsadc_detector.py), so the file path and the node feed the
detector the same samples.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rwa_monitor.telemetry.schema import Telemetry


def paired_gyro(tele: Telemetry, reference: np.ndarray, tolerance_s: float
                ) -> tuple[list[int], list[Sequence[float] | None], list[Sequence[float]]]:
    """Return (gyro rows, quaternion or None per row, reference rate per row).

    A gyro sample is paired with the star-tracker sample whose stamp is within
    ``tolerance_s`` (the closest one; None if there is none: VSADC then propagates the
    gyro alone, as the node does with an unpaired gyro sample). The reference rate is the
    last ``reference_rate`` sample stamped at or before the gyro stamp plus
    ``tolerance_s``; before the first one, ``reference`` (the constant parameter, (3,)).
    A single-rate record (a CSV file) pairs row with row, as before.
    """
    gyro_rows = tele.rows('gyro')
    star_rows = tele.rows('star_tracker')
    ref_mask = tele.present.get('reference_rate')
    time = tele.time
    attitude = tele.attitude.tolist()
    if 'gyro' not in tele.present and 'star_tracker' not in tele.present:
        quats: list[Sequence[float] | None] = [attitude[k] for k in gyro_rows.tolist()]
    else:
        star_time = time[star_rows]
        quats = []
        for k in gyro_rows.tolist():
            j = int(np.searchsorted(star_time, time[k]))
            near = [i for i in (j - 1, j) if 0 <= i < len(star_time)
                    and abs(star_time[i] - time[k]) <= tolerance_s]
            best = min(near, key=lambda i: abs(star_time[i] - time[k]), default=None)
            quats.append(None if best is None else attitude[star_rows[best]])
    if tele.reference_rate is None:
        refs = [list(map(float, reference))] * len(gyro_rows)
    elif ref_mask is None:
        refs = tele.reference_rate[gyro_rows].tolist()
    else:
        ref_rows = np.flatnonzero(ref_mask)
        ref_values = tele.reference_rate.tolist()
        at = np.searchsorted(time[ref_rows], time[gyro_rows] + tolerance_s, side='right') - 1
        fixed = list(map(float, reference))
        refs = [ref_values[ref_rows[a]] if a >= 0 else fixed for a in at.tolist()]
    return gyro_rows.tolist(), quats, refs
