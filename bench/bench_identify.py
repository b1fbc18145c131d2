"""Identification benchmark: measured coast-downs, undeclared effects, speed, LLR demo.

1. Measured: every usable run of ../shared/data/measured/drum-coastdown (read in place;
   per-run reports go to a temporary folder outside the repository; only summary numbers
   and one plot are kept). Source: github.com/hpvdt/rolling_resistance_rig (SOURCE.md).
2. Undeclared effects: simulated files (sim/undeclared.py), several seeds each.
3. Speed: a 3-hour 10 Hz file (108,000 samples), prepare + identify, goal < 10 s.
4. Closing demonstration: identify on a nominal file with undeclared drag, then run the
   LLR detector with the baseline and the refined model on files with the same drag and
   one injected dry-friction step: false alarms, and whether the step is detected.
"""

from __future__ import annotations

import json
import pathlib
import statistics
import subprocess
import tempfile
import time
from typing import Any

import numpy as np

from bench.report import table, update_section, write_json
from rwa_monitor.core.identify.data import prepare
from rwa_monitor.core.identify.model import regressors_from_config, snippet
from rwa_monitor.core.identify.select import identify
from rwa_monitor.pipelines.identify_report import write_outputs
from rwa_monitor.sim.undeclared import EFFECTS, simulate_undeclared
from rwa_monitor.telemetry import read_telemetry
from rwa_monitor.telemetry.coastdown import coastdown_runs, pendulum_inertia, read_coastdown

MEASURED = pathlib.Path(__file__).resolve().parents[2].parent / 'shared' / 'data' / \
    'measured' / 'drum-coastdown'
NOT_A_FREE_COAST = ('Samplewheel_29',)   # SOURCE.md: decelerates ten times faster
EXPECTED = {'none': '(none)', 'stribeck': 'stribeck', 'drag': 'drag',
            'temperature': 'aux:rw1_temperature:dry', 'drift': 'drift', 'periodic': 'periodic'}


