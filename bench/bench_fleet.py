"""``python -m bench fleet``: the fleet engine on a simulated fleet archive of Parquet passes.

Sections, all on archives from ``rwa-monitor simulate fleet`` (seeded, 10 Hz, 6 passes of
10 minutes a day, 4 wheels), its CSV passes rewritten as Parquet: the simulator's own
time; the whole command ``rwa-monitor fleet ARCHIVE -o OUT --workers 2`` as a user runs it
(start-up, cluster, imports, outputs: its wheel samples per wall second give the
fleet-year projection); the engine on a warm local Dask cluster of 1 and of 2 workers
(runs interleaved, best wall time of each kept: the machine is shared) against plain
``detect`` on each spacecraft's passes joined into one Parquet file (read + detect, in
this process, after a warm-up), with the event counts compared; peak RSS of one worker
on a short and a long archive of the same spacecraft (flat in the number of passes); the
start-up time of ``rwa-monitor --help`` and of each command's ``--help``. Results:
bench/results/fleet.json, fleet.png and the ``fleet`` section of docs/results.md.
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import shutil
import tempfile
import time
from typing import Any

import numpy as np

from bench import fleet_parts, report

GOALS = {'overhead': 0.15, 'scaling_2_workers': 1.7, 'peak_rss_mb': 500.0,
         'simulate_fleet_week_s': 300.0, 'fleet_year_hours': 4.0, 'start_s': 0.5}
COMMANDS = ('simulate', 'detect', 'diagnose', 'identify', 'calibrate', 'fleet', 'demo',
            'dashboard', 'params')
FLEET_YEAR = {'spacecraft': 100, 'wheels': 4, 'rate_hz': 10.0, 'days': 365.25}
PROJECT_WORKERS = (1, 2, 8, 32, 128)
FEW_SPACECRAFT = 5


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'spacecraft': 3, 'days': 1.0, 'long_days': 2.0, 'repeats': 1,
                'daily_spacecraft': 4, 'parts_repeats': 1, 'fleet_repeats': 1,
                'memory_days': (0.5, 1.0), 'memory_spacecraft': 1}
    return {'spacecraft': 20, 'days': 7.0, 'long_days': 21.0, 'repeats': 5,
            'daily_spacecraft': FLEET_YEAR['spacecraft'], 'parts_repeats': 5,
            'fleet_repeats': 4,
            'memory_days': (2.0, 8.0), 'memory_spacecraft': 2}


def simulate(folder: pathlib.Path, spacecraft: int, days: float, seed: int = 23) -> dict:
    """Write an archive with the CLI's code path, passes as Parquet; return its facts.

    The simulator writes CSV (its time is the one reported); each pass is then read and
    rewritten as Parquet with the same columns, the CSV removed.
    """
    from rwa_monitor.sim.fleet import plan_fleet, write_fleet
    from rwa_monitor.telemetry import read_telemetry
    from rwa_monitor.telemetry.parquet_io import write_parquet
    start_wall, start_cpu = time.perf_counter(), time.process_time()
    plan = plan_fleet(spacecraft=spacecraft, days=days, seed=seed)
    files = write_fleet(folder, plan)
    wall, cpu = time.perf_counter() - start_wall, time.process_time() - start_cpu
    csv_bytes = sum(p.stat().st_size for p in files)
    size = 0
    for path in files:
        if path.suffix == '.csv':
            target = path.with_suffix('.parquet')
            write_parquet(target, read_telemetry(path))
            path.unlink()
            size += target.stat().st_size
    passes = sum(len(c.passes) for c in plan.spacecraft)
    rows = passes * int(plan.pass_s * plan.rate_hz)
    return {'spacecraft': spacecraft, 'days': days, 'passes': passes, 'rows': rows,
            'wheel_samples': rows * len(plan.wheels), 'bytes': size, 'csv_bytes': csv_bytes,
            'wall_s': wall, 'cpu_s': cpu}


def join_passes(archive: pathlib.Path, out: pathlib.Path) -> list[pathlib.Path]:
    """Write each spacecraft's passes, in time order, joined into ``out/<id>.parquet``."""
    from rwa_monitor.telemetry import read_telemetry, Telemetry
    from rwa_monitor.telemetry.parquet_io import write_parquet
    truth = json.loads((archive / 'truth.json').read_text())
    paths = []
    out.mkdir(parents=True, exist_ok=True)
    for craft, block in sorted(truth['spacecraft'].items()):
        parts = [read_telemetry((archive / craft / p['file']).with_suffix('.parquet'))
                 .columns() for p in sorted(block['passes'], key=lambda p: p['t_start_s'])]
        joined = {k: np.concatenate([c[k] for c in parts]) for k in parts[0]}
        paths.append(out / f'{craft}.parquet')
        write_parquet(paths[-1], Telemetry.from_columns(joined))
    return paths


def subset(archive: pathlib.Path, out: pathlib.Path, spacecraft: int) -> pathlib.Path:
    """Return an archive of the first ``spacecraft`` folders of ``archive`` (hard links)."""
    for folder in sorted(p for p in archive.iterdir() if p.is_dir())[:spacecraft]:
        (out / folder.name).mkdir(parents=True)
        for path in folder.iterdir():
            os.link(path, out / folder.name / path.name)
    for path in archive.iterdir():
        if path.is_file():
            os.link(path, out / path.name)
    return out


