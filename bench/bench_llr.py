"""``python -m bench llr``: the llr-realtime paper's experiments (section III) and goals.

Sections: Fig. 3 (localisation, miss rate), Fig. 4 (detection probability vs size of a
dry change, simulation vs Lemma 1), Fig. 5 (average run length to a false alarm),
categorisation of dry / viscous / both changes, the offline peer (PELT on model (1),
:mod:`.llr_peer`) on the same data, throughput (streaming and batch) and memory.
All data come from :mod:`rwa_monitor.sim.friction` in the paper's scaled units (noise std
1, known to both detectors); the throughput runs use the SI realistic profile.
"""

from __future__ import annotations

import math
import multiprocessing
import pathlib
import subprocess
import time
from typing import Any, Callable

import numpy as np

from bench import llr_cases, report

WORKERS = 2
TOL = 500            # a declaration within +-TOL samples of the change detects it
CHANGE = 1500        # the paper's change step (Fig. 3; also used for Figs. 4 and cat.)
N_RUN = 3000         # samples per scenario run
# Categorisation runs: the kind is re-checked at 2, 4, 8 x ~760 samples after the change.
N_CAT = 8000
FIG4_SIZES = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5)
FIG4_RATES = (1e-3, 1e-4, 1e-5)
ARL_RATES = (1e-2, 1e-3, 1e-4, 1e-5)
ARL_WINDOWS = (100, 250, 500)
ARL_ALARMS = 100
MEMORY_BUDGET_S = 240.0
CATEGORIES = {'dry': (0.5, 0.0), 'viscous': (0.0, 0.025), 'both': (0.5, 0.025)}
CATEGORY_SCALES = (1, 2)
REALISTIC_CONFIG = {'window': 400, 'k_verif': 'auto', 'false_alarm_rate': 1e-4,
                    'noise_std': 'auto'}
GOALS = {'streaming_per_s': 300_000, 'batch_per_s': 3_000_000, 'miss_rate_0.3': 0.02,
         'categorisation': 0.95}


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'fig3_runs': 20, 'fig4_runs': 10, 'cat_runs': 10, 'arl_runs': 2,
                'arl_n': 20_000, 'peer_fa_runs': 2, 'peer_fa_n': 5000,
                'throughput_n': (88_000,), 'memory_n': (10**5, 3 * 10**5),
                'realistic_runs': 2}
    return {'fig3_runs': 200, 'fig4_runs': 100, 'cat_runs': 100, 'arl_runs': 30,
            'arl_n': 100_000, 'peer_fa_runs': 5, 'peer_fa_n': 100_000,
            'throughput_n': (88_000, 1_000_000), 'memory_n': (10**5, 10**6, 10**7),
            'realistic_runs': 20}


def _params(window: int = 500, rate: float = 1e-5) -> dict[str, Any]:
    return {'window': window, 'k_verif': window // 2, 'false_alarm_rate': rate,
            'noise_std': 1.0}