def _measured(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    if not MEASURED.exists():
        return {'skipped': f'{MEASURED} absent'}
    runs = [(r, b) for r, b, _ in coastdown_runs(MEASURED)
            if not r.startswith(NOT_A_FREE_COAST)]
    if quick:
        runs = runs[:3]
    inertia = {b: pendulum_inertia(MEASURED, b) for b in ('drum', 'wheel')}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for run, body in runs:
            sel = identify(prepare(read_coastdown(MEASURED, run, body), body, inertia[body]))
            rep = write_outputs(sel, pathlib.Path(tmp) / f'{run}-{body}', f'{run} {body}')
            params = {e['name']: e['parameters'] for e in rep['effects']}
            weights = snippet(sel)['friction_model']['weights']
            rows.append({'run': run.replace('__Separate__', ' ').replace('.csv', ''),
                         'body': body, 'samples': len(sel.data),
                         'noise_floor': rep['noise_floor'],
                         'rmse_before': rep['rmse_before'], 'rmse_after': rep['rmse_after'],
                         'jumps': len(sel.segments.starts) - 1,
                         'effects': [e['name'] for e in rep['effects']],
                         'dry': rep['baseline']['parameters']['dry'],
                         'viscous': rep['baseline']['parameters']['viscous'],
                         'refined_dry': weights['dry'], 'refined_viscous': weights['viscous'],
                         'drag_exponent': params.get('drag', {}).get('exponent'),
                         'drag_coefficient': params.get('drag', {}).get('coefficient')})
    return {'inertia_kg_m2': inertia, 'runs': rows}


def _pooled(rows: list[dict]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key in ('rmse_before', 'rmse_after'):
        for part in ('in_sample', 'held_out'):
            num = sum(r['samples'] * r[key][part] ** 2 for r in rows)
            out[f'{key}_{part}'] = float(np.sqrt(num / sum(r['samples'] for r in rows)))
    counts: dict[str, int] = {}
    for r in rows:
        for name in r['effects']:
            counts[name] = counts.get(name, 0) + 1
    out['effect_counts'] = counts
    for key in ('drag_exponent', 'drag_coefficient', 'dry', 'viscous', 'refined_dry',
                'refined_viscous'):
        values = [r[key] for r in rows if r[key] is not None and r['body'] == 'drum']
        if len(values) >= 2:
            q1, med, q3 = np.percentile(values, [25, 50, 75])
            out[key] = {'median': float(med), 'q1': float(q1), 'q3': float(q3),
                        'n': len(values)}
    return out


def _undeclared(quick: bool) -> list[dict]:
    seeds = range(21, 22 if quick else 26)
    rows = []
    for effect in EFFECTS:
        for seed in seeds:
            data = prepare(simulate_undeclared(effect, seed=seed))
            sel = identify(data)
            names = [e.name for e in sel.effects]
            rows.append({'effect': effect, 'seed': seed, 'found': names,
                         'noise_floor': data.noise_floor,
                         'held_out_before': sel.baseline_fit.rmse_held_out,
                         'held_out_after': sel.final_fit.rmse_held_out,
                         'ratio_after': sel.final_fit.rmse_held_out / data.noise_floor,
                         'jumps': len(sel.segments.starts) - 1})
    return rows


def _basilisk(quick: bool) -> dict[str, Any]:
    """Identify every wheel of a Basilisk bus file (its Stribeck friction undeclared)."""
    exe = pathlib.Path(__file__).resolve().parents[2] / '.venv-bsk' / 'bin' / 'rwa-monitor'
    if not exe.exists():
        return {'skipped': 'the optional Basilisk environment (.venv-bsk) is absent'}
    out: dict[str, Any] = {'seconds_simulated': 900.0 if quick else 3600.0, 'wheels': {}}
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / 'bus.csv'
        subprocess.run([str(exe), 'simulate', 'basilisk', '--seconds',
                        str(out['seconds_simulated']), '--seed', '1', '-o', str(path)],
                       check=True, capture_output=True)
        tele = read_telemetry(path)
        for wheel in tele.wheels:
            data = prepare(tele, wheel)
            sel = identify(data)
            out['wheels'][wheel] = {
                'noise_floor': data.noise_floor,
                'held_out_before': sel.baseline_fit.rmse_held_out,
                'held_out_after': sel.final_fit.rmse_held_out,
                'effects': [e.name for e in sel.effects],
                'jumps': len(sel.segments.starts) - 1,
                'low_speed_share': float(np.mean(np.abs(data.speed) < 2.0))}
    return out


def _speed(quick: bool) -> dict[str, Any]:
    n = 20000 if quick else 108000
    out = {}
    for effect in ('drag', 'temperature'):
        tele = simulate_undeclared(effect, n=n, dt=0.1, seed=7)
        start = time.perf_counter()
        sel = identify(prepare(tele))
        out[effect] = {'samples': n, 'seconds': time.perf_counter() - start,
                       'effects': [e.name for e in sel.effects]}
    return out


def _demo(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    from rwa_monitor.core.llr import detect_batch
    n, step_time, step, window, rate = 10000, 6000.0, 3.0e-4, 500, 1e-4
    train = prepare(simulate_undeclared('drag', n=n, seed=100))
    sel = identify(train)
    refined = regressors_from_config(snippet(sel))
    seeds = range(200, 201 if quick else 210)
    runs = []
    for seed in seeds:
        tele = simulate_undeclared('drag', n=n, seed=seed, anomaly_time=step_time,
                                   anomaly_dry=step)
        wheel = tele.wheels['rw1']
        for name, regs in (('baseline', None), ('refined', refined)):
            start = time.perf_counter()
            events = [e for e in detect_batch(tele.time, wheel.speed, wheel.friction,
                                              window=window, false_alarm_rate=rate,
                                              noise_std=train.noise_floor, regressors=regs,
                                              aux=tele.aux) if e.revision == 0]
            hit = [e for e in events if abs(e.time - step_time) <= window]
            runs.append({'model': name, 'seed': seed, 'events': len(events),
                         'false_alarms': len(events) - min(len(hit), 1),
                         'detected': bool(hit), 'seconds': time.perf_counter() - start,
                         'event_times': [e.time for e in events]})
    summary = {}
    for name in ('baseline', 'refined'):
        rs = [r for r in runs if r['model'] == name]
        fa = sum(r['false_alarms'] for r in rs)
        summary[name] = {'false_alarms': fa, 'samples': n * len(rs),
                         'false_alarms_per_sample': fa / (n * len(rs)),
                         'detected': sum(r['detected'] for r in rs), 'files': len(rs)}
    _plot_demo(out_dir, runs, step_time, n)
    return {'model': list(refined.names), 'rate': rate, 'window': window, 'step_nm': step,
            'step_time_s': step_time, 'runs': runs, 'summary': summary}


def _plot_demo(out_dir: pathlib.Path, runs: list[dict], step_time: float, n: int) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9, 2.8))
    for i, r in enumerate(runs):
        y = i + (0.0 if r['model'] == 'baseline' else 0.0)
        ax.plot(r['event_times'], [y] * len(r['event_times']), 'x' if
                r['model'] == 'baseline' else 'o', color='C3' if r['model'] == 'baseline'
                else 'C2')
    ax.axvline(step_time, color='k', ls='--', label='injected dry step')
    ax.set_yticks(range(len(runs)), [f'{r["model"]} s{r["seed"]}' for r in runs], fontsize=7)
    ax.set_xlim(0, n)
    ax.set_xlabel('time (s)')
    ax.set_title('LLR events (first declarations): baseline vs refined friction model')
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / 'identify_demo.png', dpi=90)
    plt.close(fig)


