"""``python -m bench llr_power``: LLR detection against fault size, ROC, Figs. 6-7, kinds.

Sections: probability of detection, delay and kind against the step size (dry, viscous,
both) on the Fig. 3 profile with the smallest change found in >= 90 % of runs; ROC
(detection against false alarms per hour as r varies); the llr-realtime paper's Figs.
6-7 experiment (w_k = 100 - k/1250, dry +0.3; detection over time for three windows and
three r); categorisation against the post-change speed variation on the realistic SI
profile. Scoring seeds 3000 and up, chosen before the results (development: 1-99).
"""

from __future__ import annotations

import math
import multiprocessing
import pathlib
import subprocess
import time
from typing import Any

import numpy as np

from bench import llr_power, report

WORKERS = 2
SEED0 = 3000
CHANGE = 1500
# Size runs: the kind is re-checked at 2, 4, 8 x ~760 samples after the change (8 L0 < 6500).
SIZE_N = 8000
TOL = 500
SIZES = {'dry': [(s, 0.0) for s in (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7)],
         'viscous': [(0.0, s) for s in (0.005, 0.0075, 0.01, 0.015, 0.02, 0.025, 0.035)],
         'both': [(s, s / 20.0) for s in (0.05, 0.075, 0.1, 0.15, 0.2, 0.25, 0.35, 0.5)]}
ROC_RATES = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
ROC_STEPS = {'dry': (0.2, 0.0), 'viscous': (0.0, 0.01)}
FIG6_WINDOWS = (250, 500, 1000)
FIG7_RATES = (1e-3, 1e-4, 1e-5)
REALISTIC = {'dry': (1e-4, 0.0), 'viscous': (0.0, 3e-7), 'both': (1e-4, 3e-7)}
SPEED_BINS = (0.0, 10.0, 30.0, 100.0, math.inf)


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'size_runs': 4, 'roc_runs': 2, 'roc_nominal': 2, 'fig67_runs': 4,
                'real_runs': 3}
    return {'size_runs': 40, 'roc_runs': 30, 'roc_nominal': 10, 'fig67_runs': 100,
            'real_runs': 60}


def _params(window: int = 500, rate: float = 1e-5, noise_std: float | None = None):
    return {'window': window, 'k_verif': window // 2, 'false_alarm_rate': rate,
            'noise_std': noise_std}


def _tasks(s: dict[str, Any]) -> list[dict[str, Any]]:
    tasks = []
    for kind, sizes in SIZES.items():
        for i, (d, v) in enumerate(sizes):
            tasks += [{'part': 'size', 'kind': kind, 'size_index': i, 'profile': 'fig3',
                       'n': SIZE_N, 'seed': SEED0 + j, 'dry': d, 'viscous': v,
                       'change': CHANGE, 'tol': TOL, 'params': _params()}
                      for j in range(s['size_runs'])]
    for rate in ROC_RATES:
        tasks += [{'part': 'roc_nominal', 'rate': rate, 'profile': 'fig3', 'n': 20_000,
                   'seed': SEED0 + 500 + j, 'dry': 0.0, 'viscous': 0.0,
                   'params': _params(rate=rate)} for j in range(s['roc_nominal'])]
        for kind, (d, v) in ROC_STEPS.items():
            tasks += [{'part': 'roc', 'rate': rate, 'kind': kind, 'profile': 'fig3',
                       'n': 4000, 'seed': SEED0 + 1000 + j, 'dry': d, 'viscous': v,
                       'change': CHANGE, 'tol': TOL, 'params': _params(rate=rate)}
                      for j in range(s['roc_runs'])]
    configs = [('fig6', w, 1e-4) for w in FIG6_WINDOWS] + [('fig7', 500, r) for r in FIG7_RATES]
    for fig, w, rate in configs:
        tasks += [{'part': fig, 'window': w, 'rate': rate, 'kind': 'dry', 'profile': 'fig6',
                   'n': CHANGE + 3000, 'seed': SEED0 + 2000 + j, 'dry': 0.3, 'viscous': 0.0,
                   'change': CHANGE, 'tol': TOL, 'curve': True,
                   'params': _params(w, rate, 1.0)} for j in range(s['fig67_runs'])]
    for kind, (d, v) in REALISTIC.items():
        tasks += [{'part': 'realistic', 'kind': kind, 'dry': d, 'viscous': v,
                   'n': 30_000, 'change_s': 1200.0, 'seed': SEED0 + 3000 + j}
                  for j in range(s['real_runs'])]
    return tasks


