"""The fleet's ``report.html``: one self-contained page (docs/fleet.md, "Report").

What an operator reads first: the data span and when the run was made; what was not
examined; a fleet table (spacecraft x wheel: the current verdict, changes, the dry and
viscous trend with p-value and projected crossing of the limit); the event table (one row
per change at its latest revision: kind, change and declaration times in UTC where the
archive has an epoch, size, p-value, final, new in this run); and per wheel a plot of its
pass levels over time with standard errors, the trend line and its changes drawn with
their kind, for the wheels that need a look (:func:`needs_plot`: a change, a trend flag, a
projected limit crossing or no verdict; a fleet of hundreds of healthy wheels would
otherwise be hundreds of flat plots, and their drawing the run's largest fixed cost).
Plots are SVG figures (fleet/svg_plot.py: vector, drawn in milliseconds) embedded as
base64 ``data:`` URIs: the page loads nothing from anywhere (no scripts, no style sheets,
no links out).
"""

from __future__ import annotations

import base64
from collections import defaultdict
import datetime as dt
import html
import math
from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.core.trend import SECONDS_PER_DAY
from rwa_monitor.fleet import svg_plot
from rwa_monitor.fleet.trend_table import TrendTable
from rwa_monitor.fleet.trends import LEVELS, number

UNITS = {'dry': 'N m', 'viscous': 'N m s/rad'}
# A trend is flagged in the health column when its p-value is below this (two-sided; with
# 2 tests per wheel and 400 wheels, 0.8 false flags per fleet run with no wear at all).
TREND_LEVEL = 1.0e-3
STYLE = '''body{font-family:sans-serif;margin:1.5em;color:#222;max-width:1400px}
table{border-collapse:collapse;font-size:0.95em;margin-bottom:1em}
th,td{border:1px solid #bbb;padding:3px 6px}th{background:#eee}
td.num{text-align:right;font-family:monospace}.events{background:#f6d5d5}
.trend{background:#fbeecb}.ok{background:#dcefdc}.absent{background:#e4e4e4}
.new{font-weight:bold}img{max-width:100%}'''


def render(rows: Sequence[Mapping[str, Any]], summary: Mapping[str, Any],
           trend_rows: TrendTable | Sequence[Mapping[str, Any]],
           trends: Sequence[Mapping[str, Any]],
           epoch: dt.datetime | None = None, made: dt.datetime | None = None) -> str:
    """Return the report's HTML.

    ``rows``: the events table (fleet/history.py ``rows``: superseded ones are left
    out here); ``summary``: summary.json's content; ``trend_rows``: the trend table (or
    trend.parquet's rows);
    ``trends``: fleet/trends.py ``wheel_trends`` of them; ``epoch``: time 0 of the
    archive; ``made``: when the run was made (default now).
    """
    current = [r for r in rows if not r.get('superseded')]
    changes = _latest(current)
    per_wheel: dict[tuple[str, str], list] = defaultdict(list)
    for row in changes:
        per_wheel[(str(row.get('spacecraft')), str(row.get('component')))].append(row)
    table = TrendTable.of(trend_rows)
    groups = table.by_wheel()
    plotted = [e for e in trends if needs_plot(e, per_wheel, summary)]
    made = made or dt.datetime.now(dt.timezone.utc)
    parts = ['<!DOCTYPE html>', '<html lang="en"><head><meta charset="utf-8">',
             '<title>Fleet friction report</title>', f'<style>{STYLE}</style></head><body>',
             '<h1>Fleet friction report</h1>',
             _overview(changes, summary, trends, table.span(), epoch, made),
             _table(trends, per_wheel, summary, plotted), _events(changes, epoch),
             '<h2>Wheels</h2>',
             f'<p>Pass levels of the {len(plotted)} wheels with a change, a trend flag, a '
             f'projected limit crossing or no verdict; the other '
             f'{len(trends) - len(plotted)} are healthy with no trend (their numbers are in '
             f'the fleet table).</p>']
    for entry in plotted:
        key = (entry['spacecraft'], entry['wheel'])
        svg = _plot(key, groups[key], entry, per_wheel.get(key, []), epoch)
        parts += [f'<h3 id="{_anchor(key)}">{_e(key[0])} / {_e(key[1])}</h3>',
                  f'<img alt="levels of {_e(key[0])} {_e(key[1])}" '
                  f'src="data:image/svg+xml;base64,{svg}">']
    parts += ['</body></html>', '']
    return '\n'.join(parts)