def whole_command(archive: pathlib.Path, out: pathlib.Path, workers: int = 2,
                  state: pathlib.Path | None = None) -> dict[str, Any]:
    """Time ``rwa-monitor fleet`` as a user runs it (a new process, cluster and outputs)."""
    import subprocess
    import sys
    command = [str(pathlib.Path(sys.executable).with_name('rwa-monitor')), 'fleet',
               str(archive), '-o', str(out), '--workers', str(workers)]
    if state is not None:
        command += ['--state', str(state)]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode not in (0, 1, 3):
        raise RuntimeError(f'{" ".join(command)}: exit {done.returncode}: {done.stderr}')
    summary = json.loads((out / 'summary.json').read_text())
    return {'wall_s': wall, 'exit': done.returncode, 'workers': workers,
            'wheel_samples': summary['engine']['wheel_samples'],
            'events': summary['events']}


def daily_runs(scratch: pathlib.Path, spacecraft: int, repeats: int = 1) -> dict[str, Any]:
    """Time a day's ``--state`` run of ``spacecraft`` after a first day's run.

    A 2-day archive is split by each pass's first stamp into day 1 and days 1-2 (hard
    links); the second run finds day 1 processed and runs day 2 only, as a daily job does,
    ``repeats`` times, each from a copy of the state day 1 left (``day2``: the median).
    """
    archive = scratch / 'daily'
    facts = simulate(archive, spacecraft, 2.0, seed=31)
    days = split_days(archive, scratch)
    state = scratch / 'daily-state'
    first = whole_command(days[1], scratch / 'daily-out1', state=state)
    seconds = []
    for i in range(repeats):
        again = scratch / f'daily-state{i}'
        shutil.copytree(state, again)
        seconds.append(whole_command(days[2], scratch / f'daily-out2-{i}', state=again))
    shutil.rmtree(archive, ignore_errors=True)
    return {'spacecraft': spacecraft, 'passes': facts['passes'], 'day1': first,
            'day2': typical(seconds), 'day2_runs': seconds}


