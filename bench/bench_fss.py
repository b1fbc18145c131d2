"""FSS window diagnoser benchmark: the physics-informed FSS paper's section V.

Detection-probability matrix over 30 random 20 % / 80 % splits (Fig. 11), ARL at 0.1 %
missed detection vs window size, W_b and jump size (Fig. 7), excess RMSE with and without
changepoints (Fig. 8), rejections per window (Table II), DP iterations vs changepoints
and the effect of the beam (Fig. 10), time per stage on 80,000-sample windows (Fig. 13).
Those figures use the first bench's anomalies (``legacy``: 2.5-3x away from nominal,
``rwa-monitor fss build --anomalies legacy``, seed 0, 100 windows per status, in
data/generated/fss_legacy). The tables that count are at realistic sizes (bench/fss_sizes.py:
x1.1-x3 of each wheel's nominal, laws estimated from commissioning windows, learned and
baseline side by side, the paper-Example windows with a calibration).
"""

from __future__ import annotations

import os
import pathlib
import time

import numpy as np
from scipy import stats

from bench import report
from rwa_monitor.core.fss.assign import assign_changepoints
from rwa_monitor.core.fss.classify import detection_matrix, train_model
from rwa_monitor.core.fss.pipeline import extract, FssConfig
from rwa_monitor.core.fss.segments import fit_intervals
from rwa_monitor.core.fss.wglr import detect_changepoints, estimate_sigma, wglr
from rwa_monitor.sim import fss

STATUSES = fss.STATUSES
ANOMALIES = ('dry', 'viscous', 'fss1', 'fss2')


def _dataset(quick: bool, seed: int = 0, per_status: int | None = None) -> pathlib.Path:
    name = ('fss_legacy_quick' if quick else 'fss_legacy') + (f'_seed{seed}' if seed else '')
    path = pathlib.Path('data/generated') / name
    per_status = per_status or (10 if quick else 100)
    try:
        manifest = fss.load_manifest(path)
        if manifest['per_status'] == per_status and manifest['seed'] == seed and \
                manifest.get('anomalies') == 'legacy':
            return path
    except ValueError:
        pass
    fss.build_dataset(path, per_status=per_status, seed=seed, anomalies='legacy')
    return path


def shipped_model_held_out(quick: bool) -> dict:
    """Return the shipped model's detection matrix on an independent legacy set (seed 1).

    Legacy windows have no reference window; their nominal is (1, 1) +- 10 %, where a
    calibrated wheel's reference puts it, so the absolute features are given.
    """
    from rwa_monitor.telemetry.fss_model import load_model
    path = _dataset(quick, seed=1, per_status=4 if quick else 40)
    items = fss.dataset_extractions(path)
    model = load_model()
    matrix = detection_matrix(model, items, relative=False)
    nominal = [it for it in items if it['status'] == 'nominal']
    return {'windows': len(items), 'seed': 1, 'matrix': matrix,
            'trained_on': model.spec.get('trained_on', {}),
            'nominal_any_flag': float(np.mean([any(model.predict(it['features']).values())
                                               for it in nominal]))}


