"""``python -m bench arl``: average run length to a false alarm beyond white noise.

Table: ARL (samples) of the LLR detector on the realistic SI profile for the noise cases
of :mod:`.llr_arl` at r = 1e-4 and 1e-5, with its 95 % lower bound, against the promise
1/r; the paper's detector (white noise, growing reference) beside it. Detection loss: the
probability and delay of detecting a dry and a viscous step per noise case, against the
white Gaussian case. Scoring seeds 2000 and up (chosen before any result was seen;
development used seeds 1-99).
"""

from __future__ import annotations

import math
import multiprocessing
import pathlib
import time
from typing import Any

import numpy as np
from scipy import stats

from bench import llr_arl, report

WORKERS = 2
RATES = (1e-4, 1e-5)
SEED0 = 2000
STEPS = {'dry': (2.5e-5, 0.0), 'viscous': (0.0, 1.5e-7)}   # 0.5 noise std; ~same torque
DETECTION = {'n': 20_000, 'at': 12_000, 'rate': 1e-5}


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'runs': 2, 'n': 100_000, 'paper_runs': 1, 'temp_runs': 1, 'temp_n': 20_000,
                'det_runs': 4, 'det_temp_runs': 2}
    # Sized for a shared 2-core machine: 1e6 samples per cell (a lower bound of 3.3e5
    # without alarms), the temperature cells (p = 3, ~5000 samples/s) too.
    return {'runs': 4, 'n': 250_000, 'paper_runs': 1, 'temp_runs': 4, 'temp_n': 250_000,
            'det_runs': 20, 'det_temp_runs': 4}


def lower_bound(samples: int, alarms: int, level: float = 0.95) -> float:
    """Return the one-sided lower confidence bound of the ARL (Poisson count of alarms).

    With ``a`` alarms in ``N`` samples, the alarm rate's upper bound is
    ``chi2.ppf(level, 2 a + 2) / (2 N)``; the ARL bound is its inverse.
    """
    return 2.0 * samples / stats.chi2.ppf(level, 2 * alarms + 2)


def _arl_tasks(s: dict[str, Any]) -> list[dict[str, Any]]:
    tasks = []
    for case in llr_arl.NOISE_CASES:
        temp = case == 'dry_orbit_temperature'
        for rate in RATES:
            for variant, runs in (('default', s['temp_runs'] if temp else s['runs']),
                                  ('paper', s['paper_runs'])):
                n = s['temp_n'] if temp and variant == 'default' else s['n']
                tasks += [{'case': case, 'rate': rate, 'variant': variant, 'n': n,
                           'seed': SEED0 + i} for i in range(runs)]
    return tasks


def _detection_tasks(s: dict[str, Any]) -> list[dict[str, Any]]:
    tasks = []
    rows = [(case, 'default') for case in llr_arl.NOISE_CASES]
    rows += [('gaussian', 'paper'), ('gaussian', 'sliding')]
    for case, variant in rows:
        runs = s['det_temp_runs'] if case == 'dry_orbit_temperature' else s['det_runs']
        for kind, (d_dry, d_visc) in STEPS.items():
            tasks += [dict(DETECTION, case=case, variant=variant, kind=kind, delta_dry=d_dry,
                           delta_viscous=d_visc, seed=SEED0 + 5000 + i) for i in range(runs)]
    return tasks


def _run(task: dict[str, Any]) -> dict[str, Any]:
    func = llr_arl.detection_task if 'kind' in task else llr_arl.false_alarm_task
    return dict(task, **func(task))