def typical(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Return the run of median wall time (the upper middle one of an even number)."""
    ordered = sorted(runs, key=lambda r: r['wall_s'])
    return ordered[len(ordered) // 2]


def split_days(archive: pathlib.Path, scratch: pathlib.Path) -> dict[int, pathlib.Path]:
    """Return archives of day 1 and of days 1-2 of a 2-day ``archive`` (hard links).

    A pass belongs to the days its first stamp falls in; files without one (truth.json,
    the epoch) go to both.
    """
    import pyarrow.parquet as pq
    days = {1: scratch / 'day1', 2: scratch / 'days12'}
    for path in sorted(archive.rglob('*')):
        if path.is_dir():
            continue
        relative = path.relative_to(archive)
        first = (pq.ParquetFile(path).read_row_group(0, columns=['time']).column(0)[0]
                 .as_py() if path.suffix == '.parquet' else 0.0)
        for day, root in days.items():
            if first < day * 86400.0:
                (root / relative).parent.mkdir(parents=True, exist_ok=True)
                os.link(path, root / relative)
    return days


def start_times(repeats: int = 5) -> dict[str, float]:
    """Return the median wall time of ``rwa-monitor --help`` and of each command's."""
    import subprocess
    import sys
    exe = str(pathlib.Path(sys.executable).with_name('rwa-monitor'))
    out = {}
    for name in ('',) + COMMANDS:
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            subprocess.run([exe, *([name] if name else []), '--help'], capture_output=True,
                           check=False)
            times.append(time.perf_counter() - start)
        out[name or '--help'] = float(np.median(times))
    return out


def plain_detect(files: list[pathlib.Path], repeats: int = 1) -> dict[str, Any]:
    """Time ``detect`` (the fleet's parameters) as the CLI runs it, file by file.

    ``repeats`` runs after a warm-up: ``wall_s`` and ``cpu_s`` are their medians (the
    shared machine moves single runs by a tenth), ``cpu_runs`` each run's CPU.
    """
    from rwa_monitor.cli.cmd_detect import load_config
    from rwa_monitor.fleet.engine import fleet_parameters_file
    from rwa_monitor.pipelines import detect
    from rwa_monitor.telemetry import read_telemetry
    config = load_config(fleet_parameters_file())
    detect(read_telemetry(files[0]), config)          # warm-up: compiled kernels
    walls, cpus = [], []
    for _ in range(repeats):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        events = 0
        for path in files:
            events += len(detect(read_telemetry(path), config).events)
        walls.append(time.perf_counter() - start_wall)
        cpus.append(time.process_time() - start_cpu)
    return {'wall_s': float(np.median(walls)), 'cpu_s': float(np.median(cpus)),
            'cpu_runs': cpus, 'events': events}


def fleet_runs(archive: pathlib.Path, warm: pathlib.Path, workers: int,
               repeats: int, floor: bool = False) -> list[dict[str, Any]]:
    """Run the engine ``repeats`` times on one warm local cluster of ``workers``.

    ``floor``: after each run, its idle twin on the same cluster (bench/fleet_parts.py
    ``dask_floor``: as many tasks, the same wall time, nothing computed).
    """
    from rwa_monitor.fleet.cluster import dask_client
    from rwa_monitor.fleet.engine import run_archive
    from rwa_monitor.fleet.plan import SCAN_TASK_PASSES
    passes = sum(1 for p in archive.glob('*/*') if p.name.startswith('pass-'))
    start = time.perf_counter()
    runs = []
    with dask_client(workers) as client:
        startup = time.perf_counter() - start
        run_archive(warm, client=client)               # warm-up: imports and kernels
        for _ in range(repeats):
            before = client.run(time.process_time)
            result = run_archive(archive, client=client)
            after = client.run(time.process_time)
            # The worker processes' whole CPU time over the run (tasks and Dask's own).
            whole = sum(after[w] - before[w] for w in after if w in before)
            runs.append({**result.timings, 'events': len(result.current_events()),
                         'workers': workers, 'cluster_start_s': startup,
                         'worker_process_cpu_s': whole})
            if floor:
                tasks = (sum(w['tasks'] for w in result.timings['per_worker'].values())
                         + math.ceil(passes / SCAN_TASK_PASSES))
                runs[-1]['floor'] = fleet_parts.dask_floor(client, tasks,
                                                           result.timings['wall_s'])
    return runs


def memory_run(archive: pathlib.Path, warm: pathlib.Path) -> dict[str, Any]:
    """Peak RSS of the one worker of a fresh cluster (warm-up then ``archive``)."""
    run = fleet_runs(archive, warm, 1, 1)[0]
    peaks = [w['peak_rss_mb'] for w in run['per_worker'].values()]
    return {'peak_rss_mb': max(peaks), 'wheel_samples': run['wheel_samples']}


def fleet_year_samples() -> float:
    """Return the wheel samples of a fleet-year (FLEET_YEAR)."""
    y = FLEET_YEAR
    return y['spacecraft'] * y['wheels'] * y['rate_hz'] * y['days'] * 86400.0


def projection(rate_per_worker: float) -> dict[str, Any]:
    """Hours for a fleet-year on K workers at the measured rate per worker."""
    samples = fleet_year_samples()
    hours = {k: samples / (k * rate_per_worker) / 3600.0 for k in PROJECT_WORKERS}
    return {'samples': samples, 'rate_per_worker': rate_per_worker, 'hours': hours}


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run every section; write JSON, plot and the docs/results.md section."""
    settings = _settings(quick)
    results: dict[str, Any] = {'quick': quick, 'goals': GOALS, 'settings': settings,
                               'commit': _commit(),
                               'load_average_before': list(os.getloadavg())}
    scratch = pathlib.Path(tempfile.mkdtemp(prefix='bench-fleet-'))
    try:
        archive, warm = scratch / 'archive', scratch / 'warm'
        results['simulate'] = simulate(archive, settings['spacecraft'], settings['days'])
        simulate(warm, 1, 1.0 / 6.0, seed=1)
        print(f'  simulate: {results["simulate"]}', flush=True)
        joined = join_passes(archive, scratch / 'joined')
        results['detect'] = plain_detect(joined, settings['fleet_repeats'])
        print(f'  detect: {results["detect"]}', flush=True)
        few = subset(archive, scratch / 'few', FEW_SPACECRAFT)
        long = scratch / 'long'
        results['simulate_long'] = simulate(long, settings['spacecraft'],
                                            settings['long_days'], seed=29)
        # The three sizes in turn, so that a drift of the machine's speed moves them alike.
        sizes = {'command': archive, 'command_few': few, 'command_long': long}
        for key in sizes:
            results[key] = []
        for i in range(settings['repeats']):
            for key, folder in sizes.items():
                results[key].append(whole_command(folder, scratch / f'{key}-out{i}'))
        shutil.rmtree(long, ignore_errors=True)
        for key, label in (('command', 'whole command'),
                           ('command_few', f'whole command, {FEW_SPACECRAFT} spacecraft'),
                           ('command_long', 'whole command, long archive')):
            print(f'  {label}: {results[key]}', flush=True)
        results['daily'] = daily_runs(scratch, settings['daily_spacecraft'],
                                      settings['repeats'])
        print(f'  daily runs: {results["daily"]}', flush=True)
        results['start'] = start_times()
        print(f'  start-up: {results["start"]}', flush=True)
        runs: dict[int, list] = {1: [], 2: []}
        for _ in range(settings['fleet_repeats']):
            for workers in (1, 2):
                runs[workers] += fleet_runs(archive, warm, workers, 1, workers == 1)
                print(f'  fleet {workers} worker(s): wall {runs[workers][-1]["wall_s"]:.1f} s',
                      flush=True)
        results['fleet'] = {str(k): v for k, v in runs.items()}
        results['memory'] = []
        for days in settings['memory_days']:
            folder = scratch / f'memory-{days:g}'
            facts = simulate(folder, settings['memory_spacecraft'], days, seed=5)
            results['memory'].append({**facts, **memory_run(folder, warm)})
            print(f'  memory: {results["memory"][-1]}', flush=True)
        # Last: the steps in this process would raise this process's memory (the
        # workers' peaks are their own: VmHWM, fleet/chain.py peak_memory_mb).
        results['parts'] = fleet_parts.split(archive, joined, settings['parts_repeats'])
        print(f'  in one process: {results["parts"]}', flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    results['load_average_after'] = list(os.getloadavg())
    results['summary'] = summarise(results)
    results['previous'] = previous_runs(out_dir)
    report.write_json(out_dir, 'fleet', results)
    _plot(out_dir, results)
    report.update_section('fleet', markdown(results))
    return results


def previous_runs(out_dir: pathlib.Path, keep: int = 3) -> list[dict[str, Any]]:
    """Return the last full runs in ``out_dir`` (newest first): commit, loads, summary."""
    try:
        last = json.loads((out_dir / 'fleet.json').read_text())
    except (OSError, ValueError):
        return []
    if last.get('quick') or 'summary' not in last:
        return []
    earlier = last.get('previous') or []
    earlier = [earlier] if isinstance(earlier, dict) else earlier
    mine = {k: last.get(k) for k in ('commit', 'load_average_before', 'load_average_after',
                                     'summary')}
    return ([mine] + earlier)[:keep]


def _commit() -> str:
    """Return the repository's short commit (the code measured), or '' outside git."""
    import subprocess
    done = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=report.REPO,
                          capture_output=True, text=True, check=False)
    return done.stdout.strip() if done.returncode == 0 else ''