def _pool_map(pool, func: Callable, tasks: list, label: str) -> list:
    results, step = [], max(1, len(tasks) // 10)
    start = time.perf_counter()
    for i, result in enumerate(pool.imap(func, tasks, chunksize=4)):
        results.append(result)
        if (i + 1) % step == 0 or i + 1 == len(tasks):
            print(f'  {label}: {i + 1}/{len(tasks)} ({time.perf_counter() - start:.0f} s)',
                  flush=True)
    return results


def _quantiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {'median': math.nan, 'q25': math.nan, 'q75': math.nan, 'iqr': math.nan}
    q25, med, q75 = np.percentile(values, [25, 50, 75])
    return {'median': float(med), 'q25': float(q25), 'q75': float(q75),
            'iqr': float(q75 - q25)}


def _llr_stats(outcomes: list[dict[str, Any]]) -> dict[str, Any]:
    hits = [o for o in outcomes if o['detected']]
    return {'runs': len(outcomes), 'detection_rate': len(hits) / len(outcomes),
            'miss_rate': (len(outcomes) - len(hits)) / len(outcomes),
            'no_declaration_rate': sum(not o['declared_any'] for o in outcomes) / len(outcomes),
            'false_per_run': sum(o['false'] for o in outcomes) / len(outcomes),
            'error': _quantiles([o['error'] for o in hits]),
            'delay': _quantiles([o['delay'] for o in hits]),
            'errors': [o['error'] for o in hits]}


def _peer_stats(outcomes: list[dict[str, Any]]) -> dict[str, Any]:
    hits = [o for o in outcomes if o['detected']]
    return {'runs': len(outcomes), 'detection_rate': len(hits) / len(outcomes),
            'false_per_run': sum(o['false'] for o in outcomes) / len(outcomes),
            'error': _quantiles([o['error'] for o in hits]),
            'errors': [o['error'] for o in hits],
            'samples_per_s': (sum(o['samples'] for o in outcomes)
                              / sum(o['seconds'] for o in outcomes))}


def fig3(pool, s: dict) -> dict[str, Any]:
    """Measure Fig. 3: dry +0.3 / +0.5 at k = 1500, profile fig3, r = 1e-5, w = 500."""
    out = {}
    for size in (0.3, 0.5):
        tasks = [{'profile': 'fig3', 'n': N_RUN, 'seed': seed, 'dry': size,
                  'change': CHANGE, 'tol': TOL, 'peer': True,
                  'llr': [_params(), {**_params(), 'noise_std': None}]}
                 for seed in range(s['fig3_runs'])]
        res = _pool_map(pool, llr_cases.scenario_task, tasks, f'fig3 dry +{size}')
        out[str(size)] = {'llr': _llr_stats([r['llr'][0] for r in res]),
                          'llr_noise_estimated': _llr_stats([r['llr'][1] for r in res]),
                          'peer': _peer_stats([r['peer'] for r in res])}
    return out


def lemma1_detection(speed: np.ndarray, k: int, window: int, delta: np.ndarray,
                     rate: float) -> float:
    """Return P(p_k <= r) at the change step k for a change delta (Lemma 1, unit noise).

    LLR_k = |z|^2, z = R e + Q dx with cov(z) = I - Pi_P^1/2 Pi_T^-1 Pi_P^1/2 = U L U^T and
    Q = Pi_P^1/2 (I - Pi_T^-1 Pi_P) (appendix I, eqs. (9)-(12)); so LLR_k = sum_i
    (sqrt(l_i) eta_i + m_i)^2 with m = U^T Q dx. The threshold is the nominal (1 - r)
    quantile of sum_i l_i eta_i^2 (eq. (7)).
    """
    from rwa_monitor.core.gchi2 import gchi2_isf, gchi2_sf
    h = -np.column_stack([np.sign(speed), speed])
    pi_p = h[:k].T @ h[:k]
    pi_t = h[:k + window].T @ h[:k + window]
    vals, vecs = np.linalg.eigh(pi_p)
    root_p = vecs @ np.diag(np.sqrt(vals)) @ vecs.T
    cov = np.eye(2) - root_p @ np.linalg.solve(pi_t, root_p)
    lam, u = np.linalg.eigh((cov + cov.T) / 2)
    lam = np.clip(lam, 1e-15, None)
    mean = u.T @ root_p @ (np.eye(2) - np.linalg.solve(pi_t, pi_p)) @ delta
    threshold = gchi2_isf(rate, lam)
    # Non-central form: sum_i l_i (eta_i + m_i / sqrt(l_i))^2.
    return float(gchi2_sf(threshold, lam, mean / np.sqrt(lam)))


def fig4(pool, s: dict) -> dict[str, Any]:
    """Measure Fig. 4: detection probability vs dry change size, profile fig4, w = 500, three r."""
    params = [_params(rate=r) for r in FIG4_RATES]
    tasks = [{'profile': 'fig4', 'n': N_RUN, 'seed': 10_000 + seed, 'dry': size,
              'change': CHANGE, 'tol': TOL, 'llr': params}
             for size in FIG4_SIZES for seed in range(s['fig4_runs'])]
    res = _pool_map(pool, llr_cases.scenario_task, tasks, 'fig4')
    speed = llr_cases.series('fig4', N_RUN, 0)[1]
    curves = {}
    for j, rate in enumerate(FIG4_RATES):
        sim, theory = [], []
        for i, size in enumerate(FIG4_SIZES):
            block = res[i * s['fig4_runs']:(i + 1) * s['fig4_runs']]
            sim.append(sum(r['llr'][j]['detected'] for r in block) / len(block))
            theory.append(lemma1_detection(speed, CHANGE, 500, np.array([size, 0.0]), rate))
        curves[f'{rate:g}'] = {'sizes': list(FIG4_SIZES), 'simulation': sim,
                               'theory': theory}
    return {'runs_per_point': s['fig4_runs'], 'curves': curves}


def _arl_runs(rate: float, s: dict) -> int:
    """Return the runs of arl_n samples for one cell: about ARL_ALARMS / r samples."""
    return max(1, min(s['arl_runs'], math.ceil(ARL_ALARMS / rate / s['arl_n'])))


def fig5(pool, s: dict) -> dict[str, Any]:
    """Measure Fig. 5: average run length to a false alarm, no anomaly, profile fig5.

    Each cell gets about ARL_ALARMS / r samples (at most arl_runs runs of arl_n): enough
    to see an ARL near 1/r a hundred times or to bound it above 1/r.
    """
    from scipy import stats
    cells = [(w, r) for w in ARL_WINDOWS for r in ARL_RATES]
    tasks, spans = [], []
    for w, r in cells:
        runs = _arl_runs(r, s)
        spans.append((len(tasks), len(tasks) + runs))
        tasks += [{'n': s['arl_n'], 'seed': 20_000 + seed, 'params': _params(w, r)}
                  for seed in range(runs)]
    res = _pool_map(pool, llr_cases.arl_task, tasks, 'fig5')
    out = []
    for (w, r), (first, last) in zip(cells, spans):
        block = res[first:last]
        alarms = sum(b['alarms'] for b in block)
        samples = sum(b['samples'] for b in block)
        # Alarms as a Poisson count over `samples`: ARL = samples / alarms, and the 95 %
        # one-sided lower bound uses the chi-square upper bound of the count.
        lower = samples / (stats.chi2.ppf(0.95, 2 * (alarms + 1)) / 2)
        out.append({'window': w, 'rate': r, 'alarms': alarms, 'samples': samples,
                    'arl': samples / alarms if alarms else math.inf,
                    'arl_lower_95': lower, 'one_over_r': 1 / r})
    return {'max_runs_per_cell': s['arl_runs'], 'samples_per_run': s['arl_n'], 'cells': out}


def categorisation(pool, s: dict) -> dict[str, Any]:
    """Categorise dry, viscous and both changes at k = 1500, profile fig3, r = 1e-5.

    Two magnitudes: the base one (dry 0.5, viscous 0.025, also run through the peer)
    and twice that (key ``<kind> x2``).
    """
    out = {}
    for scale in CATEGORY_SCALES:
        for name, (dry, visc) in CATEGORIES.items():
            key = name if scale == 1 else f'{name} x{scale:g}'
            tasks = [{'profile': 'fig3', 'n': N_CAT, 'seed': 30_000 + seed,
                      'dry': scale * dry, 'viscous': scale * visc, 'change': CHANGE,
                      'tol': TOL, 'llr': [_params()], 'peer': scale == 1}
                     for seed in range(s['cat_runs'])]
            res = _pool_map(pool, llr_cases.scenario_task, tasks, f'categorise {key}')
            llr = [r['llr'][0] for r in res]
            hits = [o for o in llr if o['detected']]
            out[key] = {'kind': name, 'delta_dry': scale * dry, 'delta_viscous': scale * visc,
                        'llr': {k: v for k, v in _llr_stats(llr).items() if k != 'errors'},
                        'first_kind_accuracy': (sum(o['kind'] == name for o in hits)
                                                / len(hits) if hits else math.nan),
                        'final_kind_accuracy': (sum(o['final_kind'] == name for o in hits)
                                                / len(hits) if hits else math.nan),
                        'kinds': {k: sum(o['final_kind'] == k for o in hits)
                                  for k in (*CATEGORIES, 'undecided')}}
            if scale == 1:
                out[key]['peer'] = {k: v for k, v in
                                    _peer_stats([r['peer'] for r in res]).items()
                                    if k != 'errors'}
    return out


def peer_false_alarms(pool, s: dict) -> dict[str, Any]:
    """Count the changes found by the peer on anomaly-free fig5 data, per 100k samples."""
    tasks = [{'n': s['peer_fa_n'], 'seed': 40_000 + seed} for seed in range(s['peer_fa_runs'])]
    res = _pool_map(pool, llr_cases.peer_false_task, tasks, 'peer false alarms')
    samples = sum(r['samples'] for r in res)
    alarms = sum(r['alarms'] for r in res)
    return {'samples': samples, 'alarms': alarms, 'per_100k': 1e5 * alarms / samples,
            'samples_per_s': samples / sum(r['seconds'] for r in res)}


def throughput(s: dict) -> dict[str, Any]:
    """Measure samples per CPU second of streaming and batch paths (SI realistic profile)."""
    from rwa_monitor.core.llr import detect_batch, LLRDetector
    from rwa_monitor.sim.friction import simulate_friction
    params = {'window': 400, 'k_verif': 200, 'false_alarm_rate': 1e-4, 'noise_std': None}
    out = []
    for n in s['throughput_n']:
        tele = simulate_friction(wheels=('rw1',), n_samples=n, rate_hz=10.0, seed=7)
        w = tele.wheels['rw1']
        start = time.process_time()
        batch_events = detect_batch(tele.time, w.speed, w.friction, component='rw1', **params)
        batch_s = time.process_time() - start
        detector = LLRDetector('rw1', **params)
        t_list, w_list, f_list = tele.time.tolist(), w.speed.tolist(), w.friction.tolist()
        stream_events = []
        start = time.process_time()
        for t_k, w_k, f_k in zip(t_list, w_list, f_list):
            found = detector.update(t_k, w_k, f_k)
            if found:
                stream_events.extend(found)
        stream_s = time.process_time() - start
        same = [e.to_json() for e in batch_events] == [e.to_json() for e in stream_events]
        row = {'n': n, 'batch_s': batch_s, 'batch_per_s': n / batch_s,
               'stream_s': stream_s, 'stream_per_s': n / stream_s,
               'batch_events': len(batch_events), 'stream_events': len(stream_events),
               'same_events': same}
        print(f'  throughput n={n}: stream {row["stream_per_s"]:.0f}/s, '
              f'batch {row["batch_per_s"]:.0f}/s', flush=True)
        out.append(row)
    return {'params': params, 'rows': out}


def realistic(pool, s: dict) -> dict[str, Any]:
    """Run the file pipeline on 3-hour, 4-wheel SI files with one change per wheel 2-4."""
    tasks = [{'seed': 50_000 + seed, 'hours': 3.0, 'config': REALISTIC_CONFIG}
             for seed in range(s['realistic_runs'])]
    res = _pool_map(pool, llr_cases.realistic_task, tasks, 'realistic')
    out: dict[str, Any] = {'runs': len(res), 'config': REALISTIC_CONFIG,
                           'anomalies': llr_cases.REALISTIC_ANOMALIES}
    for kind in ('dry', 'viscous', 'both'):
        rows = [c for r in res for c in r['changes'] if c['kind'] == kind]
        hits = [c for c in rows if c['detected']]
        out[kind] = {'changes': len(rows), 'detected': len(hits),
                     'error_s': _quantiles([c['error_s'] for c in hits]),
                     'delay_s': _quantiles([c['delay_s'] for c in hits]),
                     'kind_accuracy': (sum(c['final_kind'] == kind for c in hits) / len(hits)
                                       if hits else math.nan)}
    hours = sum(r['wheel_hours'] for r in res)
    false = sum(r['false'] for r in res)
    out['false'] = false
    out['wheel_hours'] = hours
    out['false_per_wheel_hour'] = false / hours
    return out


def memory(s: dict, stream_per_s: float) -> dict[str, Any]:
    """Measure the RSS of one streaming detector fed 1e5 .. 1e7 samples (fresh process).

    A size whose run would take more than MEMORY_BUDGET_S at the measured streaming
    rate is skipped and listed as such.
    """
    ctx = multiprocessing.get_context('spawn')
    rows, skipped = [], []
    for n in s['memory_n']:
        if n / stream_per_s > MEMORY_BUDGET_S:
            skipped.append(n)
            print(f'  memory n={n}: skipped (~{n / stream_per_s:.0f} s)', flush=True)
            continue
        with ctx.Pool(1) as pool:
            row = pool.apply(llr_cases.memory_probe, (n, _params()))
        row['growth_kb'] = row['rss_final_kb'] - row['rss_after_first_chunk_kb']
        print(f'  memory n={n}: peak {row["peak_rss_kb"]} kB, growth after the first '
              f'chunk {row["growth_kb"]} kB ({row["seconds"]:.0f} s)', flush=True)
        rows.append(row)
    return {'rows': rows, 'skipped': skipped, 'budget_s': MEMORY_BUDGET_S}


def code_version() -> str:
    """Return the commit of the code measured, marked if the detector's files differ."""
    try:
        head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'rwa_monitor/core',
                                'rwa_monitor/pipelines', 'rwa_monitor/sim'],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown (not a git checkout)'
    return head + (' + uncommitted changes in core/pipelines/sim' if dirty else '')


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run every section, write llr.json, the plots and the llr section of results.md."""
    s = _settings(quick)
    results: dict[str, Any] = {'quick': quick, 'settings': s, 'code': code_version()}
    started = time.perf_counter()
    print('throughput (single process)', flush=True)
    results['throughput'] = throughput(s)
    with multiprocessing.get_context('fork').Pool(WORKERS) as pool:
        results['fig3'] = fig3(pool, s)
        results['fig4'] = fig4(pool, s)
        results['fig5'] = fig5(pool, s)
        results['categorisation'] = categorisation(pool, s)
        results['peer_false_alarms'] = peer_false_alarms(pool, s)
        results['realistic'] = realistic(pool, s)
    print('memory (fresh processes)', flush=True)
    results['memory'] = memory(s, min(row['stream_per_s']
                                      for row in results['throughput']['rows']))
    results['goals'] = goals(results)
    results['bench_seconds'] = time.perf_counter() - started
    from bench import llr_report
    llr_report.plots(out_dir, results)
    for size in ('0.3', '0.5'):
        for who in ('llr', 'llr_noise_estimated', 'peer'):
            results['fig3'][size][who].pop('errors')
    report.write_json(out_dir, 'llr', results)
    if not quick:
        report.update_section('llr', llr_report.markdown(results))
    else:
        print(llr_report.markdown(results))
    return results


def goals(r: dict[str, Any]) -> list[dict[str, Any]]:
    """Return each goal with its measured value and whether it is met."""
    stream = min(row['stream_per_s'] for row in r['throughput']['rows'])
    batch = min(row['batch_per_s'] for row in r['throughput']['rows'])
    miss = r['fig3']['0.3']['llr']['miss_rate']
    iqr_llr = r['fig3']['0.5']['llr']['error']['iqr']
    iqr_peer = r['fig3']['0.5']['peer']['error']['iqr']
    cat = min(r['categorisation'][name]['final_kind_accuracy'] for name in CATEGORIES)
    mem = r['memory']['rows']
    peaks = [row['peak_rss_kb'] for row in mem]
    growth = max(max(row['growth_kb'] for row in mem), max(peaks) - min(peaks))
    flat = growth < 10_240  # < 10 MB: within a run, and of the peak from 1e5 to max n
    return [
        {'goal': 'streaming >= 300,000 samples/s per wheel', 'value': stream,
         'met': stream >= GOALS['streaming_per_s']},
        {'goal': 'batch >= 3,000,000 samples/s', 'value': batch,
         'met': batch >= GOALS['batch_per_s']},
        {'goal': 'miss rate <= 2 % for +0.3 at r = 1e-5', 'value': miss,
         'met': miss <= GOALS['miss_rate_0.3']},
        {'goal': 'localisation IQR on +0.5 <= offline peer', 'value': [iqr_llr, iqr_peer],
         'met': iqr_llr <= iqr_peer},
        {'goal': 'categorisation >= 95 % once confirmed (worst of dry 0.5, viscous 0.025, '
                 'both)', 'value': cat,
         'met': cat >= GOALS['categorisation']},
        {'goal': f'memory flat (growth < 10 MB, kB shown, 1e5 to {mem[-1]["n"]:.0e} samples)',
         'value': growth, 'met': flat},
    ]