def _summarise_arl(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for case in llr_arl.NOISE_CASES:
        for rate in RATES:
            for variant in ('default', 'paper'):
                sel = [r for r in results if r['case'] == case and r['rate'] == rate
                       and r['variant'] == variant]
                samples = sum(r['samples'] for r in sel)
                alarms = sum(r['alarms'] for r in sel)
                arl = samples / alarms if alarms else math.inf
                low = lower_bound(samples, alarms)
                rows.append({'case': case, 'rate': rate, 'variant': variant, 'runs': len(sel),
                             'samples': samples, 'alarms': alarms, 'arl': arl,
                             'arl_lower95': low, 'promise': 1.0 / rate,
                             'met': arl >= 1.0 / rate, 'met_lower95': low >= 1.0 / rate,
                             'cpu_s': sum(r['seconds'] for r in sel)})
    return rows


def _summarise_detection(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    keys = sorted({(r['case'], r['variant'], r['kind']) for r in results},
                  key=lambda k: (llr_arl.NOISE_CASES.index(k[0]), k[1], k[2]))
    for case, variant, kind in keys:
        sel = [r for r in results if (r['case'], r['variant'], r['kind'])
               == (case, variant, kind)]
        delays = [r['delay'] for r in sel if r['detected']]
        rows.append({'case': case, 'variant': variant, 'kind': kind, 'runs': len(sel),
                     'detected': sum(r['detected'] for r in sel) / len(sel),
                     'median_delay': float(np.median(delays)) if delays else math.nan,
                     'early_alarms': sum(r['early_alarm'] for r in sel)})
    white = {r['kind']: r for r in rows if r['case'] == 'gaussian' and r['variant'] == 'default'}
    for r in rows:
        ref = white[r['kind']]
        r['loss_vs_white'] = ref['detected'] - r['detected']
        r['delay_ratio_vs_white'] = r['median_delay'] / ref['median_delay']
    return rows


def markdown(res: dict[str, Any]) -> str:
    """Return the docs/results.md section."""
    arl_rows = []
    by = {(r['case'], r['rate'], r['variant']): r for r in res['arl']}
    for case in llr_arl.NOISE_CASES:
        for rate in RATES:
            d, p = by[(case, rate, 'default')], by[(case, rate, 'paper')]
            arl_rows.append([case, f'{rate:.0e}', f'{d["arl"]:.3g}', f'{d["arl_lower95"]:.3g}',
                             f'{d["alarms"]} / {d["samples"]:.2g}',
                             'yes' if d['met_lower95'] else ('ARL only' if d['met'] else 'NO'),
                             f'{p["arl"]:.3g}', f'{p["alarms"]} / {p["samples"]:.2g}'])
    det_rows = [[r['case'], r['variant'], r['kind'], r['runs'], f'{r["detected"]:.2f}',
                 f'{r["median_delay"]:.0f}', f'{r["loss_vs_white"]:+.2f}',
                 f'{r["delay_ratio_vs_white"]:.2f}', r['early_alarms']]
                for r in res['detection']]
    cfg = res['config']
    return '\n'.join([
        '## LLR: average run length to a false alarm beyond white noise (`python -m bench arl`)',
        '',
        f'Realistic SI profile at 10 Hz (holds, slews, zero crossings), window '
        f'{cfg["window"]}, k_verif {cfg["k_verif"]}, noise level estimated; cases in '
        '`bench/llr_arl.py`. Detector (default): AR prewhitening (order <= 3 by BIC on the '
        'first 801 samples); `dry_orbit` adds a sliding reference of '
        f'{cfg["reference_max"]} samples; `dry_orbit_temperature` a temperature column '
        '(p = 3); `speed_noise` the noise level modelled against |w| '
        '(`noise_speed_model`, docs/llr.md "Noise growing with speed"). Paper: white '
        'noise, growing reference. ARL = samples / alarms over all '
        'runs (each alarm restarts the reference); lower 95 % bound from the Poisson '
        f'count. Seeds {SEED0} and up (chosen before the results; development on 1-99). '
        f'Code commit `{res["commit"]}`' + ''.join(
            f'; cells of `{case}` (default detector) re-run at `{commit}`'
            for case, commit in res.get('rerun', {}).items()) + '.',
        '',
        report.table(['noise', 'r', 'ARL', 'ARL 95 % low', 'alarms / samples',
                      'ARL >= 1/r', 'paper ARL', 'paper alarms / samples'], arl_rows),
        '',
        f'Detection of a step at sample {DETECTION["at"]} (r = {DETECTION["rate"]:.0e}, '
        f'{DETECTION["n"]} samples per run): dry +{STEPS["dry"][0]:.2g} N m (0.5 noise std, '
        f'12.5 % of nominal), viscous +{STEPS["viscous"][1]:.2g} N m s. Delay in samples '
        '(median, detected runs). Loss = detection probability of the white Gaussian case '
        '(default detector) minus this one; `early` = runs with a false alarm before the '
        'step.',
        '',
        report.table(['noise', 'detector', 'step', 'runs', 'P(detect)', 'median delay',
                      'loss vs white', 'delay / white', 'early'], det_rows),
    ])


def run(out_dir: pathlib.Path, quick: bool = False) -> dict[str, Any]:
    """Run the benchmark; write arl.json and the docs/results.md section."""
    import subprocess
    s = _settings(quick)
    started = time.perf_counter()
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                            text=True, cwd=report.REPO).stdout.strip()
    tasks = _arl_tasks(s) + _detection_tasks(s)
    # Longest first so that the two workers finish together.
    tasks.sort(key=lambda t: -(t['n'] * (30 if t['case'] == 'dry_orbit_temperature'
                                         and t['variant'] != 'paper' else 1)))
    results = []
    with multiprocessing.get_context('fork').Pool(WORKERS) as pool:
        for i, r in enumerate(pool.imap_unordered(_run, tasks)):
            results.append(r)
            if (i + 1) % 50 == 0 or i + 1 == len(tasks):
                print(f'  arl: {i + 1}/{len(tasks)} ({time.perf_counter() - started:.0f} s)',
                      flush=True)
    res = {'settings': s, 'commit': commit, 'seed0': SEED0,
           'config': dict(llr_arl.DETECTOR, reference_max=llr_arl.REFERENCE_MAX),
           'arl': _summarise_arl([r for r in results if 'kind' not in r]),
           'detection': _summarise_detection([r for r in results if 'kind' in r]),
           'bench_seconds': time.perf_counter() - started}
    plot(out_dir, res)
    report.write_json(out_dir, 'arl', res)
    text = markdown(res)
    if quick:
        print(text)
    else:
        report.update_section('arl', text)
    return res


def plot(out_dir: pathlib.Path, res: dict[str, Any]) -> None:
    """Plot ARL per noise case and rate against 1/r (log scale)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9, 4))
    cases = llr_arl.NOISE_CASES
    x = np.arange(len(cases))
    for j, rate in enumerate(RATES):
        for variant, marker in (('default', 'o'), ('paper', 'x')):
            rows = {r['case']: r for r in res['arl'] if r['rate'] == rate
                    and r['variant'] == variant}
            arl = [min(rows[c]['arl'], 1e9) for c in cases]
            low = [rows[c]['arl_lower95'] for c in cases]
            ax.scatter(x + 0.15 * j, arl, marker=marker, color=f'C{j}',
                       label=f'{variant}, r = {rate:.0e}')
            if variant == 'default':
                ax.vlines(x + 0.15 * j, low, arl, color=f'C{j}', lw=1)
        ax.hlines(1.0 / rate, -0.5, len(cases) - 0.5, color=f'C{j}', ls='--', lw=0.8)
    ax.set_yscale('log')
    ax.set_xticks(x + 0.075)
    ax.set_xticklabels(cases, rotation=20, fontsize=8)
    ax.set_ylabel('ARL to a false alarm (samples)')
    ax.set_title('LLR ARL beyond white noise (dashed: 1/r; bars: 95 % lower bound)')
    ax.legend(fontsize=7)
    fig.tight_layout()
    out_dir.mkdir(parents=True, exist_ok=True)
    from rwa_monitor.telemetry.atomic import atomic_write
    with atomic_write(out_dir / 'arl.png', 'wb', encoding=None) as handle:
        fig.savefig(handle, format='png', dpi=110)
    plt.close(fig)


def rerun_cases(cases: list[str], out_dir: pathlib.Path = report.RESULTS_DIR
                ) -> dict[str, Any]:
    """Re-run the default-detector cells of ``cases`` only; keep the other stored cells.

    ``python -c "from bench import bench_arl; bench_arl.rerun_cases(['speed_noise'])"``:
    for a change that affects only some cases (the paper detector and the other cases'
    detectors are untouched), on a machine too loaded for the whole table. Same seeds and
    budgets as :func:`run`; the section names the commit of each re-run case.
    """
    import json
    import subprocess
    s = _settings(False)
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                            text=True, cwd=report.REPO).stdout.strip()
    res = json.loads((out_dir / 'arl.json').read_text())
    res.pop('machine', None)
    for row in res['arl']:     # the JSON stores inf (no alarm) as null
        row['arl'] = math.inf if row['arl'] is None else row['arl']
    for row in res['detection']:
        for key in ('median_delay', 'delay_ratio_vs_white'):
            row[key] = math.nan if row[key] is None else row[key]
    tasks = [t for t in _arl_tasks(s) + _detection_tasks(s)
             if t['case'] in cases and t['variant'] == 'default']
    with multiprocessing.get_context('fork').Pool(WORKERS) as pool:
        results = list(pool.imap_unordered(_run, tasks))
    new_arl = {(r['case'], r['rate']): r for r in
               _summarise_arl([r for r in results if 'kind' not in r])
               if r['variant'] == 'default' and r['runs']}
    res['arl'] = [new_arl.get((r['case'], r['rate']), r) if r['variant'] == 'default'
                  else r for r in res['arl']]
    kept = [r for r in res['detection'] if not (r['case'] in cases
                                                and r['variant'] == 'default')]
    fresh = [r for r in results if 'kind' in r]
    white = [r for r in res['detection'] if r['case'] == 'gaussian'
             and r['variant'] == 'default']
    rows = []
    for case in cases:
        for kind in STEPS:
            sel = [r for r in fresh if (r['case'], r['kind']) == (case, kind)]
            delays = [r['delay'] for r in sel if r['detected']]
            ref = next(w for w in white if w['kind'] == kind)
            detected = sum(r['detected'] for r in sel) / len(sel)
            delay = float(np.median(delays)) if delays else math.nan
            rows.append({'case': case, 'variant': 'default', 'kind': kind, 'runs': len(sel),
                         'detected': detected, 'median_delay': delay,
                         'early_alarms': sum(r['early_alarm'] for r in sel),
                         'loss_vs_white': ref['detected'] - detected,
                         'delay_ratio_vs_white': delay / ref['median_delay']})
    res['detection'] = sorted(kept + rows, key=lambda r: (
        llr_arl.NOISE_CASES.index(r['case']), r['variant'], r['kind']))
    res['settings'] = s
    res['rerun'] = dict(res.get('rerun', {}), **{case: commit for case in cases})
    plot(out_dir, res)
    report.write_json(out_dir, 'arl', res)
    report.update_section('arl', markdown(res))
    return res