def summarise(results: dict[str, Any]) -> dict[str, Any]:
    """Derive the ratios and the projection from the runs (best wall time of each)."""
    best = {k: min(v, key=lambda r: r['wall_s']) for k, v in results['fleet'].items()}
    one, two = best['1'], best['2']
    detect = results['detect']
    samples = one['wheel_samples']
    rate_two = samples / two['wall_s'] / 2
    command = typical(results['command'])
    return {
        'samples': samples,
        'per_worker_wall_rate': {'1': samples / one['wall_s'], '2': rate_two},
        'per_worker_cpu_rate': {'1': one['wheel_samples_per_cpu_s'],
                                '2': two['wheel_samples_per_cpu_s']},
        'command_rate': command['wheel_samples'] / command['wall_s'],
        'command_fleet_year_hours': fleet_year_samples() * command['wall_s']
        / command['wheel_samples'] / 3600.0,
        **marginal(results),
        'slowest_start_s': max(results['start'].values()),
        'detect_rate': samples / detect['wall_s'],
        'overhead_wall': one['wall_s'] / detect['wall_s'] - 1.0,
        'overhead_cpu': (one['cpu_s'] + one['client_cpu_s']) / detect['cpu_s'] - 1.0,
        'overhead_cpu_median': float(np.median([r['cpu_s'] + r['client_cpu_s']
                                                for r in results['fleet']['1']]))
        / detect['cpu_s'] - 1.0,
        **_whole_median(results),
        'scaling': one['wall_s'] / two['wall_s'],
        'events': {'detect': detect['events'], 'fleet_1': one['events'],
                   'fleet_2': two['events']},
        'peak_rss_mb': max(w['peak_rss_mb'] for r in (one, two)
                           for w in r['per_worker'].values()),
        'projection': projection(rate_two)}


def _whole_median(results: dict[str, Any]) -> dict[str, float]:
    """Return the CPU ratio of the 1-worker runs counting whole processes (medians).

    The worker process's whole CPU (its ``step`` tasks, the plan's ``scan`` tasks and
    Dask's own work between them) plus the client's, over ``detect``'s: all the CPU a
    run of the fleet costs, where ``overhead_cpu_median`` counts the steps' tasks only.
    """
    runs = [r for r in results['fleet']['1'] if 'worker_process_cpu_s' in r]
    if not runs:
        return {}
    whole = float(np.median([r['worker_process_cpu_s'] + r['client_cpu_s'] for r in runs]))
    return {'whole_cpu_median_s': whole,
            'overhead_cpu_whole_median': whole / results['detect']['cpu_s'] - 1.0}


def paired_difference(larger: list[dict[str, Any]], smaller: list[dict[str, Any]]) -> float:
    """Return the median over rounds of the wall-time difference of two sizes' runs.

    Round i's runs of the sizes ran one after the other, so a drift of the machine's
    speed between rounds (a third on this shared machine) moves both and cancels in
    their difference; the difference of the two medians does not cancel it (on
    c9c8ce7 the medians of this bench's 5 rounds gave a fleet-year of 2.64 h, the median
    of 10 paired differences of the same commands 4.9 h).
    """
    return float(np.median([b['wall_s'] - a['wall_s'] for a, b in zip(smaller, larger)]))


def _differences(results: dict[str, Any], larger: str, smaller: str) -> str:
    """Return the rounds' wall-time differences of two sizes, as text (s)."""
    pairs = zip(results[smaller], results[larger])
    return ', '.join(f'{b["wall_s"] - a["wall_s"]:.2f}' for a, b in pairs) + ' s'


