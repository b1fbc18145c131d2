"""The fleet's ``report.html``: one self-contained page (docs/fleet.md, "Report").

A fleet table (spacecraft x wheel: health, events, dry and viscous trend with p-value and
projected crossing of the limit) and, per wheel, a plot of its pass levels over time
with standard errors, the trend line and the events marked. Plots are matplotlib PNGs
embedded as base64 ``data:`` URIs: the page loads nothing from anywhere (no scripts, no
style sheets, no links out).
"""

from __future__ import annotations

import base64
from collections import defaultdict
import html
import io
import math
import os
from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.core.trend import SECONDS_PER_DAY, wheel_trend
from rwa_monitor.telemetry.atomic import write_text_atomic

LEVELS = ('dry', 'viscous')
UNITS = {'dry': 'N m', 'viscous': 'N m s/rad'}
# A trend is flagged in the health column when its p-value is below this (two-sided; with
# 2 tests per wheel and 400 wheels, 0.8 false flags per fleet run with no wear at all).
TREND_LEVEL = 1.0e-3
STYLE = '''body{font-family:sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;font-size:0.9em}th,td{border:1px solid #bbb;padding:3px 6px}
th{background:#eee}td.num{text-align:right;font-family:monospace}
.events{background:#f6d5d5}.trend{background:#fbeecb}.ok{background:#dcefdc}
.absent{background:#e4e4e4}img{max-width:100%}'''


def wheel_trends(trend_rows: Sequence[Mapping[str, Any]],
                 limits: Mapping[str, float] | None = None) -> list[dict[str, Any]]:
    """Return one row per spacecraft and wheel: the trend of its dry and viscous levels.

    Each pass's level is placed at its mid time ``(t_start + t_end) / 2``; the trend is
    :func:`rwa_monitor.core.trend.wheel_trend`; ``limits`` (``dry``/``viscous``, in the
    levels' own reference: ``relative_to`` of the rows) adds the projected crossing. A
    wheel whose passes mix references (a calibration added later) is fitted on the passes
    in the reference of its latest pass only (``passes`` counts them).
    Keys: ``spacecraft``, ``wheel``, ``passes``, ``relative_to`` and per level ``<level>_``
    ``slope_per_day``, ``slope_se``, ``p_value``, ``crossing_s``, ``crossing_low_s``,
    ``crossing_high_s`` (None without a crossing).
    """
    limits = dict(limits or {})
    out = []
    for (craft, wheel), rows in sorted(_by_wheel(trend_rows).items()):
        latest = rows[-1].get('relative_to', '')
        rows = [r for r in rows if r.get('relative_to', '') == latest]
        mid = np.array([0.5 * (_num(r.get('t_start')) + _num(r.get('t_end'))) for r in rows])
        entry: dict[str, Any] = {'spacecraft': craft, 'wheel': wheel, 'passes': len(rows),
                                 'relative_to': latest}
        for level in LEVELS:
            values = np.array([_num(r.get(level)) for r in rows])
            errors = np.array([_num(r.get(f'{level}_se')) for r in rows])
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


def write_report(path: str | os.PathLike, events: list[dict], summary: dict,
                 trend_rows: list[dict], limits: Mapping[str, float] | None = None) -> None:
    """Write the self-contained ``report.html`` at ``path`` (atomically).

    ``events``: the fleet's event dicts (``spacecraft``, ``component``, ``kind``, ``time``);
    ``summary``: summary.json's content (per spacecraft ``components`` and ``not_examined``
    are shown where present); ``trend_rows``: one per spacecraft, wheel and pass (the
    trend.parquet rows); ``limits``: see :func:`wheel_trends` (default: the summary's
    ``trend_limits``, if any).
    """
    if limits is None:
        limits = summary.get('trend_limits') or {}
    trends = wheel_trends(trend_rows, limits)
    by_wheel = _by_wheel(trend_rows)
    wheel_events: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for event in events:
        wheel_events[(str(event.get('spacecraft')), str(event.get('component')))].append(event)
    parts = ['<!DOCTYPE html>', '<html lang="en"><head><meta charset="utf-8">',
             '<title>Fleet friction report</title>', f'<style>{STYLE}</style></head><body>',
             '<h1>Fleet friction report</h1>', _overview(events, summary, trends),
             _table(trends, wheel_events, summary),
             _other_events(wheel_events, {(t['spacecraft'], t['wheel']) for t in trends}),
             '<h2>Wheels</h2>']
    for entry in trends:
        key = (entry['spacecraft'], entry['wheel'])
        png = _plot(key, by_wheel[key], entry, wheel_events.get(key, []))
        parts += [f'<h3 id="{_anchor(key)}">{_e(key[0])} / {_e(key[1])}</h3>',
                  f'<img alt="levels of {_e(key[0])} {_e(key[1])}" '
                  f'src="data:image/png;base64,{png}">']
    parts += ['</body></html>', '']
    write_text_atomic(path, '\n'.join(parts))