def classification(items: list[dict], splits: int, use: str = 'both',
                   bins: int = 20) -> dict:
    """Return min/mean/max detection matrices over random 20 % / 80 % splits (Fig. 11).

    Each split trains on a random 20 % of every status and validates on the rest.
    """
    rng = np.random.default_rng(0)
    mats, any_nominal = [], []
    by_status = {st: [i for i, it in enumerate(items) if it['status'] == st]
                 for st in STATUSES}
    for _ in range(splits):
        chosen = set()
        for idx in by_status.values():  # 20 % of each status (stratified)
            chosen.update(rng.permutation(idx)[:max(1, len(idx) // 5)].tolist())
        train = [it for i, it in enumerate(items) if i in chosen]
        valid = [it for i, it in enumerate(items) if i not in chosen]
        model = train_model(train, use=use, bins=bins)
        mats.append(detection_matrix(model, valid))
        nominal = [it for it in valid if it['status'] == 'nominal']
        any_nominal.append(np.mean([any(model.predict(it['features']).values())
                                    for it in nominal]))
    out = {}
    for st in STATUSES:
        out[st] = {a: {'min': min(m[st][a] for m in mats),
                       'mean': float(np.mean([m[st][a] for m in mats])),
                       'max': max(m[st][a] for m in mats)} for a in ANOMALIES}
    return {'matrix': out, 'splits': len(mats), 'use': use,
            'nominal_any_flag': {'min': float(np.min(any_nominal)),
                                 'mean': float(np.mean(any_nominal)),
                                 'max': float(np.max(any_nominal))}}


def arl(windows=(10, 20, 50, 100), w_biases=(0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0),
        sizes=(2.0, 3.0, 4.0, 5.0), mdr: float = 1e-3) -> dict:
    """Return ARL at ``mdr`` missed detection for window sizes, W_b and jump sizes (Fig. 7).

    A jump of size delta (in noise std) in the middle of a slew at the profile's largest
    acceleration (speed 0.8 + 0.0025 k, normalised): the noise-free wGLR at the jump is
    lambda sigma^2, with lambda the non-centrality of the statistic, so the threshold
    giving ``mdr`` is the ``mdr`` quantile of ncx2(1, lambda), and ARL = 1 / P(chi2(1) >
    threshold) (the prior only makes the no-jump statistic smaller: a lower bound).
    """
    rows = []
    for w in windows:
        n = 4 * w
        x = 0.8 + 0.0025 * np.arange(n)
        for w_bias in w_biases:
            for size in sizes:
                y = np.where(np.arange(n) >= n // 2, size, 0.0) + 1.0 + x
                lam = wglr(y, x, window=w, w_bias=w_bias, viscous_prior=1.0)[n // 2]
                thr = stats.ncx2.ppf(mdr, 1, max(lam, 1e-12))
                rows.append({'window': w, 'w_bias': w_bias, 'delta_sigma': size,
                             'noncentrality': float(lam),
                             'arl': float(1.0 / max(stats.chi2.sf(thr, 1), 1e-300))})
    return {'rows': rows, 'mdr': mdr}


def arl_check(trials: int, seed: int = 0) -> dict:
    """Check the ARL model by simulation at w = 20, W_b = 1e-4, delta = 3 sigma."""
    rng = np.random.default_rng(seed)
    w, size = 20, 3.0
    n = 4 * w
    x = 0.8 + 0.0025 * np.arange(n)
    base = 1.0 + x
    lam = wglr(base + np.where(np.arange(n) >= n // 2, size, 0.0), x, window=w,
               w_bias=1e-4, viscous_prior=1.0)[n // 2]
    thr = stats.ncx2.ppf(1e-3, 1, lam)
    missed = exceed = 0
    for _ in range(trials):
        noise = rng.normal(0.0, 1.0, n)
        g1 = wglr(base + noise + np.where(np.arange(n) >= n // 2, size, 0.0), x, window=w,
                  w_bias=1e-4, viscous_prior=1.0)[n // 2]
        g0 = wglr(base + noise, x, window=w, w_bias=1e-4, viscous_prior=1.0)[n // 2]
        missed += g1 < thr
        exceed += g0 > 2.0  # a low threshold so that exceedances are observable
    return {'trials': trials, 'threshold': float(thr), 'mdr_measured': missed / trials,
            'mdr_target': 1e-3, 'p_exceed_2_measured': exceed / trials,
            'p_exceed_2_chi2': float(stats.chi2.sf(2.0, 1))}


def _summary(values) -> dict:
    values = np.asarray(values, dtype=float)
    return {'min': float(values.min()), 'median': float(np.median(values)),
            'mean': float(values.mean()), 'max': float(values.max())}


def timing_pass(path: pathlib.Path, manifest: dict, items: list[dict],
                repeats: int = 3, count: int = 100) -> dict:
    """Return per-stage wall and CPU times over all windows, each the minimum of repeats.

    The machine is shared: a wall-clock run measures the other processes as much as this
    code. Each window is run ``repeats`` times; per stage we keep the fastest wall time
    and the smallest CPU time of this thread (``time.thread_time``: the time the stage
    actually ran, which is what an otherwise idle computer would take). The load average
    before and after is recorded beside.
    """
    from rwa_monitor.telemetry.fss_model import load_model
    model = load_model()
    count = min(count, len(items))
    stages = ('changepoints', 'least_squares', 'assignment', 'classification', 'total')
    wall: dict[str, list[float]] = {k: [] for k in stages}
    cpu: dict[str, list[float]] = {k: [] for k in stages}
    load_before = os.getloadavg()
    per_status = count // len(STATUSES)
    chosen = [(e, it) for e, it in zip(manifest['windows'], items)
              if int(e['file'].split('_')[-1][:4]) < per_status]
    for entry, item in chosen:
        speed, friction = fss.load_window(path, entry)
        best_wall: dict[str, float] = {}
        best_cpu: dict[str, float] = {}
        for _ in range(repeats):
            ext = extract(speed, friction)
            t0, c0 = time.perf_counter(), time.thread_time()
            model.predict(item['features'])
            run_wall = dict(ext.timings, classification=time.perf_counter() - t0)
            run_cpu = dict(ext.cpu_timings, classification=time.thread_time() - c0)
            for run, best in ((run_wall, best_wall), (run_cpu, best_cpu)):
                run['total'] = sum(run.values())
                for k, v in run.items():
                    best[k] = min(best.get(k, np.inf), v)
        for k in stages:
            wall[k].append(best_wall[k])
            cpu[k].append(best_cpu[k])
    return {'wall': {k: _summary(v) for k, v in wall.items()},
            'cpu': {k: _summary(v) for k, v in cpu.items()}, 'repeats': repeats,
            'windows': len(chosen),
            'load_average_before': list(load_before),
            'load_average_after': list(os.getloadavg())}


def bins_sweep(items: list[dict], splits: int, bins=(5, 10, 20, 40)) -> list[dict]:
    """Return the FSS diagonal and nominal false flags vs histogram bins (Fig. 12)."""
    rows = []
    for n_bins in bins:
        res = classification(items, splits, bins=n_bins)
        m = res['matrix']
        rows.append({'bins': n_bins, 'fss1': m['fss1']['fss1']['mean'],
                     'fss2': m['fss2']['fss2']['mean'],
                     'nominal_fss1': m['nominal']['fss1']['mean'],
                     'nominal_fss2': m['nominal']['fss2']['mean']})
    return rows


def changepoint_truth(path: pathlib.Path, manifest: dict, count: int) -> dict:
    """Return false and missed changepoints per window against the simulator's truth."""
    false, missed, big_missed, excess_cp, excess_naive = [], [], [], [], []
    right_system, matched = 0, 0
    config = FssConfig()
    for entry in manifest['windows'][:count]:
        speed, friction = fss.load_window(path, entry)
        with np.load(path / entry['file']) as data:
            true = np.flatnonzero(data['jump'])
            true_system = data['jump'][true]
        cps = detect_changepoints(friction, speed)
        d = np.abs(cps.changepoints[:, None] - true[None, :]) if true.size else None
        near = d.min(axis=1) <= 3 if d is not None else np.zeros(cps.changepoints.size, bool)
        false.append(int(np.sum(~near)))
        hit = d.min(axis=0) <= 3 if d is not None else np.zeros(0, bool)
        missed.append(int(np.sum(~hit)))
        gaps = np.diff(np.concatenate(([0], true, [speed.size])))
        isolated = (gaps[:-1] > 2 * config.wglr_window) & (gaps[1:] > 2 * config.wglr_window)
        big_missed.append(int(np.sum(~hit & isolated)))
        sigma = estimate_sigma(friction, speed, 1.0)
        ext = extract(speed, friction, config)
        if true.size and ext.accepted.size:
            dist = np.abs(ext.accepted[:, None] - true[None, :])
            hit = dist.min(axis=1) <= 3
            nearest = true_system[dist.argmin(axis=1)]
            matched += int(hit.sum())
            right_system += int(np.sum(hit & (nearest == ext.systems_of)))
        excess_cp.append(ext.rmse - sigma)
        excess_naive.append(fit_intervals(friction, speed, []).rmse - sigma)
    return {'windows': count, 'false_per_window': float(np.mean(false)),
            'missed_per_window': float(np.mean(missed)),
            'missed_isolated_per_window': float(np.mean(big_missed)),
            'true_per_window': float(np.mean([e['n_jumps'] for e in
                                              manifest['windows'][:count]])),
            'excess_rmse_with_cp': excess_cp, 'excess_rmse_naive': excess_naive,
            'assigned_to_the_true_system': right_system / max(matched, 1)}


def beam_effect(path: pathlib.Path, manifest: dict, count: int,
                beams=(8, 32, 64, 256), reference: int = 4096) -> dict:
    """Return, per beam, agreement with a much wider beam and the DP time (Fig. 10)."""
    cases = []
    for entry in manifest['windows'][:count]:
        speed, friction = fss.load_window(path, entry)
        cps = detect_changepoints(friction, speed)
        fit = fit_intervals(friction, speed, cps.changepoints)
        signs = np.where(np.diff(fit.dry) >= 0, 1, -1)
        cases.append((fit.changepoints, signs, fit.rejection_cost / (2 * fit.sigma2),
                      speed.size))
    systems = FssConfig().systems
    ref = [assign_changepoints(*c, systems, beam=reference) for c in cases]
    rows = []
    for beam in beams:
        same, gap, times, exact = [], [], [], []
        for case, r in zip(cases, ref):
            t0 = time.perf_counter()
            a = assign_changepoints(*case, systems, beam=beam)
            times.append(time.perf_counter() - t0)
            same.append(bool(np.array_equal(a.inputs, r.inputs)))
            gap.append(r.score - a.score)
            exact.append(a.exact)
        rows.append({'beam': beam, 'same_inputs': float(np.mean(same)),
                     'mean_score_gap': float(np.mean(gap)), 'max_score_gap': float(np.max(gap)),
                     'exact': float(np.mean(exact)), 'median_s': float(np.median(times)),
                     'max_s': float(np.max(times))})
    return {'windows': count, 'reference_beam': reference, 'rows': rows,
            'reference_exact': float(np.mean([r.exact for r in ref]))}


def run(out_dir: pathlib.Path, quick: bool) -> dict:
    """Run every experiment; write fss.json, plots and the fss section of results.md."""
    from bench import fss_sizes
    from rwa_monitor.telemetry.fss_model import load_model
    started = time.perf_counter()
    sizes = fss_sizes.run_sizes(quick)
    paper = fss_sizes.paper_examples(load_model(), quick)
    path = _dataset(quick)
    manifest = fss.load_manifest(path)
    items = fss.dataset_extractions(path)  # cached per code and parameters
    stats_ = [it['stats'] for it in items]
    timing = timing_pass(path, manifest, items, repeats=3, count=25 if quick else 100)
    splits = 5 if quick else 30
    results = {
        'dataset': {'path': str(path), 'windows': len(items), 'per_status': manifest[
            'per_status'], 'seed': manifest['seed'], 'n_samples': manifest['n_samples']},
        'classification': classification(items, splits),
        'classification_paper_levels': classification(items, splits, use='levels'),
        'arl': arl(),
        'arl_check': arl_check(2000 if quick else 20000),
        'changepoints': changepoint_truth(path, manifest, 10 if quick else 100),
        'rejections': np.bincount(np.minimum([s['rejected'] for s in stats_], 6),
                                  minlength=7).tolist(),
        'dp': {'changepoints': [s['detected'] for s in stats_],
               'rejected': [s['rejected'] for s in stats_],
               'iterations': [s['iterations'] for s in stats_],
               'exact': float(np.mean([s['exact'] for s in stats_]))},
        'beam': beam_effect(path, manifest, 10 if quick else 60),
        'bins': bins_sweep(items, splits),
        'held_out': shipped_model_held_out(quick),
        'timing_s': timing,
        'sizes': sizes,
        'paper_examples': paper,
    }
    results['goals'] = goals(results)
    results['bench_seconds'] = time.perf_counter() - started
    from bench import fss_report
    fss_report.plots(out_dir, results)
    report.write_json(out_dir, 'fss', results)
    if quick:
        print(fss_report.markdown(results))
    else:
        report.update_section('fss', fss_report.markdown(results))
    return results


def goals(results: dict) -> dict:
    """Return the issue's goals with the measured values and whether each is met."""
    m = results['classification']['matrix']
    worst = min(m[a][a]['mean'] for a in ANOMALIES)
    nominal = results['classification']['nominal_any_flag']['mean']
    t = results['timing_s']['cpu']
    # Timing goals: the thread's CPU time per stage, minimum of 3 runs (timing_pass).
    return {'legacy_detection_min_over_anomalies': {'value': worst, 'goal': 0.97,
                                                    'met': worst >= 0.97},
            'legacy_nominal_flagged': {'value': nominal, 'goal': 0.03,
                                       'met': nominal <= 0.03},
            'changepoint_cpu_median_s': {'value': t['changepoints']['median'], 'goal': 0.05,
                                         'met': t['changepoints']['median'] <= 0.05},
            'assignment_cpu_max_s': {'value': t['assignment']['max'], 'goal': 0.1,
                                     'met': t['assignment']['max'] <= 0.1}}


def rerun(parts: list[str], out_dir: pathlib.Path = report.RESULTS_DIR) -> dict:
    """Re-measure only ``parts`` ('sizes', 'paper') on their scoring seeds; rewrite the doc.

    The other results are read back from ``out_dir/fss.json`` (the last full run), and
    the fss section of docs/results.md is written from them all through
    report.update_section, as :func:`run` does.
    """
    import json

    from bench import fss_report, fss_sizes
    from rwa_monitor.telemetry.fss_model import load_model
    results = json.loads((out_dir / 'fss.json').read_text())
    started = time.perf_counter()
    if 'sizes' in parts:
        results['sizes'] = fss_sizes.run_sizes(False)
        fss_report.sizes_plots(out_dir, results['sizes'])
    if 'paper' in parts:
        results['paper_examples'] = fss_sizes.paper_examples(load_model(), False)
    results.setdefault('reruns', []).append(
        {'parts': parts, 'seconds': time.perf_counter() - started})
    report.write_json(out_dir, 'fss', results)
    report.update_section('fss', fss_report.markdown(results))
    return results


if __name__ == '__main__':
    import sys
    rerun(sys.argv[1:] or ['paper'])
