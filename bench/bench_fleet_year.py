"""A daily ``--state`` run late in a fleet's year: what the growing archive and state cost.

A daily run lists the archive (every pass so far) and finds the processed ones by name
and size in the state's pass records, reads the state's trend table (one row per
spacecraft, wheel and pass so far) and event history, adds its own, fits each wheel's
trend, draws the report and writes both tables twice (outputs and state). Their size
grows with the days, the day's telemetry does not. Measured: 100 spacecraft (seed 31, 6
passes of 10 min a day each), a day-1 run with a state, then the day-2 run from that
state as it is ("age 0") and from copies of it aged to older fleets: the day-1 trend
rows, events and pass records repeated once per earlier day (shifted back by whole days,
the passes renamed ``day-N-<name>``), written through the state's own commit, so the run
reads, checks and rewrites them as a real one would, and the archive given those passes
as files (hard links to day 1's). The day-2 run's whole command
(new process, cluster, outputs, state) is timed, median of ``repeats``, each from a
fresh copy of the state. The extra time over age 0, integrated over the year, is what
the growing archive and state add to a fleet-year of daily runs (bench fleet's
figure leaves it out).
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import shutil
import statistics
import tempfile
from typing import Any

from bench.bench_fleet import simulate, split_days, whole_command
from bench.report import table, update_section, write_json

SECONDS_PER_DAY = 86400.0
DAYS_PER_YEAR = 365.25


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'spacecraft': 3, 'ages': (0, 20), 'repeats': 1}
    return {'spacecraft': 100, 'ages': (0, 91, 182, 364), 'repeats': 3}


def age_state(fresh: pathlib.Path, aged: pathlib.Path, days: int) -> dict[str, int]:
    """Copy the state ``fresh`` to ``aged`` with its tables and passes repeated for ``days``.

    Returns the rows of the aged trend table and event history, and the pass records.
    """
    from rwa_monitor.fleet import state
    from rwa_monitor.fleet.history import Entry, to_parquet
    from rwa_monitor.fleet.records import PassLog
    from rwa_monitor.fleet.trend_table import TrendTable
    shutil.copytree(fresh, aged)
    loaded = state.load(aged)
    rows = list(loaded.trend)
    trend = TrendTable.from_rows(
        [dataclasses.replace(r, t_start=r.t_start - d * SECONDS_PER_DAY,
                             t_end=r.t_end - d * SECONDS_PER_DAY,
                             pass_name=f'day-{d}-{r.pass_name}')
         for d in range(days, 0, -1) for r in rows] + rows)
    history = [Entry(h.spacecraft, dataclasses.replace(
        h.event, time=h.event.time - d * SECONDS_PER_DAY,
        declared_time=h.event.declared_time - d * SECONDS_PER_DAY),
        h.run, h.end_of_run, h.superseded)
        for d in range(days, 0, -1) for h in loaded.history] + list(loaded.history)
    records = {craft: dataclasses.replace(record, passes=PassLog.of([
        dataclasses.replace(p, name=f'day-{d}-{p.name}', first=p.first - d * SECONDS_PER_DAY,
                            last=p.last - d * SECONDS_PER_DAY)
        for d in range(days, 0, -1) for p in record.passes]).plus(list(record.passes)))
        for craft, record in loaded.records.items()}
    state.commit(aged, loaded, records, trend.to_parquet(), to_parquet(history))
    return {'trend_rows': len(trend), 'history_rows': len(history),
            'pass_records': sum(len(r.passes) for r in records.values())}


def age_archive(day1: pathlib.Path, archive: pathlib.Path, days: int) -> None:
    """Give ``archive`` day 1's passes of ``days`` earlier days, as ``age_state`` names them.

    Adds the links an earlier call did not (the ages are run in increasing order).
    """
    for folder in sorted(p for p in day1.iterdir() if p.is_dir()):
        passes = [p for p in sorted(folder.iterdir()) if p.suffix == '.parquet']
        for d in range(1, days + 1):
            for path in passes:
                link = archive / folder.name / f'day-{d}-{path.name}'
                if not link.exists():
                    os.link(path, link)


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run the measurement; write fleet_year.json and docs/results.md's section."""
    settings = _settings(quick)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix='bench-fleet-year-') as tmp:
        scratch = pathlib.Path(tmp)
        archive = scratch / 'archive'
        facts = simulate(archive, settings['spacecraft'], 2.0, seed=31)
        days = split_days(archive, scratch)
        fresh = scratch / 'state'
        day1 = whole_command(days[1], scratch / 'out-day1', state=fresh)
        ages = []
        for age in settings['ages']:
            aged = scratch / f'state-{age}'
            size = age_state(fresh, aged, age)
            age_archive(days[1], days[2], age)
            walls = []
            for repeat in range(settings['repeats']):
                work = scratch / f'state-{age}-{repeat}'
                shutil.copytree(aged, work)
                done = whole_command(days[2], scratch / f'out-{age}-{repeat}', state=work)
                walls.append(done['wall_s'])
                shutil.rmtree(work)
            ages.append({'age_days': age, **size, 'wall_s': walls,
                         'median_wall_s': statistics.median(walls)})
            print(f'fleet_year: age {age} d: {statistics.median(walls):.1f} s', flush=True)
    results = {'settings': settings, 'archive': facts, 'day1': day1, 'ages': ages,
               'load_before': load_before, 'load_after': os.getloadavg()[0], **_year(ages)}
    write_json(out_dir, 'fleet_year', results)
    if not quick:
        update_section('fleet_year', markdown(results))
    return results


def _year(ages: list[dict[str, Any]]) -> dict[str, Any]:
    """Return the extra time of the tables over a year (trapezoids over the ages)."""
    base = ages[0]['median_wall_s']
    points = [(a['age_days'], a['median_wall_s'] - base) for a in ages]
    extra = sum(0.5 * (y0 + y1) * (x1 - x0)
                for (x0, y0), (x1, y1) in zip(points, points[1:]))
    span = points[-1][0] - points[0][0]
    extra_year = extra * DAYS_PER_YEAR / span if span else 0.0
    return {'extra_s_per_run_at_end': points[-1][1], 'extra_year_h': extra_year / 3600.0}


def markdown(results: dict[str, Any]) -> str:
    """Return docs/results.md's section."""
    s = results['settings']
    rows = [[a['age_days'], a['trend_rows'], a['history_rows'], a.get('pass_records', ''),
             f'{a["median_wall_s"]:.1f}', ', '.join(f'{w:.1f}' for w in a['wall_s'])]
            for a in results['ages']]
    return '\n'.join([
        '## A daily fleet run late in the year (`python -m bench fleet_year`, issue 31 '
        'item 5)', '',
        f'{s["spacecraft"]} spacecraft, day 2 of a 2-day archive (seed 31, '
        f'{results["archive"]["passes"]} passes) run with `--state` after day 1, the '
        'state aged by repeating its trend rows, events and pass records once per earlier '
        "day, and the archive given those passes' files (bench/bench_fleet_year.py); "
        'whole command, 2 workers, median of '
        f'{s["repeats"]}; load average of the 2-core machine (1 min) '
        f'{results["load_before"]:.1f} before, {results["load_after"]:.1f} after.', '',
        table(['state age (days)', 'trend rows', 'history events', 'passes (files and '
               'records)', 'median wall (s)', 'runs (s)'], rows), '',
        f'- Extra time of a run at the last age: '
        f'{results["extra_s_per_run_at_end"]:.1f} s; over a year of daily runs '
        f'(trapezoids through the ages): **{results["extra_year_h"]:.2f} h**, to add to '
        'the fleet-year of daily runs of the fleet section.',
    ])