def _run(task: dict[str, Any]) -> dict[str, Any]:
    func = llr_power.realistic_task if task['part'] == 'realistic' else llr_power.paper_task
    out = dict(task, **func(task))
    out.pop('params', None)
    return out


def _kinds(rows: list[dict[str, Any]]) -> dict[str, float]:
    hits = [r for r in rows if r['detected']]
    n = max(len(hits), 1)
    return {c: sum(r.get('kind_class') == c for r in hits) / n
            for c in ('right', 'undecided', 'wrong')} | {
        'guess_right': sum(r.get('guess_right', False) for r in hits) / n}


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Return the tables and curves from the task results."""
    out: dict[str, Any] = {'size': {}, 'roc': {}, 'fig67': {}, 'realistic': []}
    for kind, sizes in SIZES.items():
        rows = []
        for i, (d, v) in enumerate(sizes):
            sel = [r for r in results if r['part'] == 'size' and r['kind'] == kind
                   and r['size_index'] == i]
            delays = [r['delay'] for r in sel if r['detected']]
            rows.append({'dry': d, 'viscous': v, 'runs': len(sel),
                         'p_detect': sum(r['detected'] for r in sel) / len(sel),
                         'median_delay': float(np.median(delays)) if delays else math.nan,
                         **_kinds(sel)})
        size_axis = [max(r['dry'], r['viscous']) for r in rows]
        out['size'][kind] = {'rows': rows, 'smallest_90': llr_power.smallest(
            size_axis, [r['p_detect'] for r in rows])}
    for rate in ROC_RATES:
        nominal = [r for r in results if r['part'] == 'roc_nominal' and r['rate'] == rate]
        hours = sum(r['samples'] for r in nominal) / 3600.0
        alarms = sum(r['alarms'] for r in nominal)
        row = {'rate': rate, 'false_per_hour': alarms / hours, 'alarms': alarms,
               'hours': hours}
        for kind in ROC_STEPS:
            sel = [r for r in results if r['part'] == 'roc' and r['rate'] == rate
                   and r['kind'] == kind]
            row[f'p_detect_{kind}'] = sum(r['detected'] for r in sel) / len(sel)
        out['roc'][f'{rate:g}'] = row
    horizon = np.arange(0, 3001, 100)
    for fig, key, values in (('fig6', 'window', FIG6_WINDOWS), ('fig7', 'rate', FIG7_RATES)):
        curves = {}
        for value in values:
            sel = [r for r in results if r['part'] == fig and r[key] == value]
            first = [min(r['declared']) - CHANGE if r.get('declared') else math.inf
                     for r in sel]
            curves[f'{value:g}'] = {
                'p_by_delay': [float(np.mean([d <= h for d in first])) for h in horizon],
                'p_detect': sum(r['detected'] for r in sel) / len(sel),
                **_kinds(sel)}
        out['fig67'][fig] = {'horizon': horizon.tolist(), 'curves': curves}
    for kind in REALISTIC:
        for lo, hi in zip(SPEED_BINS[:-1], SPEED_BINS[1:]):
            sel = [r for r in results if r['part'] == 'realistic' and r['kind'] == kind
                   and lo <= r['speed_std_after'] < hi]
            if not sel:
                continue
            out['realistic'].append({'kind': kind, 'speed_std_lo': lo, 'speed_std_hi': hi,
                                     'runs': len(sel),
                                     'p_detect': sum(r['detected'] for r in sel) / len(sel),
                                     **_kinds(sel)})
    return out


def markdown(res: dict[str, Any]) -> str:
    """Return the docs/results.md section."""
    lines = ['## LLR: detection against fault size, ROC, Figs. 6-7, kinds '
             '(`python -m bench llr_power`)', '',
             f'Code commit `{res["commit"]}`; seeds {SEED0} and up (chosen before the '
             'results). Default detector (noise level estimated, AR prewhitening), '
             'w = 500, k_verif = 250, Fig. 3 profile (scaled units, unit noise, x0 = (4, '
             f'0.01)), change at k = {CHANGE}, {SIZE_N} samples per run (the kind is '
             're-checked 2, 4, 8 L0 ~ 1500, 3000, 6000 samples after the change); detected = '
             f'a first declaration within {TOL} samples of the change. Kind of the last '
             'revision: right (confirmed, correct), undecided, wrong (confirmed, incorrect; '
             'for `both`, mostly a minor component below the `detectable_*` size the event '
             'states); guess = kind or, for undecided, its `kind_guess`. Rule and limits: '
             'docs/llr.md "Categorisation".', '']
    for kind, block in res['size'].items():
        rows = [[f'{r["dry"]:g}', f'{r["viscous"]:g}', r['runs'], f'{r["p_detect"]:.2f}',
                 f'{r["median_delay"]:.0f}', f'{r["right"]:.2f}', f'{r["undecided"]:.2f}',
                 f'{r["wrong"]:.2f}', f'{r["guess_right"]:.2f}'] for r in block['rows']]
        lines += [f'**{kind}** (r = 1e-5): smallest step detected in >= 90 % of runs: '
                  f'{block["smallest_90"]:g}', '',
                  report.table(['dry', 'viscous', 'runs', 'P(detect)', 'median delay',
                                'right', 'undecided', 'wrong', 'guess right'], rows), '']
    rows = [[k, f'{r["false_per_hour"]:.3g}', f'{r["alarms"]} / {r["hours"]:.0f} h',
             f'{r["p_detect_dry"]:.2f}', f'{r["p_detect_viscous"]:.2f}']
            for k, r in res['roc'].items()]
    lines += ['**ROC** (Fig. 3 profile at 1 Hz; false alarms from nominal runs of 20,000 '
              f'samples; detection of dry +{ROC_STEPS["dry"][0]:g} and viscous '
              f'+{ROC_STEPS["viscous"][1]:g}); plot `llr_power_roc.png`.', '',
              report.table(['r', 'false alarms / h', 'alarms / hours', 'P(detect dry)',
                            'P(detect viscous)'], rows), '']
    rows = []
    for fig, block in res['fig67'].items():
        for value, c in block['curves'].items():
            rows.append([fig, value, f'{c["p_detect"]:.2f}',
                         f'{c["p_by_delay"][10]:.2f}', f'{c["p_by_delay"][20]:.2f}',
                         f'{c["right"]:.2f}', f'{c["undecided"]:.2f}', f'{c["wrong"]:.2f}',
                         f'{c["guess_right"]:.2f}'])
    lines += ['**Figs. 6-7 of the llr-realtime paper** (w_k = 100 - k/1250, dry +0.3 at '
              f'k = {CHANGE}, known unit noise as in the paper; fig6: w varies at r = 1e-4, '
              'fig7: r varies at w = 500; curves over time in `llr_power_fig67.png`). The '
              'speed barely varies after the change (100 -> 97.6 rad/s over 3000 '
              'samples), so dry and viscous cannot be told apart: undecided is the right '
              'answer.', '',
              report.table(['figure', 'w or r', 'P(detect)', 'P(by 1000)', 'P(by 2000)',
                            'right', 'undecided', 'wrong', 'guess right'], rows), '']
    rows = [[r['kind'], f'{r["speed_std_lo"]:g}-{r["speed_std_hi"]:g}', r['runs'],
             f'{r["p_detect"]:.2f}', f'{r["right"]:.2f}', f'{r["undecided"]:.2f}',
             f'{r["wrong"]:.2f}', f'{r["guess_right"]:.2f}'] for r in res['realistic']]
    lines += ['**Kinds against the post-change speed variation** (realistic SI profile, '
              '10 Hz, 3000 s, change at 1200 s: dry +1e-4 N m, viscous +3e-7 N m s, both; '
              'w = 400, r = 1e-5; bins of the std of abs(w) from the change to the end).', '',
              report.table(['change', 'post-change std of abs(w) (rad/s)', 'runs',
                            'P(detect)', 'right', 'undecided', 'wrong', 'guess right'], rows)]
    return '\n'.join(lines)


def plot(out_dir: pathlib.Path, res: dict[str, Any]) -> None:
    """Write the ROC, size and Figs. 6-7 plots."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from rwa_monitor.telemetry.atomic import atomic_write
    out_dir.mkdir(parents=True, exist_ok=True)

    def save(fig, name):
        with atomic_write(out_dir / name, 'wb', encoding=None) as handle:
            fig.savefig(handle, format='png', dpi=110)
        plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4))
    for ax, (kind, block) in zip(axes, res['size'].items()):
        x = [max(r['dry'], r['viscous']) for r in block['rows']]
        ax.plot(x, [r['p_detect'] for r in block['rows']], 'o-', label='P(detect)')
        ax.plot(x, [r['right'] for r in block['rows']], 's--', label='kind right')
        ax.plot(x, [r['undecided'] for r in block['rows']], 'x:', label='undecided')
        ax.set_title(kind)
        ax.set_xlabel('step (dry N m or viscous N m s, scaled)')
        ax.set_ylim(-0.02, 1.02)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    save(fig, 'llr_power_size.png')
    fig, ax = plt.subplots(figsize=(5, 4))
    rows = list(res['roc'].values())
    fph = [max(r['false_per_hour'], 1e-3) for r in rows]
    for kind in ROC_STEPS:
        ax.plot(fph, [r[f'p_detect_{kind}'] for r in rows], 'o-', label=kind)
    ax.set_xscale('log')
    ax.set_xlabel('false alarms per hour (1 Hz; 1e-3 = none seen)')
    ax.set_ylabel('P(detect)')
    ax.legend()
    fig.tight_layout()
    save(fig, 'llr_power_roc.png')
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, (fig_name, block) in zip(axes, res['fig67'].items()):
        for value, c in block['curves'].items():
            ax.plot(block['horizon'], c['p_by_delay'], label=value)
        ax.set_title(f'{fig_name}: P(declared by delay)')
        ax.set_xlabel('samples after the change')
        ax.legend(fontsize=7)
    fig.tight_layout()
    save(fig, 'llr_power_fig67.png')


def run(out_dir: pathlib.Path, quick: bool = False) -> dict[str, Any]:
    """Run the benchmark; write llr_power.json, plots and the docs/results.md section."""
    s = _settings(quick)
    started = time.perf_counter()
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                            text=True, cwd=report.REPO).stdout.strip()
    tasks = _tasks(s)
    tasks.sort(key=lambda t: -t['n'])
    results = []
    with multiprocessing.get_context('fork').Pool(WORKERS) as pool:
        for i, r in enumerate(pool.imap_unordered(_run, tasks, chunksize=4)):
            results.append(r)
            if (i + 1) % 200 == 0 or i + 1 == len(tasks):
                print(f'  llr_power: {i + 1}/{len(tasks)} '
                      f'({time.perf_counter() - started:.0f} s)', flush=True)
    res = {'settings': s, 'commit': commit, 'seed0': SEED0, **summarise(results),
           'bench_seconds': time.perf_counter() - started}
    plot(out_dir, res)
    report.write_json(out_dir, 'llr_power', res)
    text = markdown(res)
    if quick:
        print(text)
    else:
        report.update_section('llr_power', text)
    return res