def _plot_measured(out_dir: pathlib.Path, rows: list[dict]) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4))
    x = np.arange(len(rows))
    a.bar(x - 0.2, [r['rmse_before']['held_out'] for r in rows], 0.4, label='baseline')
    a.bar(x + 0.2, [r['rmse_after']['held_out'] for r in rows], 0.4, label='refined')
    a.plot(x, [r['noise_floor'] for r in rows], 'k_', ms=8, label='noise floor')
    a.set_yscale('log')
    a.set_xlabel('run')
    a.set_ylabel('held-out RMSE (N m)')
    a.legend(fontsize=7)
    a.set_title('measured coast-downs: held-out RMSE per run')
    exps = [r['drag_exponent'] for r in rows if r['drag_exponent'] is not None]
    b.hist(exps, bins=np.arange(1.0, 4.5, 0.25) - 0.125)
    b.set_xlabel('drag exponent selected')
    b.set_title(f'drag found in {len(exps)} of {len(rows)} runs')
    fig.tight_layout()
    fig.savefig(out_dir / 'identify_measured.png', dpi=90)
    plt.close(fig)


def run(out_dir: pathlib.Path, quick: bool) -> dict:
    """Run the benchmark; write JSON, plots and the identify section of docs/results.md."""
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {'quick': quick}
    results['measured'] = _measured(out_dir, quick)
    if 'runs' in results['measured']:
        results['measured']['pooled'] = _pooled(results['measured']['runs'])
        _plot_measured(out_dir, results['measured']['runs'])
    results['undeclared'] = _undeclared(quick)
    results['basilisk'] = _basilisk(quick)
    results['speed'] = _speed(quick)
    results['demo'] = _demo(out_dir, quick)
    write_outputs(identify(prepare(simulate_undeclared('drag', seed=1))),
                  out_dir / 'identify_example_drag', 'simulated drag (undeclared)')
    write_json(out_dir, 'identify', results)
    update_section('identify', _markdown(results))
    return results