def marginal(results: dict[str, Any]) -> dict[str, Any]:
    """Whole-command time as c0 + c1 x spacecraft + samples / rate.

    From three archives: the short one, the same spacecraft over three times the days
    (the rate) and its first FEW_SPACECRAFT spacecraft (c1: what each spacecraft costs
    whatever its days: its scan, task, state, outputs and plots); the rate and c1 from
    the rounds' paired differences (:func:`paired_difference`). A fleet-year in one
    command pays c0 + c1 x 100 once; in daily ``--state`` runs, once a day.
    """
    if not results.get('command_long') or not results.get('command_few'):
        return {}
    short, long, few = (typical(results[k]) for k in ('command', 'command_long',
                                                      'command_few'))
    crafts = results['simulate']['spacecraft']
    rate = ((long['wheel_samples'] - short['wheel_samples'])
            / paired_difference(results['command_long'], results['command']))
    per_craft = ((paired_difference(results['command'], results['command_few'])
                  - (short['wheel_samples'] - few['wheel_samples']) / rate)
                 / (crafts - FEW_SPACECRAFT))
    fixed = short['wall_s'] - per_craft * crafts - short['wheel_samples'] / rate
    run = fixed + per_craft * FLEET_YEAR['spacecraft']
    year = fleet_year_samples() / rate
    out = {'marginal_rate': rate, 'fixed_s': fixed, 'per_spacecraft_s': per_craft,
           'marginal_year_hours': (run + year) / 3600.0,
           'daily_model_year_hours': (365 * run + year) / 3600.0}
    daily = results.get('daily')
    if daily:
        # The measured day's run, its samples replaced by a day of continuous telemetry
        # of its spacecraft at the fleet-year's rate (the archive holds passes only).
        y = FLEET_YEAR
        day = daily['day2']
        continuous = daily['spacecraft'] * y['wheels'] * y['rate_hz'] * 86400.0
        out['daily_day_s'] = day['wall_s'] - day['wheel_samples'] / rate + continuous / rate
        out['daily_runs_year_hours'] = (y['days'] * out['daily_day_s']
                                        * y['spacecraft'] / daily['spacecraft'] / 3600.0)
    return out


