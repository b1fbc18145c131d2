"""Each wheel's friction trend over its passes, computed once per run for every output.

:func:`wheel_trends` fits core/trend.py's weighted line through a wheel's pass levels
(docs/fleet.md "Trend of a wheel") with a jump at each confirmed step (:func:`trend_steps`);
:func:`add_trends` writes them into summary.json, and report.html draws the same entries
(it does not fit them again).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.trend import wheel_trend
from rwa_monitor.fleet.trend_table import TrendTable

LEVELS = ('dry', 'viscous')
# The kinds of a step in the levels: a confirmed one starts the wheel's trend anew.
STEP_KINDS = frozenset({'dry', 'viscous', 'both'})


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


def number(value: Any) -> float:
    """Return ``value`` as a float, NaN if it is none."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def trend_steps(events: Iterable[tuple[str, AnomalyEvent]]
                ) -> dict[tuple[str, str], tuple[float, ...]]:
    """Return (spacecraft, wheel) -> change times of the wheel's confirmed steps.

    ``events``: (spacecraft, event) of the current (not superseded) events; each change
    counts at its latest revision (fleet/result.py ``latest_kinds``, as the health
    column). A step is a change of a level kind (STEP_KINDS) that the step tests
    confirmed (``kind_shape`` ``step``, ``kind_confirmed``): the levels jump there, and
    one line through both sides would turn the jump into a slope (docs/fleet.md "Trend
    of a wheel"). A ramp (``kind_shape`` ``ramp``) or an unconfirmed kind is no step: a
    wear is a slope, whatever declarations it draws.
    """
    from rwa_monitor.fleet.result import latest_kinds
    by_craft: dict[str, list[AnomalyEvent]] = {}
    for craft, event in events:
        by_craft.setdefault(craft, []).append(event)
    steps: dict[tuple[str, str], set[float]] = {}
    for craft, event in ((c, e) for c, mine in by_craft.items()
                         for e in latest_kinds(mine).values()):
        details = event.details
        confirmed = details.get('kind_confirmed')
        if (event.kind in STEP_KINDS and details.get('kind_shape') == 'step'
                and isinstance(confirmed, (bool, np.bool_)) and confirmed
                and math.isfinite(event.time)):
            steps.setdefault((craft, event.component), set()).add(float(event.time))
    return {key: tuple(sorted(times)) for key, times in steps.items()}


def wheel_trends(trend_rows: TrendTable | Sequence[Mapping[str, Any]],
                 limits: TrendLimits | Mapping[str, float] | None = None,
                 steps: Mapping[tuple[str, str], Sequence[float]] | None = None
                 ) -> list[dict[str, Any]]:
    """Return one row per spacecraft and wheel: the trend of its dry and viscous levels.

    ``trend_rows``: the trend table, or its rows as mappings. Each pass's level is placed
    at its mid time ``(t_start + t_end) / 2``; the trend is
    :func:`rwa_monitor.core.trend.wheel_trend`; ``limits`` (``dry``/``viscous``, in the
    levels' own reference: ``relative_to`` of the rows) adds the projected crossing. A
    wheel whose passes mix references (a calibration added later) is fitted on the passes
    in the reference of its latest pass only (``passes`` counts them). ``steps``
    (:func:`trend_steps`): a wheel's confirmed steps are fitted as jumps between the
    passes that start before and at or after each (``steps_s``, the steps the passes
    separate; ``since_s`` the last of them, from which the line's intercept and crossing
    hold; ``<level>_step_sizes``).
    Keys: ``spacecraft``, ``wheel``, ``passes``, ``relative_to``, ``steps_s``,
    ``since_s`` and per level ``<level>_``
    ``slope_per_day``, ``slope_se``, ``p_value``, ``intercept``, ``step_sizes``,
    ``limit``, ``crossing_s``, ``crossing_low_s``, ``crossing_high_s`` (None without a
    crossing).
    """
    limits = limits.as_dict() if isinstance(limits, TrendLimits) else dict(limits or {})
    out = []
    for (craft, wheel), columns in TrendTable.of(trend_rows).by_wheel().items():
        latest = str(columns['relative_to'][-1])
        mine = columns['relative_to'] == latest
        starts = columns['t_start'][mine]
        mid = 0.5 * (starts + columns['t_end'][mine])
        # A step is placed at the mid time of the first pass that starts at or after it.
        jumps = {when: float(np.min(mid[starts >= when]))
                 for when in (steps or {}).get((craft, wheel), ()) if np.any(starts >= when)}
        entry: dict[str, Any] = {'spacecraft': craft, 'wheel': wheel,
                                 'passes': int(np.count_nonzero(mine)),
                                 'relative_to': latest}
        fitted: tuple[float, ...] = ()
        for level in LEVELS:
            values = columns[level][mine]
            errors = columns[f'{level}_se'][mine]
            trend = wheel_trend(mid, values, errors, limits.get(level), list(jumps.values()))
            fitted = fitted or tuple(w for w, at in jumps.items() if at in trend.step_times)
            crossing = trend.crossing
            entry.update({f'{level}_slope_per_day': trend.slope,
                          f'{level}_step_sizes': list(trend.step_sizes),
                          f'{level}_slope_se': trend.slope_se,
                          f'{level}_p_value': trend.p_value,
                          f'{level}_intercept': trend.intercept,
                          f'{level}_limit': limits.get(level),
                          f'{level}_crossing_s': crossing and crossing.time,
                          f'{level}_crossing_low_s': crossing and crossing.low,
                          f'{level}_crossing_high_s': crossing and crossing.high})
        entry.update({'steps_s': list(fitted), 'since_s': fitted[-1] if fitted else None})
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
    if isinstance(value, list):
        return [_json_number(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value