def _markdown(res: dict) -> str:
    lines = ['## identify: closing the loop (issue 7)', '',
             '`python -m bench identify`'
             + (' --quick (smoke run, not a result)' if res['quick'] else '') + '. '
             'Method and decisions: docs/identify.md. RMSE in N m; "held out" = the '
             'interleaved blocks not used for fitting.', '']
    m = res['measured']
    if 'runs' in m:
        p = m['pooled']
        lines += ['### Measured coast-downs (drum-coastdown folder, read in place; source '
                  'github.com/hpvdt/rolling_resistance_rig, see its SOURCE.md)', '',
                  f'Inertia from the pendulum swings: drum {m["inertia_kg_m2"]["drum"]:.2f} '
                  f'kg m^2 (SOURCE.md: about 26.4), wheel {m["inertia_kg_m2"]["wheel"]:.4f} '
                  f'kg m^2 (about 0.090). Friction = J dw/dt (local quadratic, 11 '
                  f'revolutions). Samplewheel_29 left out (not a free coast).', '',
                  table(['run', 'body', 'n', 'noise floor', 'held-out before',
                         'held-out after', 'in-sample before', 'in-sample after', 'jumps',
                         'effects (in order)'],
                        [[r['run'], r['body'], r['samples'], r['noise_floor'],
                          r['rmse_before']['held_out'], r['rmse_after']['held_out'],
                          r['rmse_before']['in_sample'], r['rmse_after']['in_sample'],
                          r['jumps'], ', '.join(r['effects']) or '(none)']
                         for r in m['runs']]), '',
                  f'Pooled over {len(m["runs"])} runs (sample-weighted RMS): held out '
                  f'{p["rmse_before_held_out"]:.4g} -> {p["rmse_after_held_out"]:.4g}, in sample '
                  f'{p["rmse_before_in_sample"]:.4g} -> {p["rmse_after_in_sample"]:.4g}. '
                  f'Effects found (runs): {json.dumps(p["effect_counts"])}.', '']
        spread = [[k, v['n'], v['median'], v['q1'], v['q3']] for k, v in p.items()
                  if isinstance(v, dict) and 'median' in v]
        lines += ['Spread across drum runs (different tyres and pressures load the drum '
                  'differently, so a spread is expected):', '',
                  table(['parameter', 'runs', 'median', 'q1', 'q3'], spread), '',
                  '![measured](../bench/results/identify_measured.png)', '']
    else:
        lines += [f'Measured data: {m["skipped"]}.', '']
    und = res['undeclared']
    rows = []
    for effect in EFFECTS:
        rs = [r for r in und if r['effect'] == effect]
        want = EXPECTED[effect]
        ok = sum((r['found'][:1] == [want]) if effect != 'none' else not r['found']
                 for r in rs)
        fb = sum(r['found'][:1] == ['smooth_speed'] for r in rs)
        rows.append([effect, want, f'{ok}/{len(rs)}', fb,
                     statistics.median(r['held_out_before'] / r['noise_floor'] for r in rs),
                     max(r['ratio_after'] for r in rs),
                     sum(r['jumps'] for r in rs)])
    lines += ['### Undeclared effects (simulated, 10,000 samples at 1 Hz, noise 5e-5 N m)', '',
              table(['effect', 'expected name', 'found first', 'via fallback',
                     'median held-out before / floor', 'max held-out after / floor',
                     'false jumps'], rows), '',
              'Goal: found, held-out RMSE after <= 1.10 x noise floor; the no-effect file '
              'keeps the baseline.', '']
    b = res['basilisk']
    if 'wheels' in b:
        lines += ['### Basilisk bus telemetry (its Stribeck friction is not declared)', '',
                  f'`rwa-monitor simulate basilisk --seconds {b["seconds_simulated"]:g} '
                  f'--seed 1` (4 Hz; Coulomb 5e-4, breakaway 8e-4 N m at a Stribeck speed '
                  f'of 1 rad/s, a friction band of +-0.1 rad/s around zero, noise 5e-5 N m).',
                  '', table(['wheel', 'noise floor', 'held-out before', 'held-out after',
                             'after / floor', 'share abs(w) < 2 rad/s', 'effects (in order)'],
                            [[k, v['noise_floor'], v['held_out_before'], v['held_out_after'],
                              v['held_out_after'] / v['noise_floor'], v['low_speed_share'],
                              ', '.join(v['effects']) or '(none)']
                             for k, v in b['wheels'].items()]), '']
    else:
        lines += [f'Basilisk telemetry: {b["skipped"]}.', '']
    sp = res['speed']
    lines += ['### Speed', '',
              table(['file', 'samples', 'identify time (s)', 'goal', 'effects'],
                    [[k, v['samples'], v['seconds'], '< 10 s', ', '.join(v['effects'])]
                     for k, v in sp.items()]), '']
    d = res['demo']
    s = d['summary']
    lines += ['### Closing demonstration: LLR false alarms, baseline vs refined model', '',
              f'Model identified on a nominal file with undeclared drag: {d["model"]}. '
              f'Test files: same drag, one dry step of {d["step_nm"]:g} N m at '
              f't = {d["step_time_s"]:g} s; LLR window {d["window"]}, r = {d["rate"]:g}.', '',
              table(['model', 'files', 'false alarms', 'per sample', 'nominal r',
                     'step detected'],
                    [[k, v['files'], v['false_alarms'], v['false_alarms_per_sample'],
                      d['rate'], f'{v["detected"]}/{v["files"]}'] for k, v in s.items()]), '',
              '![demo](../bench/results/identify_demo.png)', '']
    return '\n'.join(lines)