def markdown(results: dict[str, Any]) -> str:
    """Return the ``fleet`` section of docs/results.md."""
    s, sim, det = results['summary'], results['simulate'], results['detect']
    best = {k: min(v, key=lambda r: r['wall_s']) for k, v in results['fleet'].items()}
    mem = results['memory']
    load = (f'{results["load_average_before"][0]:.1f} before, '
            f'{results["load_average_after"][0]:.1f} after')
    met = {'overhead': s['overhead_wall'] <= GOALS['overhead'],
           'overhead_cpu': s['overhead_cpu'] <= GOALS['overhead'],
           'scaling': s['scaling'] >= GOALS['scaling_2_workers'],
           'memory': (max(m['peak_rss_mb'] for m in mem) < GOALS['peak_rss_mb']
                      and mem[-1]['peak_rss_mb'] <= 1.1 * mem[0]['peak_rss_mb'])}
    word = {True: 'met', False: 'not met'}
    lines = [f'## Fleet engine on Dask (`python -m bench fleet'
             f'{" --quick" if results["quick"] else ""}`)', '',
             f'Archive from `simulate fleet`: {sim["spacecraft"]} spacecraft x '
             f'{sim["days"]:g} days, {sim["passes"]} passes of 10 min at 10 Hz, 4 wheels: '
             f'{sim["wheel_samples"]:.3g} wheel samples, {sim["bytes"] / 1e6:.0f} MB of '
             f'Parquet ({sim["csv_bytes"] / 1e6:.0f} MB as the simulator\'s CSV, written in '
             f'{sim["wall_s"]:.1f} s wall ({sim["cpu_s"]:.1f} s CPU, one process; '
             f'goal for 20 spacecraft x 7 days: <= {GOALS["simulate_fleet_week_s"]:.0f} s'
             + (f', **{word[sim["wall_s"] <= GOALS["simulate_fleet_week_s"]]}**'
                if (sim['spacecraft'], sim['days']) == (20, 7.0) else ', not this size')
             + '). '
             f'Engine on a warm local cluster (start-up and a warm-up run excluded), best of '
             f'{len(results["fleet"]["1"])} interleaved runs per size; code of commit '
             f'{results.get("commit") or "?"}. Load average of the 2-core machine (`uptime`, '
             f'1 min): {load}; wall / CPU time of `detect` (one process, 1.0 when it has a '
             f'core to itself): {det["wall_s"] / det["cpu_s"]:.1f}, of the 1-worker run: '
             f'{best["1"]["wall_s"] / (best["1"]["cpu_s"] + best["1"]["client_cpu_s"]):.1f}. '
             'Wall-time ratios measured under such contention are uncertain; the CPU '
             'ratio is the steadier figure.', '']
    rows = [['plain detect on the joined files (one process)', f'{det["wall_s"]:.1f}',
             f'{det["cpu_s"]:.1f}', f'{s["detect_rate"]:.3g}', det['events'], ''],
            ['fleet, 1 worker', f'{best["1"]["wall_s"]:.1f}',
             f'{best["1"]["cpu_s"] + best["1"]["client_cpu_s"]:.1f}',
             f'{s["per_worker_wall_rate"]["1"]:.3g}', best['1']['events'],
             f'{max(w["peak_rss_mb"] for w in best["1"]["per_worker"].values()):.0f}'],
            ['fleet, 2 workers', f'{best["2"]["wall_s"]:.1f}',
             f'{best["2"]["cpu_s"] + best["2"]["client_cpu_s"]:.1f}',
             f'{s["per_worker_wall_rate"]["2"]:.3g}', best['2']['events'],
             f'{max(w["peak_rss_mb"] for w in best["2"]["per_worker"].values()):.0f}']]
    lines += [report.table(['run', 'wall (s)', 'CPU (s, workers + client)',
                            'wheel samples / s per worker (wall)', 'events',
                            'peak RSS per worker (MB)'], rows), '']
    if 'worker_process_cpu_s' in best['1']:
        whole = {k: best[k]['worker_process_cpu_s'] + best[k]['client_cpu_s'] for k in best}
        lines += ["- Whole worker processes' CPU (tasks and Dask's own work between them) "
                  f"plus the client's (which runs the local scheduler): {whole['1']:.1f} s "
                  f'(1 worker), {whole["2"]:.1f} s (2 workers); against `detect`: '
                  f'{100 * (whole["1"] / det["cpu_s"] - 1):+.0f} % (1 worker).']
    share = {k: (best[k]['cpu_s'] + best[k]['client_cpu_s']) / (best[k]['wall_s'] * int(k))
             for k in best}
    lines += [f'- Share of a core each worker got (CPU / (wall x workers)): {share["1"]:.2f} '
              f'(1 worker), {share["2"]:.2f} (2 workers): the scaling measures the engine '
              'only as far as the shared machine gave the second worker a core.']
    lines += [f'- Samples per CPU second per worker: {s["per_worker_cpu_rate"]["1"]:.3g} '
              f'(1 worker), {s["per_worker_cpu_rate"]["2"]:.3g} (2 workers).',
              f'- Overhead of `fleet` (1 worker) against `detect` on the joined files: '
              f'{100 * s["overhead_wall"]:+.0f} % in wall time, {100 * s["overhead_cpu"]:+.0f} '
              f'% in CPU time (goal <= {100 * GOALS["overhead"]:.0f} %): wall '
              f'**{word[met["overhead"]]}**, CPU **{word[met["overhead_cpu"]]}**. CPU of '
              "the fleet: its tasks' process time on the workers plus the client's; "
              'what a worker process spends between tasks (heartbeats, scheduling '
              'messages) is not in it, and shows in the wall time.',
              *_median_lines(results),
              *_parts_lines(results, best['1']),
              *_floor_lines(results),
              f'- Scaling 1 -> 2 workers: x{s["scaling"]:.2f} (goal >= '
              f'{GOALS["scaling_2_workers"]}): **{word[met["scaling"]]}**.',
              '- Peak RSS of one worker: ' + ', '.join(
                  f'{m["peak_rss_mb"]:.0f} MB on {m["passes"]} passes' for m in mem)
              + f' (goal: flat, < {GOALS["peak_rss_mb"]:.0f} MB): **{word[met["memory"]]}**'
              + " (the worker's own high-water mark, VmHWM).",
              f'- Events: detect {s["events"]["detect"]}, fleet {s["events"]["fleet_1"]} '
              f'(1 worker), {s["events"]["fleet_2"]} (2 workers).']
    for before in results.get('previous') or []:
        was = before['summary']
        lines += [f'- Earlier full run (commit {before["commit"]}, load '
                  f'{before["load_average_before"][0]:.1f} before, '
                  f'{before["load_average_after"][0]:.1f} after): overhead '
                  f'{100 * was["overhead_wall"]:+.0f} % wall, {100 * was["overhead_cpu"]:+.0f} '
                  f'% CPU; scaling x{was["scaling"]:.2f}; samples per CPU second per worker '
                  f'{was["per_worker_cpu_rate"]["1"]:.3g} (1 worker).']
    command = typical(results['command'])
    hours = s.get('marginal_year_hours', s['command_fleet_year_hours'])
    year = fleet_year_samples()
    lines += ['', f'Whole command, as a user runs it (`rwa-monitor fleet ARCHIVE -o OUT '
              f'--workers 2`: a new process, its cluster, imports, outputs; median of '
              f'{len(results["command"])}, the three sizes below run in turn): '
              f'{command["wall_s"]:.1f} s for '
              f'{command["wheel_samples"]:.3g} wheel samples = {s["command_rate"]:.3g} wheel '
              f'samples/s (a fleet-year at that rate: {s["command_fleet_year_hours"]:.3g} h, '
              "the command's fixed start-up counted once per week of this archive)."]
    if 'marginal_rate' in s:
        long = typical(results['command_long'])
        few = typical(results['command_few'])
        crafts = FLEET_YEAR['spacecraft']
        lines += ['', f'The same {results["simulate_long"]["spacecraft"]} spacecraft over '
                  f'{results["simulate_long"]["days"]:g} days (seed 29): '
                  f'{long["wall_s"]:.1f} s for {long["wheel_samples"]:.3g} wheel samples; '
                  f'the first {FEW_SPACECRAFT} spacecraft of the 7-day archive: '
                  f'{few["wall_s"]:.1f} s for {few["wheel_samples"]:.3g} (medians). Time = '
                  f'c0 + c1 x spacecraft + samples / rate, the rate and c1 from the median '
                  f"of the rounds' differences (the sizes of a round ran one after the "
                  f'other: long - short {_differences(results, "command_long", "command")}; '
                  f'short - few {_differences(results, "command", "command_few")}): '
                  f'rate = {s["marginal_rate"]:.3g} wheel '
                  f'samples/s, c1 = {s["per_spacecraft_s"]:.3f} s per spacecraft (its '
                  f'scan, task, state, outputs and plots, whatever its days), c0 = '
                  f'{s["fixed_s"]:.1f} s (process, cluster, imports). A fleet-year '
                  f'({crafts} spacecraft, {year:.3g} wheel samples) in one command: '
                  f'({s["fixed_s"]:.1f} + {s["per_spacecraft_s"]:.3f} x {crafts} + '
                  f'{year:.3g} / {s["marginal_rate"]:.3g}) / 3600 = '
                  f'**{s["marginal_year_hours"]:.3g} h** on this 2-core machine (goal <= '
                  f'{GOALS["fleet_year_hours"]:g} h: '
                  f'**{word[hours <= GOALS["fleet_year_hours"]]}**).']
        daily = results.get('daily')
        if daily and 'daily_runs_year_hours' in s:
            day = daily['day2']
            lines += ['', f'Daily `--state` runs, measured: {daily["spacecraft"]} spacecraft '
                      f'(seed 31, 6 passes a day each), day 1 run '
                      f'({daily["day1"]["wall_s"]:.1f} s), then the archive with day 2 added '
                      f'and the same state: {day["wall_s"]:.1f} s (median of '
                      f'{len(daily.get("day2_runs", [day]))} runs, each from a copy of the '
                      f'state) for '
                      f'{day["wheel_samples"]:.3g} new wheel samples. A day of continuous '
                      f'telemetry ({FLEET_YEAR["wheels"]} wheels x '
                      f'{FLEET_YEAR["rate_hz"]:g} Hz x 86400 s a spacecraft) instead of its '
                      f'passes, at the rate above: {s["daily_day_s"]:.1f} s a day; x '
                      f'{FLEET_YEAR["days"]} days = **{s["daily_runs_year_hours"]:.3g} h** '
                      f'(goal <= {GOALS["fleet_year_hours"]:g} h: '
                      f'**{word[s["daily_runs_year_hours"] <= GOALS["fleet_year_hours"]]}** '
                      'before the growth below). '
                      f'The c0 + c1 model above would say '
                      f'{s["daily_model_year_hours"]:.3g} h: its c1 holds the plots of wheels '
                      'with events, which grow with the days, not the spacecraft. Not '
                      "counted here: what a day's run reads and rewrites that grows through "
                      "the year (the archive's passes and the state's pass records, the "
                      'history and trend tables); `python -m bench fleet_year` measures what '
                      'they add (section "A daily fleet run late in the year"), and the two '
                      'together are the daily-run figure.']
    lines += ['',
              f'Start-up, median of 5 (goal <= {GOALS["start_s"]} s each): ' + ', '.join(
                  f'`{k}` {v:.2f} s' for k, v in results['start'].items())
              + f': **{word[s["slowest_start_s"] <= GOALS["start_s"]]}**.']
    p = s['projection']
    lines += ['', f'Engine-only projection: 100 spacecraft x 4 wheels x 10 Hz x 365.25 d x '
              f'86400 s = {p["samples"]:.3g} wheel samples; measured rate per worker '
              f'{p["rate_per_worker"]:.3g} samples/s (warm 2-worker run: samples / wall / 2); '
              'time = samples / (K x rate), assuming the per-worker rate holds as K grows '
              '(400 independent wheel chains to share out):', '']
    lines += [report.table(['workers K', 'arithmetic', 'hours'],
                           [[k, f'{p["samples"]:.3g} / ({k} x {p["rate_per_worker"]:.3g}) '
                             f'/ 3600', f'{h:.3g}'] for k, h in p['hours'].items()])]
    return '\n'.join(lines)


