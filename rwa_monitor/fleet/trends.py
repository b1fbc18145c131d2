"""Each wheel's friction trend over its passes, computed once per run for every output.

:func:`wheel_trends` fits core/trend.py's weighted line through a wheel's pass levels
(docs/fleet.md "Trend of a wheel"); :func:`add_trends` writes them into summary.json, and
report.html draws the same entries (it does not fit them again).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
import math
from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.core.trend import wheel_trend

LEVELS = ('dry', 'viscous')


@dataclass(frozen=True)
class TrendLimits:
    """The limits whose projected crossing the trend reports (None: no limit).

    In the levels' own reference: an absolute level without a calibration, the rise
    against the nominal with one (docs/fleet.md).
    """

    dry: float | None = None
    viscous: float | None = None

    def as_dict(self) -> dict[str, float]:
        """Return the limits that are set, by level."""
        return {level: value for level, value in (('dry', self.dry),
                                                  ('viscous', self.viscous))
                if value is not None}


def trend_limits(fleet_block: Mapping[str, object]) -> TrendLimits:
    """Return the limits of the fleet block (``dry_limit``, ``viscous_limit``; 0 = none)."""
    def limit(level: str) -> float | None:
        value = float(fleet_block[f'{level}_limit'])
        return value if value > 0.0 else None
    return TrendLimits(limit('dry'), limit('viscous'))


def by_wheel(rows: Sequence[Mapping[str, Any]]) -> dict[tuple[str, str], list]:
    """Return the trend rows per (spacecraft, wheel), each group in time order."""
    groups: dict[tuple[str, str], list] = defaultdict(list)
    for row in rows:
        groups[(str(row.get('spacecraft')), str(row.get('wheel')))].append(row)
    for group in groups.values():
        group.sort(key=lambda r: number(r.get('t_start')))
    return dict(groups)


def number(value: Any) -> float:
    """Return ``value`` as a float, NaN if it is none."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def wheel_trends(trend_rows: Sequence[Mapping[str, Any]],
                 limits: TrendLimits | Mapping[str, float] | None = None
                 ) -> list[dict[str, Any]]:
    """Return one row per spacecraft and wheel: the trend of its dry and viscous levels.

    Each pass's level is placed at its mid time ``(t_start + t_end) / 2``; the trend is
    :func:`rwa_monitor.core.trend.wheel_trend`; ``limits`` (``dry``/``viscous``, in the
    levels' own reference: ``relative_to`` of the rows) adds the projected crossing. A
    wheel whose passes mix references (a calibration added later) is fitted on the passes
    in the reference of its latest pass only (``passes`` counts them).
    Keys: ``spacecraft``, ``wheel``, ``passes``, ``relative_to`` and per level ``<level>_``
    ``slope_per_day``, ``slope_se``, ``p_value``, ``intercept``, ``limit``,
    ``crossing_s``, ``crossing_low_s``, ``crossing_high_s`` (None without a crossing).
    """
    limits = limits.as_dict() if isinstance(limits, TrendLimits) else dict(limits or {})
    out = []
    for (craft, wheel), rows in sorted(by_wheel(trend_rows).items()):
        latest = rows[-1].get('relative_to', '')
        rows = [r for r in rows if r.get('relative_to', '') == latest]
        mid = np.array([0.5 * (number(r.get('t_start')) + number(r.get('t_end')))
                        for r in rows])
        entry: dict[str, Any] = {'spacecraft': craft, 'wheel': wheel, 'passes': len(rows),
                                 'relative_to': latest}
        for level in LEVELS:
            values = np.array([number(r.get(level)) for r in rows])
            errors = np.array([number(r.get(f'{level}_se')) for r in rows])
            trend = wheel_trend(mid, values, errors, limits.get(level))
            crossing = trend.crossing
            entry.update({f'{level}_slope_per_day': trend.slope,
                          f'{level}_slope_se': trend.slope_se,
                          f'{level}_p_value': trend.p_value,
                          f'{level}_intercept': trend.intercept,
                          f'{level}_limit': limits.get(level),
                          f'{level}_crossing_s': crossing and crossing.time,
                          f'{level}_crossing_low_s': crossing and crossing.low,
                          f'{level}_crossing_high_s': crossing and crossing.high})
        out.append(entry)
    return out


def add_trends(summary: dict[str, Any], trends: Sequence[Mapping[str, Any]],
               limits: Mapping[str, float]) -> None:
    """Write each wheel's trend into its summary entry (``summary['trend_limits']`` too).

    Per spacecraft and wheel ``trend``: passes, reference and per level the slope per day,
    its standard error, p-value, the limit and the projected crossing with its interval
    (telemetry time in s; null where a number is not defined, and for an end of the
    interval the data cannot bound).
    """
    summary['trend_limits'] = limits.as_dict()
    for entry in trends:
        craft = summary['spacecraft'].get(entry['spacecraft'])
        wheel = craft and craft['components'].get(entry['wheel'])
        if wheel is None:
            continue
        wheel['trend'] = {k: _json_number(v) for k, v in entry.items()
                          if k not in ('spacecraft', 'wheel')}


def _json_number(value: Any) -> Any:
    """Return ``value`` with a non-finite float as None (JSON has no NaN or infinity)."""
    return None if isinstance(value, float) and not math.isfinite(value) else value