def _by_wheel(rows: Sequence[Mapping[str, Any]]) -> dict[tuple[str, str], list]:
    groups: dict[tuple[str, str], list] = defaultdict(list)
    for row in rows:
        groups[(str(row.get('spacecraft')), str(row.get('wheel')))].append(row)
    for group in groups.values():
        group.sort(key=lambda r: _num(r.get('t_start')))
    return dict(groups)


def _num(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _anchor(key: tuple[str, str]) -> str:
    return 'w-' + ''.join(c if c.isalnum() else '_' for c in f'{key[0]}-{key[1]}')


def _overview(events: list[dict], summary: Mapping[str, Any],
              trends: list[dict[str, Any]]) -> str:
    engine = summary.get('engine') or {}
    facts = [f'{len(summary.get("spacecraft") or {}) or len({t["spacecraft"] for t in trends})}'
             f' spacecraft', f'{len(trends)} wheels with pass levels', f'{len(events)} events']
    if 'wall_s' in engine:
        facts.append(f'wall time {_num(engine["wall_s"]):.1f} s')
    if 'workers' in engine:
        facts.append(f'{_e(engine["workers"])} workers')
    lines = [f'<p>{", ".join(facts)}. Trend: weighted least-squares slope of the pass levels '
             f'in time, two-sided t test; flagged below p = {TREND_LEVEL:g}.</p>']
    missing = []
    for craft, block in sorted((summary.get('spacecraft') or {}).items()):
        for what, why in sorted((block.get('not_examined') or {}).items()):
            missing.append(f'<li>{_e(craft)}: {_e(what)}: {_e(why)}</li>')
    if missing:
        lines += ['<h2>Not examined</h2>', '<ul>', *missing, '</ul>']
    return '\n'.join(lines)


def _health(entry: Mapping[str, Any], found: list[dict], reason: str | None) -> tuple[str, str]:
    if found:
        kinds = sorted({str(e.get('kind')) for e in found})
        return 'events', f'events ({", ".join(kinds)})'
    if reason:
        return 'absent', f'not examined: {reason}'
    flagged = [lv for lv in LEVELS if _num(entry[f'{lv}_p_value']) < TREND_LEVEL]
    if flagged:
        return 'trend', f'trend ({", ".join(flagged)})'
    return 'ok', 'ok'


def _table(trends: list[dict[str, Any]], wheel_events: Mapping[tuple[str, str], list],
           summary: Mapping[str, Any]) -> str:
    head = ('<tr><th>spacecraft</th><th>wheel</th><th>health</th><th>events</th>'
            '<th>passes</th><th>relative to</th>'
            + ''.join(f'<th>{lv} slope / day ({UNITS[lv]})</th><th>{lv} p</th>'
                      f'<th>{lv} crossing (day, interval)</th>' for lv in LEVELS) + '</tr>')
    rows = ['<h2>Fleet</h2>', '<table>', head]
    for entry in trends:
        key = (entry['spacecraft'], entry['wheel'])
        block = ((summary.get('spacecraft') or {}).get(key[0]) or {})
        reason = ((block.get('components') or {}).get(key[1]) or {}).get('not_examined')
        found = list(wheel_events.get(key, []))
        css, text = _health(entry, found, reason)
        cells = [f'<a href="#{_anchor(key)}">{_e(key[0])}</a>', _e(key[1]),
                 _e(text), str(len(found)), str(entry['passes']), _e(entry['relative_to'])]
        for lv in LEVELS:
            cells += [f'{_fmt(entry[f"{lv}_slope_per_day"])} &plusmn; '
                      f'{_fmt(entry[f"{lv}_slope_se"])}', _fmt(entry[f'{lv}_p_value']),
                      _crossing(entry, lv)]
        rows.append(f'<tr class="{css}">' + ''.join(
            f'<td class="num">{c}</td>' if i >= 3 else f'<td>{c}</td>'
            for i, c in enumerate(cells)) + '</tr>')
    rows.append('</table>')
    return '\n'.join(rows)


def _other_events(wheel_events: Mapping[tuple[str, str], list],
                  shown: set[tuple[str, str]]) -> str:
    """List the events of components without pass levels (gyro axes, wheels not fitted)."""
    items = [f'<li>{_e(key[0])} {_e(key[1])}: {_e(e.get("detector", ""))} '
             f'{_e(e.get("kind"))} at day {_num(e.get("time")) / SECONDS_PER_DAY:.3f}</li>'
             for key, found in sorted(wheel_events.items()) if key not in shown
             for e in found]
    return '\n'.join(['<h2>Other events</h2>', '<ul>', *items, '</ul>']) if items else ''


def _fmt(value: Any) -> str:
    x = _num(value)
    return '&ndash;' if not math.isfinite(x) else f'{x:.3g}'


def _crossing(entry: Mapping[str, Any], level: str) -> str:
    when = entry.get(f'{level}_crossing_s')
    if when is None:
        return '&ndash;'
    days = [_num(entry[f'{level}_crossing{s}_s']) / SECONDS_PER_DAY
            for s in ('', '_low', '_high')]
    ends = ['&minus;&infin;' if d == -math.inf else '&infin;' if d == math.inf else f'{d:.1f}'
            for d in days[1:]]
    return f'{days[0]:.1f} ({ends[0]} .. {ends[1]})'


def _plot(key: tuple[str, str], rows: list, entry: Mapping[str, Any],
          found: list[dict]) -> str:
    """Return the base64 PNG of one wheel: levels with errors, trend, limit, events."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    mid = np.array([0.5 * (_num(r.get('t_start')) + _num(r.get('t_end'))) for r in rows])
    days = mid / SECONDS_PER_DAY
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
    for ax, level in zip(axes, LEVELS):
        y = np.array([_num(r.get(level)) for r in rows])
        se = np.array([_num(r.get(f'{level}_se')) for r in rows])
        ax.errorbar(days, y, yerr=se, fmt='o', ms=3, color='C0', ecolor='0.6',
                    label='pass level +- 1 s.e.')
        slope, intercept = _num(entry[f'{level}_slope_per_day']), _num(
            entry[f'{level}_intercept'])
        if math.isfinite(slope) and days.size:
            grid = np.array([np.nanmin(days), np.nanmax(days)])
            ax.plot(grid, intercept + slope * grid, 'C1-',
                    label=f'trend, p = {_num(entry[f"{level}_p_value"]):.2g}')
        if entry.get(f'{level}_limit') is not None:
            ax.axhline(entry[f'{level}_limit'], color='C3', ls=':', label='limit')
        for i, event in enumerate(found):
            ax.axvline(_num(event.get('time')) / SECONDS_PER_DAY, color='C3', lw=1,
                       label=f'event ({event.get("kind")})' if i == 0 else None)
        ax.set_xlabel('time (days)')
        ax.set_ylabel(f'{level} ({UNITS[level]}), vs {entry["relative_to"] or "zero"}')
        ax.legend(loc='best', fontsize=7)
    fig.suptitle(f'{key[0]} / {key[1]}', fontsize=10)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format='png', dpi=72)
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode('ascii')