def _median_lines(results: dict[str, Any]) -> list[str]:
    """Return the bullet of the CPU ratio from the medians of all runs (not the best's)."""
    s = results['summary']
    if 'overhead_cpu_median' not in s:
        return []
    runs = results['fleet']['1']
    cpu = [r['cpu_s'] + r['client_cpu_s'] for r in runs]
    ok = s['overhead_cpu_median'] <= GOALS['overhead']
    return [f'- The same CPU ratio from the medians of the runs (steadier): fleet 1 worker '
            f'{np.median(cpu):.2f} s (steps {np.median([r["cpu_s"] for r in runs]):.2f} + '
            f'client {np.median([r["client_cpu_s"] for r in runs]):.2f}; {len(runs)} runs, '
            f'{min(cpu):.2f}-{max(cpu):.2f}), `detect` {results["detect"]["cpu_s"]:.2f} s '
            f'(runs: {len(results["detect"].get("cpu_runs", [0]))}): '
            f'{100 * s["overhead_cpu_median"]:+.0f} % (goal <= '
            f'{100 * GOALS["overhead"]:.0f} %): **{"met" if ok else "not met"}**.'
            + _whole_text(s)]


def _whole_text(summary: dict[str, Any]) -> str:
    if 'overhead_cpu_whole_median' not in summary:
        return ''
    ok = summary['overhead_cpu_whole_median'] <= GOALS['overhead']
    return (' Counting the whole processes (the worker process with its scan tasks and '
            "Dask's work between tasks, plus the client): "
            f'{summary["whole_cpu_median_s"]:.2f} s, '
            f'{100 * summary["overhead_cpu_whole_median"]:+.0f} %: '
            f'**{"met" if ok else "not met"}**.')