def _latest(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Return one row per change (spacecraft, component, change index): its latest."""
    latest: dict[tuple, Mapping[str, Any]] = {}
    for row in rows:
        key = (row.get('spacecraft'), row.get('component'), row.get('index'))
        revision = row.get('revision') or 0
        if key not in latest or revision >= (latest[key].get('revision') or 0):
            latest[key] = row
    return sorted(latest.values(), key=lambda r: (number(r.get('time')),
                                                  str(r.get('spacecraft'))))


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _anchor(key: tuple[str, str]) -> str:
    return 'w-' + ''.join(c if c.isalnum() else '_' for c in f'{key[0]}-{key[1]}')


def _when(seconds: Any, epoch: dt.datetime | None) -> str:
    t = number(seconds)
    if not math.isfinite(t):
        return '&ndash;'
    if epoch is None:
        return f'{t:.1f} s (day {t / SECONDS_PER_DAY:.3f})'
    moment = epoch + dt.timedelta(seconds=t)
    return moment.strftime('%Y-%m-%d %H:%M:%S') + ' UTC'


def _overview(changes: list, summary: Mapping[str, Any], trends: Sequence[Mapping],
              data_span: tuple[float, float] | None, epoch: dt.datetime | None,
              made: dt.datetime) -> str:
    engine = summary.get('engine') or {}
    new = sum(bool(r.get('new')) for r in changes)
    facts = [f'{len(summary.get("spacecraft") or {})} spacecraft',
             f'{len(trends)} wheels with pass levels',
             f'{len(changes)} changes ({new} new in this run)']
    if summary.get('new_passes') is not None:
        facts.append(f'{summary["new_passes"]} new passes, '
                     f'{summary.get("already_processed", 0)} processed before')
    if 'wall_s' in engine:
        facts.append(f'wall time {number(engine["wall_s"]):.1f} s')
    span = (f'Data from {_when(data_span[0], epoch)} to {_when(data_span[1], epoch)}.'
            if data_span else 'No pass levels.')
    lines = [f'<p>{span} Report made {made.strftime("%Y-%m-%d %H:%M:%S")} UTC'
             f'{"" if epoch else "; the archive has no epoch: times are seconds of the archive"}'
             f'.</p>', f'<p>{", ".join(facts)}. Trend: weighted least-squares slope of the '
             f'pass levels in time, two-sided t test; flagged below p = {TREND_LEVEL:g}.</p>']
    point = summary.get('operating_point') or {}
    if 'false_alarm_rate' in point:
        lines.append(f'<p>Changes: LLR detector at false-alarm rate r = '
                     f'{number(point["false_alarm_rate"]):g} per test, window '
                     f'{_e(point.get("window"))} samples; parameters from '
                     f'{_e(summary.get("config"))}.</p>')
    missing = []
    for craft, block in sorted((summary.get('spacecraft') or {}).items()):
        for what, why in sorted((block.get('not_examined') or {}).items()):
            missing.append(f'<li>{_e(craft)}: {_e(what)}: {_e(why)}</li>')
    if missing:
        lines += ['<h2>Not examined</h2>', '<ul>', *missing, '</ul>']
    return '\n'.join(lines)


def _health(entry: Mapping[str, Any], block: Mapping[str, Any]) -> tuple[str, str]:
    verdict = str(block.get('health') or 'unknown')
    if verdict not in ('healthy', 'unknown'):
        return 'events', verdict
    if verdict == 'unknown':
        return 'absent', 'unknown (not examined)'
    flagged = [lv for lv in LEVELS if number(entry[f'{lv}_p_value']) < TREND_LEVEL]
    if flagged:
        return 'trend', f'healthy; trend ({", ".join(flagged)})'
    return 'ok', 'healthy'


def needs_plot(entry: Mapping[str, Any], per_wheel: Mapping[tuple[str, str], list],
               summary: Mapping[str, Any]) -> bool:
    """Return whether a wheel's levels are drawn: anything but healthy with no trend."""
    key = (entry['spacecraft'], entry['wheel'])
    css, _ = _health(entry, _block(summary, key))
    crossing = any(entry.get(f'{lv}_crossing_s') is not None for lv in LEVELS)
    return css != 'ok' or bool(per_wheel.get(key)) or crossing


def _passes(entry: Mapping[str, Any]) -> str:
    """Return the passes the trend is fitted on, and the days of the steps fitted in it."""
    steps = [number(s) / SECONDS_PER_DAY for s in entry.get('steps_s') or ()]
    if not steps:
        return str(entry['passes'])
    days = ', '.join(f'{d:.2f}' for d in steps)
    return f'{entry["passes"]} (step{"s" if len(steps) > 1 else ""} at day {days})'


def _block(summary: Mapping[str, Any], key: tuple[str, str]) -> Mapping[str, Any]:
    craft = (summary.get('spacecraft') or {}).get(key[0]) or {}
    return (craft.get('components') or {}).get(key[1]) or {}


def _table(trends: Sequence[Mapping[str, Any]], per_wheel: Mapping[tuple[str, str], list],
           summary: Mapping[str, Any], plotted: Sequence[Mapping[str, Any]] = ()) -> str:
    head = ('<tr><th>spacecraft</th><th>wheel</th><th>health</th><th>changes</th>'
            '<th>passes</th><th>relative to</th>'
            + ''.join(f'<th>{lv} slope / day ({UNITS[lv]})</th><th>{lv} p</th>'
                      f'<th>{lv} crossing (day, interval)</th>' for lv in LEVELS) + '</tr>')
    rows = ['<h2>Fleet</h2>', '<table>', head]
    drawn = {(e['spacecraft'], e['wheel']) for e in plotted}
    for entry in trends:
        key = (entry['spacecraft'], entry['wheel'])
        css, text = _health(entry, _block(summary, key))
        name = (f'<a href="#{_anchor(key)}">{_e(key[0])}</a>' if key in drawn
                else _e(key[0]))
        cells = [name, _e(key[1]), _e(text),
                 str(len(per_wheel.get(key, []))), _passes(entry),
                 _e(entry['relative_to'])]
        for lv in LEVELS:
            cells += [f'{_fmt(entry[f"{lv}_slope_per_day"])} &plusmn; '
                      f'{_fmt(entry[f"{lv}_slope_se"])}', _fmt(entry[f'{lv}_p_value']),
                      _crossing(entry, lv)]
        rows.append(f'<tr class="{css}">' + ''.join(
            f'<td class="num">{c}</td>' if i >= 3 else f'<td>{c}</td>'
            for i, c in enumerate(cells)) + '</tr>')
    rows.append('</table>')
    return '\n'.join(rows)


def _events(changes: Sequence[Mapping[str, Any]], epoch: dt.datetime | None) -> str:
    head = ('<tr><th>spacecraft</th><th>component</th><th>kind</th><th>change time</th>'
            '<th>declared</th><th>size</th><th>p-value</th><th>revision</th><th>final</th>'
            '<th>new</th></tr>')
    lines = ['<h2>Events</h2>']
    if not changes:
        return '\n'.join(lines + ['<p>No change declared.</p>'])
    lines += ['<table>', head]
    for r in changes:
        cells = [_e(r.get('spacecraft')), _e(r.get('component')), _e(r.get('kind')),
                 _when(r.get('time'), epoch) + _gap(r), _when(r.get('declared_time'), epoch),
                 _size(r), _p(r.get('p_value')), _e(r.get('revision')),
                 'yes' if r.get('final') else '', 'new' if r.get('new') else '']
        css = ' class="new"' if r.get('new') else ''
        lines.append(f'<tr{css}>' + ''.join(f'<td>{c}</td>' for c in cells) + '</tr>')
    lines.append('</table>')
    return '\n'.join(lines)


def _gap(row: Mapping[str, Any]) -> str:
    gap = number(row.get('after_gap_s'))
    return f' (after a gap of {gap / 3600.0:.2f} h)' if math.isfinite(gap) and gap > 0 else ''


def _size(row: Mapping[str, Any]) -> str:
    parts = []
    for key, unit in (('delta_dry_nm', 'N m dry'), ('delta_viscous_nms', 'N m s/rad viscous')):
        x = number(row.get(key))
        if math.isfinite(x):
            parts.append(f'{x:+.2e} {unit}')
    return ', '.join(parts) or '&ndash;'


def _p(value: Any) -> str:
    x = number(value)
    if not math.isfinite(x):
        return 'n/a'
    return '&lt; 1e-300' if x < 1e-300 else f'{x:.2g}'


def _fmt(value: Any) -> str:
    x = number(value)
    return '&ndash;' if not math.isfinite(x) else f'{x:.3g}'


def _crossing(entry: Mapping[str, Any], level: str) -> str:
    when = entry.get(f'{level}_crossing_s')
    if when is None:
        return '&ndash;'
    days = [number(entry[f'{level}_crossing{s}_s']) / SECONDS_PER_DAY
            for s in ('', '_low', '_high')]
    ends = ['&minus;&infin;' if d == -math.inf else '&infin;' if d == math.inf else f'{d:.1f}'
            for d in days[1:]]
    return f'{days[0]:.1f} ({ends[0]} .. {ends[1]})'


def _plot(key: tuple[str, str], columns: Mapping[str, np.ndarray], entry: Mapping[str, Any],
          changes: list, epoch: dt.datetime | None) -> str:
    """Return the base64 SVG of one wheel: levels with errors, trend, limit, changes.

    ``columns``: the wheel's group of TrendTable.by_wheel.
    """
    days = 0.5 * (columns['t_start'] + columns['t_end']) / SECONDS_PER_DAY
    origin = f' since {epoch:%Y-%m-%d %H:%M} UTC' if epoch else ''
    panels = []
    for level in LEVELS:
        panel = svg_plot.Panel(
            days, np.asarray(columns[level], dtype=float),
            np.asarray(columns[f'{level}_se'], dtype=float), f'time (days{origin})',
            f'{level} ({UNITS[level]}), vs {entry["relative_to"] or "zero"}',
            point_label='pass level ± 1 s.e.', mark_label='change')
        slope = number(entry[f'{level}_slope_per_day'])
        intercept = number(entry[f'{level}_intercept'])
        finite = days[np.isfinite(days)]
        if math.isfinite(slope) and finite.size:
            since = number(entry.get('since_s')) / SECONDS_PER_DAY
            start = since if math.isfinite(since) else float(finite.min())
            end = float(finite.max())
            after = ' since the step' if math.isfinite(since) else ''
            panel.lines.append(((start, end), (intercept + slope * start,
                                               intercept + slope * end), svg_plot.ORANGE,
                                f'trend{after}, p = '
                                f'{number(entry[f"{level}_p_value"]):.2g}'))
        if entry.get(f'{level}_limit') is not None:
            panel.levels.append((number(entry[f'{level}_limit']), svg_plot.RED, 'limit'))
        for change in changes:
            panel.marks.append((number(change.get('time')) / SECONDS_PER_DAY, svg_plot.RED,
                                str(change.get('kind'))))
        panels.append(panel)
    svg = svg_plot.figure(f'{key[0]} / {key[1]}', panels)
    return base64.b64encode(svg.encode('utf-8')).decode('ascii')