def _parts_lines(results: dict[str, Any], one: dict[str, Any]) -> list[str]:
    """Return the bullet of the in-process split (bench/fleet_parts.py), if it was run."""
    p = results.get('parts')
    if not p:
        return []
    engine = one['cpu_s'] + one['client_cpu_s']
    return [f'- In one process without Dask (bench/fleet_parts.py; CPU s, median of '
            f'{results["settings"].get("parts_repeats", "?")} warm runs): `detect` '
            f'{p["detect"]:.2f} (reading the joined files {p["detect_read"]:.2f}, detecting '
            f'{p["detect_detect"]:.2f}); the steps of every spacecraft {p["step"]:.2f} '
            f'({100 * (p["step"] / p["detect"] - 1):+.0f} %: reading the '
            f'{results["simulate"]["passes"]} passes {p["step_read"]:.2f}, feeding the '
            f'runners {p["step_feed"]:.2f}, trend levels {p["step_trend"]:.2f}, the rest '
            f'{p["step_rest"]:.2f}; without the trend levels '
            f'{100 * ((p["step"] - p["step_trend"]) / p["detect"] - 1):+.0f} %); the scan of '
            f'the plan {p["scan"]:.2f} (on the workers, not in the CPU above). The trend '
            f'levels alone are {100 * p["step_trend"] / p["detect"]:.0f} % of `detect`. '
            f'The cluster adds {engine - p["step"]:.2f} s to the '
            'steps (the CPU of the 1-worker run less the steps in one process). Where it '
            'goes and what bounds it: docs/fleet.md "CPU against detect".']


def _floor_lines(results: dict[str, Any]) -> list[str]:
    """Return the bullet of Dask's own CPU at the run's size and the bound it sets."""
    floors = [r['floor'] for r in results['fleet']['1'] if 'floor' in r]
    p = results.get('parts')
    if not floors or not p:
        return []
    client = float(np.median([f['client_cpu_s'] for f in floors]))
    workers = float(np.median([f['worker_process_cpu_s'] for f in floors]))
    bound = p['step'] + client + workers
    detect = results['detect']['cpu_s']
    tasks = floors[0]['tasks']
    return ['- What Dask costs at this size with nothing computed (bench/fleet_parts.py '
            f'`dask_floor`: after each 1-worker run, {tasks} tasks that sleep '
            f'through its wall time on the same cluster; median of {len(floors)}): the '
            f'client process {client:.2f} s, the worker process {workers:.2f} s: '
            f'{100 * (client + workers) / detect:.0f} % of `detect` ({detect:.2f} s) for '
            f'the cluster alone. With the steps in one process ({p["step"]:.2f} s) the '
            f'fleet on Dask costs no less than {bound:.2f} s, '
            f'{100 * (bound / detect - 1):+.0f} % over `detect`.']


def _plot(out_dir: pathlib.Path, results: dict[str, Any]) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from rwa_monitor.telemetry.atomic import atomic_write
    s = results['summary']
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    names = ['detect', 'fleet 1w', 'fleet 2w']
    best = {k: min(v, key=lambda r: r['wall_s']) for k, v in results['fleet'].items()}
    left.bar(names, [results['detect']['wall_s'], best['1']['wall_s'], best['2']['wall_s']])
    left.set_ylabel('wall time (s)')
    left.set_title(f'{s["samples"]:.3g} wheel samples')
    mem = results['memory']
    right.plot([m['passes'] for m in mem], [m['peak_rss_mb'] for m in mem], 'o-')
    right.axhline(GOALS['peak_rss_mb'], color='C3', ls=':', label='goal')
    right.set_xlabel('passes in the archive')
    right.set_ylabel('peak RSS of the worker (MB)')
    right.set_ylim(0, None)
    right.legend()
    fig.tight_layout()
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_write(out_dir / 'fleet.png', 'wb', encoding=None) as handle:
        fig.savefig(handle, format='png', dpi=90)
    plt.close(fig)
