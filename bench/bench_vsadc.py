"""Gyro drift/bias diagnosis: VSADC against the paper's supervised baselines, one run.

Scenarios (rwa_monitor.sim.aocs): fast / medium / slow drift and a bias step on gyro x at
900 s of a 3600 s, 4 Hz record; several seeds. Per run the supervised baselines train on a
random 70 % of the rows (vsadc-gyro-drift paper, section 4.1) and every method (VSADC too)
is scored on the other 30 %: accuracy, FAR, MAR, IDR (READING-NOTES definitions) and the
detection delay. Also: VSADC with the paper-literal reading of Algorithm 1, the false
alarms on the two healthy axes, the streaming throughput, and the continuous-nominal
option on long runs with an orbital thermal bias. Writes bench/results/vsadc.json, a plot
and the ``vsadc`` section of docs/results.md.
"""

from __future__ import annotations

from dataclasses import replace
import os
import pathlib
import time
from typing import Any
import warnings

import numpy as np

from bench import report
from rwa_monitor.core import baselines
from rwa_monitor.core.vsadc import VsadcAxis
from rwa_monitor.pipelines import vsadc as pipeline
from rwa_monitor.sim.aocs import (AocsConfig, DRIFT_SLOPES, GyroFault, named_fault,
                                  simulate_aocs)

SCENARIOS = ('fast', 'medium', 'slow', 'bias')
DURATION_S, FAULT_S, TS = 3600.0, 900.0, 0.25
#: Fresh seeds of this round, fixed before any result (tuning used seeds 0-3; the
#: previous rounds scored 100-105). Three, to keep the run near 20 machine minutes.
SEEDS = tuple(range(4200, 4203))
QUICK_SEEDS = (100,)
TRAIN_FRACTION = 0.7
#: Records the ``cross`` protocol trains on: other seeds, half of each fault sign.
CROSS_RECORDS = 4
#: Algorithm 1 read literally: one window everywhere, limits from the last SW sigmas,
#: hysteresis on the mean, no margins.
PAPER_LITERAL = {'sigma_window': 'auto', 'reference_window': 'auto', 'margin': 1.0,
                 'exit_limit': 'mean', 'exit_margin': 1.0, 'adaptive': False,
                 'recovery_fraction': 1.0}

# The paper's Tables 3-6 (fast, medium, slow). Two cells garbled by the extraction are
# read through IDR = FAR + MAR: RBF MAR fast 2.5 ("25"), kNN-2 FAR slow 7.93 ("193").
PAPER: dict[str, dict[str, tuple[float, float, float]]] = {
    'accuracy': {
        'knn-1': (95.95, 90.8, 82.86), 'knn-2': (95.87, 90.59, 82.49),
        'knn-3': (95.8, 90.44, 82.2), 'knn-4': (95.77, 90.34, 81.93),
        'knn-5': (95.74, 90.24, 81.77), 'knn-10': (95.64, 89.97, 80.94),
        'knn-15': (95.51, 89.69, 80.42), 'knn-20': (95.41, 89.36, 79.98),
        'knn-50': (95.09, 88.5, 78.39), 'knn-100': (94.73, 87.78, 76.59),
        'knn-200': (94.26, 86.8, 74.6), 'svm-linear': (1.51, 4.34, 8.85),
        'svm-poly2': (96.13, 90.95, 83.15), 'svm-poly3': (97.32, 93.97, 89.34),
        'svm-poly4': (46.89, 58.36, 74.67), 'svm-rbf': (96.95, 92.98, 86.97),
        'naive-bayes': (97.49, 93.99, 88.88), 'vsadc': (98.21, 96.45, 92.98)},
    'mar': {
        'knn-1': (3.65, 8.71, 16.6), 'knn-2': (3.8, 9.05, 17.27), 'knn-3': (3.78, 9.03, 17.26),
        'knn-4': (3.84, 9.22, 17.7), 'knn-5': (3.83, 9.19, 17.69),
        'knn-10': (3.96, 9.49, 18.69), 'knn-15': (4.06, 9.71, 19.17),
        'knn-20': (4.19, 10.09, 19.7), 'knn-50': (4.56, 10.95, 21.5),
        'knn-100': (4.96, 11.71, 23.66), 'knn-200': (5.49, 12.82, 26.04),
        'svm-linear': (97.97, 94.09, 87.76), 'svm-poly2': (3.8, 8.97, 17.04),
        'svm-poly3': (2.68, 5.32, 9.45), 'svm-poly4': (58.92, 42.95, 21.04),
        'svm-rbf': (2.5, 5.85, 11.06), 'naive-bayes': (2.35, 5.31, 9.97),
        'vsadc': (2.38, 1.85, 2.69)},
    'far': {
        'knn-1': (1.85, 4.05, 8.09), 'knn-2': (1.8, 3.9, 7.93), 'knn-3': (1.93, 4.26, 8.48),
        'knn-4': (1.91, 4.2, 8.42), 'knn-5': (1.96, 4.38, 8.74),
        'knn-10': (1.96, 4.48, 9.01), 'knn-15': (2.04, 4.67, 9.39),
        'knn-20': (2.05, 4.77, 9.54), 'knn-50': (2.12, 5.17, 10.27),
        'knn-100': (2.22, 5.48, 10.98), 'knn-200': (2.33, 5.81, 11.83),
        'svm-linear': (35.02, 36.41, 38.33), 'svm-poly2': (1.43, 3.51, 7.0),
        'svm-poly3': (0.93, 2.96, 5.54), 'svm-poly4': (12.4, 12.84, 13.1),
        'svm-rbf': (1.63, 3.86, 7.63), 'naive-bayes': (1.02, 2.94, 5.71),
        'vsadc': (0.01, 3.02, 7.36)},
    'idr': {
        'knn-1': (5.49, 12.76, 24.7), 'knn-2': (5.6, 13.04, 25.2),
        'knn-3': (5.71, 13.29, 25.75), 'knn-4': (5.75, 13.41, 26.12),
        'knn-5': (5.79, 13.58, 26.43), 'knn-10': (5.93, 13.97, 27.71),
        'knn-15': (6.1, 14.38, 28.56), 'knn-20': (6.24, 14.86, 29.23),
        'knn-50': (6.68, 16.13, 31.77), 'knn-100': (7.18, 17.19, 34.64),
        'knn-200': (7.83, 18.62, 37.88), 'svm-linear': (float('nan'),) * 3,
        'svm-poly2': (5.23, 12.48, 24.04), 'svm-poly3': (3.61, 8.27, 14.99),
        'svm-poly4': (71.32, 55.79, 34.15), 'svm-rbf': (4.13, 9.71, 18.69),
        'naive-bayes': (3.37, 8.24, 15.67), 'vsadc': (2.39, 4.87, 10.05)},
}
METRICS = ('accuracy', 'far', 'mar', 'idr')


def scores(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Return accuracy, FAR, MAR and IDR in % (paper eqs. (1)-(2), READING-NOTES).

    FAR = time labelled faulty while healthy / time faulty; MAR = time labelled healthy
    while faulty / time faulty; IDR = FAR + MAR; accuracy = share of rows whose label
    (0/1/2) is right. Rows are equally spaced, so times are row counts. ``switches``
    counts label changes along the rows (the paper's "detection noise"; the truth of a
    record changes 1 or 2 times).
    """
    faulty = truth != 0
    t_faults = max(int(faulty.sum()), 1)
    far = 100.0 * np.sum((pred != 0) & ~faulty) / t_faults
    mar = 100.0 * np.sum((pred == 0) & faulty) / t_faults
    return {'accuracy': 100.0 * float(np.mean(pred == truth)), 'far': float(far),
            'mar': float(mar), 'idr': float(far + mar),
            'switches': int(np.count_nonzero(np.diff(pred)))}


def delay(time_s: np.ndarray, pred: np.ndarray, onset_s: float) -> float:
    """Return seconds from the fault onset to the first faulty label at or after it."""
    hit = np.flatnonzero((time_s >= onset_s) & (pred != 0))
    return float(time_s[hit[0]] - onset_s) if len(hit) else float('nan')


def scenario(name: str, seed: int) -> GyroFault:
    """Return the fault of a bench record: the named speed, a seeded level and sign.

    The level is drawn from +-[1e-4, 3e-4] rad/s so that a classifier cannot learn the
    state from the fault's size alone (drift below the level, bias at it).
    """
    rng = np.random.default_rng(10_000 + seed)
    level = float(rng.uniform(1.0e-4, 3.0e-4) * rng.choice((-1.0, 1.0)))
    return named_fault(name, 'x', FAULT_S, level)


def _baseline_features(tele, config: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Return (raw residuals held over dropouts, window means) on gyro x."""
    raw = baselines.residuals(tele.time, tele.gyro, tele.attitude, tele.reference_rate, 0,
                              config['max_gap'])
    held = raw.copy()
    last = np.full(2, np.nan)
    for k in range(len(held)):                       # hold the last reading over a dropout
        if np.isfinite(held[k]).all():
            last = held[k]
        else:
            held[k] = last
    return held, baselines.smoothed_features(raw, config['window'])


def cross_training(name: str, seed: int, config: dict[str, Any]
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Return window-mean features and labels of CROSS_RECORDS other records of a scenario.

    Seeds ``seed + 1000 + j``, the first ones whose drawn fault sign fills half of the
    records with each sign; never the scored record.
    """
    feats, labels, signs = [], [], {1.0: 0, -1.0: 0}
    j = 0
    while len(feats) < CROSS_RECORDS:
        other_seed = seed + 1000 + j
        j += 1
        fault = scenario(name, other_seed)
        sign = 1.0 if fault.level > 0 else -1.0
        if signs[sign] >= CROSS_RECORDS // 2:
            continue
        signs[sign] += 1
        other = simulate_aocs(DURATION_S, fault=fault, seed=other_seed)
        x = _baseline_features(other, config)[1]
        ok = np.isfinite(x).all(axis=1)
        feats.append(x[ok])
        labels.append(other.truth['gyro_x'].astype(int)[ok])
    return np.concatenate(feats), np.concatenate(labels)


def _predict_all(x_train, y_train, x_test, seed, names) -> dict[str, np.ndarray]:
    out = {}
    ok_train = np.isfinite(x_train).all(axis=1)
    ok_test = np.isfinite(x_test).all(axis=1)
    for name in names:
        pred = np.zeros(len(x_test), dtype=int)
        pred[ok_test] = baselines.fit_predict(name, x_train[ok_train], y_train[ok_train],
                                              x_test[ok_test], seed)
        out[name] = pred
    return out


def one_run(name: str, seed: int, config: dict[str, Any]) -> dict[str, Any]:
    """Simulate one record; score VSADC (tuned and paper-literal) and every baseline.

    Baselines, three protocols: ``paper`` (per-sample residuals of eqs. (3), (7), random
    70/30 split of the record), ``smoothed`` (VSADC's window means, same split) and
    ``cross`` (window means, trained on 70 % of another record of the same scenario with
    its own seed and level, tested on this record's 30 %).
    """
    tele = simulate_aocs(DURATION_S, fault=scenario(name, seed), seed=seed)
    truth = tele.truth['gyro_x'].astype(int)
    labels, events, det = pipeline.label_series(tele, config)
    literal, _, _ = pipeline.label_series(tele, {**config, **PAPER_LITERAL})
    residual, _, _ = pipeline.label_series(tele, {**config, 'feature': 'residual'})
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(tele))
    n_train = int(TRAIN_FRACTION * len(tele))
    train, test = np.sort(order[:n_train]), np.sort(order[n_train:])
    raw, smooth = _baseline_features(tele, config)
    other_smooth, other_truth = cross_training(name, seed, config)
    names = list(baselines.methods())
    start = time.perf_counter()
    preds = {'paper': _predict_all(raw[train], truth[train], raw[test], seed, names),
             'smoothed': _predict_all(smooth[train], truth[train], smooth[test], seed, names),
             'cross': _predict_all(other_smooth, other_truth, smooth[test], seed, names)}
    fit_s = time.perf_counter() - start
    t_test, y_test = tele.time[test], truth[test]
    preds['paper']['vsadc'] = labels[test, 0].astype(int)
    preds['paper']['vsadc-literal'] = literal[test, 0].astype(int)
    preds['paper']['residual'] = residual[test, 0].astype(int)
    out: dict[str, Any] = {'level_rad_s': scenario(name, seed).level, 'baseline_fit_s': fit_s}
    for protocol, by_name in preds.items():
        out[protocol] = {m: {**scores(p, y_test), 'delay_s': delay(t_test, p, FAULT_S)}
                         for m, p in by_name.items()}
    first = [e for e in events if e.component == 'gyro_x']
    out['vsadc_events'] = [(e.kind, e.time, e.declared_time) for e in first]
    out['vsadc_full'] = {**scores(labels[:, 0].astype(int), truth),
                         'delay_s': delay(tele.time, labels[:, 0], FAULT_S)}
    out['onset_error_s'] = (first[0].time - FAULT_S) if first else float('nan')
    out['other_axes_alarm_pct'] = float(100.0 * np.mean(labels[:, 1:] != 0))
    out['counters'] = det.counters
    return out


def throughput(config: dict[str, Any], seconds: float = 2.0) -> dict[str, float]:
    """Return streaming rates: VsadcAxis updates/s, and full 3-axis rows/s (incl. q)."""
    tele = simulate_aocs(DURATION_S, fault=named_fault('medium', 'x', FAULT_S), seed=1)
    res = baselines.residuals(tele.time, tele.gyro, tele.attitude, tele.reference_rate, 0,
                              config['max_gap'])
    res = res[np.isfinite(res).all(axis=1)].tolist()
    kwargs = pipeline.detector_kwargs(config)
    axis_kwargs = {k: v for k, v in kwargs.items()
                   if k not in ('max_gap', 'norm_tolerance', 'axes')}
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        ax = VsadcAxis(**axis_kwargs)
        update = ax.update
        for x1, x2 in res:
            update(x1, x2)
        count += len(res)
    axis_rate = count / (time.perf_counter() - start)
    start = time.perf_counter()
    pipeline.label_series(tele, config)
    rows_rate = len(tele) / (time.perf_counter() - start)
    return {'axis_updates_per_s': axis_rate, 'detector_rows_per_s': rows_rate,
            'detector_axis_samples_per_s': 3 * rows_rate,
            'load_average_1min': os.getloadavg()[0]}


def tracking_study(config: dict[str, Any], seeds: tuple[int, ...]) -> dict[str, Any]:
    """Compare a fixed and a tracked nominal centre on 4 h records with a thermal bias.

    Two thermal amplitudes (the default 1e-6 rad/s and 1e-5 rad/s) and a slow drift at 3 h;
    FAR before the fault, MAR, accuracy and delay for both settings.
    """
    out: dict[str, Any] = {}
    duration, onset = 4 * 3600.0, 3 * 3600.0
    for amplitude in (1.0e-6, 1.0e-5):
        cfg = replace(AocsConfig(), gyro_thermal=amplitude)
        for tracking in (0, 1200, 'residual'):
            rows = []
            for seed in seeds:
                fault = GyroFault(0, onset, 2.0e-4, DRIFT_SLOPES['slow'])
                tele = simulate_aocs(duration, fault=fault, config=cfg, seed=seed)
                truth = tele.truth['gyro_x'].astype(int)
                setting = {'feature': 'residual'} if tracking == 'residual' else {
                    'nominal_tracking': tracking}
                labels, _, _ = pipeline.label_series(tele, {**config, **setting})
                s = scores(labels[:, 0].astype(int), truth)
                s['delay_s'] = delay(tele.time, labels[:, 0], onset)
                s['healthy_alarm_pct'] = float(100.0 * np.mean(labels[truth == 0, 0] != 0))
                s['other_axes_alarm_pct'] = float(100.0 * np.mean(labels[:, 1:] != 0))
                rows.append(s)
            out[f'{amplitude:g}/{tracking}'] = {k: float(np.nanmean([r[k] for r in rows]))
                                                for k in rows[0]}
    return out


def _fmt(x: float) -> str:
    return '—' if not np.isfinite(x) else f'{x:.2f}'


def _paper_tables(agg: dict[str, Any], names: list[str]) -> list[str]:
    lines = []
    for metric, title in (('accuracy', 'Accuracy (%)'), ('far', 'FAR (%)'),
                          ('mar', 'MAR (%)'), ('idr', 'IDR = FAR + MAR (%)')):
        rows = []
        for name in names:
            row = [name]
            for i, sc in enumerate(SCENARIOS):
                row.append(_fmt(agg[sc][name][metric]))
                if sc != 'bias':
                    row.append(_fmt(PAPER[metric].get(name, (float('nan'),) * 3)[i]))
            rows.append(row)
        lines += [f'**{title}**', '', report.table(
            ['method', 'fast', 'paper', 'medium', 'paper', 'slow', 'paper', 'bias'], rows), '']
    return lines


def _markdown(res: dict[str, Any]) -> str:
    agg, names = res['aggregate'], res['method_order']
    paper = agg['paper']
    baseline_names = [n for n in names if not n.startswith('vsadc') and n != 'residual']
    lines = [
        f'Gyro x faults at {FAULT_S:g} s of {DURATION_S:g} s records at 4 Hz '
        f'(rwa_monitor.sim.aocs, docs/simulators.md): fast / medium / slow drifts '
        f'({", ".join(f"{v:g}" for v in DRIFT_SLOPES.values())} rad/s per s) up to a seeded '
        'level in +-[1e-4, 3e-4] rad/s, then held (bias); "bias" = a step to such a level. '
        f'Seeds {res["seeds"]} (the VSADC settings were tuned on seeds 0-3). Protocol of the '
        'paper: each baseline trains on a random 70 % of the rows of the record, with the '
        'per-sample residuals of eqs. (3), (7) as features; every method, VSADC too, is '
        'scored on the other 30 %. SVMs train on a random '
        f'{baselines.DEFAULT_SVM_MAX_TRAIN} of the training rows (one-vs-all, two cores). '
        'Mean over seeds. "paper" = the vsadc-gyro-drift paper\'s Tables 3-6 (its own '
        'simulator: indicative only; FAR and MAR are normalised by the faulty time, which '
        'depends on the record layout). vsadc-literal = Algorithm 1 read literally '
        '(docs/vsadc.md). VSADC settings: ' + ', '.join(
            f'{k}={v}' for k, v in res['config'].items() if k in pipeline.DEFAULTS) + '.', '']
    cross = agg['cross']
    rows = [[m0] + [_fmt(paper[sc][m0][m]) for sc in SCENARIOS
                    for m in ('accuracy', 'idr', 'delay_s')] for m0 in ('residual', 'vsadc')]
    rows += [[n] + [_fmt(cross[sc][n][m]) for sc in SCENARIOS
                    for m in ('accuracy', 'idr', 'delay_s')] for n in baseline_names]
    lines += [f'**Headline, fair protocol: baselines trained on {CROSS_RECORDS} other records '
              '(own seeds and levels, both fault signs) on window means, never on the scored '
              'record; every method scored on the same 30 % test rows of the record. '
              'residual = the gyro-minus-star-tracker diagnosis (default settings, no '
              'calibration); vsadc = Algorithm 1 on the two residuals of the paper. Accuracy / '
              'IDR (%) / delay (s)**', '', report.table(
                  ['method'] + [f'{sc} {m}' for sc in SCENARIOS
                                for m in ('acc', 'IDR', 'delay')], rows), '']
    best = {sc: max((cross[sc][n]['accuracy'], n) for n in baseline_names)
            for sc in SCENARIOS}
    lines += ['Best cross-trained baseline by accuracy: ' + '; '.join(
        f'{sc} {best[sc][1]} {best[sc][0]:.2f} (residual {paper[sc]["residual"]["accuracy"]:.2f}'
        f', vsadc {paper[sc]["vsadc"]["accuracy"]:.2f})' for sc in SCENARIOS) + '.', '',
        '**The protocol of the paper** (each baseline trains on a random 70 % of the rows of '
        'the record it is scored on, so it sees the time neighbours of its test rows; kept for '
        'comparison with the tables of the paper only)', '']
    lines += _paper_tables(paper, names)
    rows = [[name] + [_fmt(paper[sc][name]['delay_s']) for sc in SCENARIOS] for name in names]
    lines += ['**Detection delay (s): first faulty label on a test row after the onset**', '',
              report.table(['method', *SCENARIOS], rows), '']
    rows = [[name] + [f'{paper[sc][name]["switches"]:.1f}' for sc in SCENARIOS]
            for name in names]
    lines += ['**Label changes along the test rows of a record** (detection noise; the '
              'truth changes 2 times, once for the bias step)', '',
              report.table(['method', *SCENARIOS], rows), '']
    for protocol, title in (
            ('smoothed', 'Baselines on the window means of VSADC, same random 70/30 split'),):
        rows = [[m0] + [_fmt(paper[sc][m0][m]) for sc in SCENARIOS
                        for m in ('accuracy', 'idr')] for m0 in ('residual', 'vsadc')]
        rows += [[n] + [_fmt(agg[protocol][sc][n][m]) for sc in SCENARIOS
                        for m in ('accuracy', 'idr')] for n in baseline_names]
        lines += [f'**{title}: accuracy / IDR (%)**', '', report.table(
            ['method'] + [f'{sc} {m}' for sc in SCENARIOS for m in ('acc', 'IDR')], rows), '']
    full = res['vsadc_detail']
    columns = ('accuracy', 'far', 'mar', 'idr', 'delay_s', 'onset_error_s',
               'other_axes_alarm_pct')
    rows = [[sc] + [_fmt(full[sc][k]) for k in columns] for sc in SCENARIOS]
    lines += ['**VSADC on every row of the records**', '', report.table(
        ['scenario', 'accuracy', 'FAR', 'MAR', 'IDR', 'delay (s)', 'onset estimate - truth (s)',
         'y, z alarmed (%)'], rows), '']
    lines += ['**Verdict against the goal** (VSADC accuracy >= paper, IDR <= paper, IDR below '
              'every baseline; paper protocol)', '']
    for i, sc in enumerate(SCENARIOS[:3]):
        ours = paper[sc]['vsadc']
        best = min((paper[sc][n]['idr'], n) for n in baseline_names)
        lines.append(
            f'- {sc}: accuracy {ours["accuracy"]:.2f} vs paper {PAPER["accuracy"]["vsadc"][i]}'
            f' ({"met" if ours["accuracy"] >= PAPER["accuracy"]["vsadc"][i] else "NOT met"});'
            f' IDR {ours["idr"]:.2f} vs paper {PAPER["idr"]["vsadc"][i]} '
            f'({"met" if ours["idr"] <= PAPER["idr"]["vsadc"][i] else "NOT met"}); best '
            f'baseline IDR {best[0]:.2f} ({best[1]}): '
            f'{"met" if ours["idr"] < best[0] else "NOT met"}.')
    tp = res['throughput']
    lines += ['', f'Throughput (streaming, one core of the 2-core machine shared with other '
              f'jobs, load average {tp["load_average_1min"]:.1f} during the measurement): '
              f'{tp["axis_updates_per_s"]:,.0f} VsadcAxis updates/s (one axis); the full '
              f'detector (star-tracker rate from q, three axes, input checks) '
              f'{tp["detector_rows_per_s"]:,.0f} rows/s = '
              f'{tp["detector_axis_samples_per_s"]:,.0f} axis-samples/s. Goal: >= 100,000 '
              'samples/s per axis.', '']
    rows = []
    for key, v in res['tracking'].items():
        amp, tracking = key.split('/')
        nominal = {'0': 'fixed (paper)', 'residual': 'residual diagnosis'}.get(
            tracking, f'tracked ({tracking})')
        rows.append([amp, nominal,
                     _fmt(v['healthy_alarm_pct']), _fmt(v['far']), _fmt(v['mar']),
                     _fmt(v['accuracy']), _fmt(v['delay_s']), _fmt(v['other_axes_alarm_pct'])])
    lines += ['**Continuous nominal estimate** (4 h records, slow drift on x at 3 h, orbital '
              'thermal gyro bias of the given amplitude in rad/s on every axis; '
              'docs/vsadc.md)', '',
              report.table(['thermal', 'nominal', 'x healthy time alarmed (%)', 'FAR (%)',
                            'MAR (%)', 'accuracy (%)', 'delay (s)', 'y, z alarmed (%)'], rows),
              '', 'Plot: bench/results/vsadc_slow_labels.png.']
    return '\n'.join(lines)


def _plot(out_dir: pathlib.Path, config: dict[str, Any], seed: int) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    tele = simulate_aocs(DURATION_S, fault=scenario('slow', seed), seed=seed)
    truth = tele.truth['gyro_x']
    labels, _, _ = pipeline.label_series(tele, config)
    feats = _baseline_features(tele, config)[0]          # the paper protocol's features
    ok = np.isfinite(feats).all(axis=1)
    rng = np.random.default_rng(seed)
    train = np.zeros(len(tele), bool)
    train[rng.permutation(len(tele))[:int(TRAIN_FRACTION * len(tele))]] = True
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(9, 7))
    axes[0].plot(tele.time, truth, 'k')
    axes[0].set_ylabel('truth')
    axes[1].plot(tele.time, labels[:, 0], 'C0')
    axes[1].set_ylabel('VSADC')
    for ax, name in zip(axes[2:], ('naive-bayes', 'svm-poly3')):
        test = ~train & ok
        pred = baselines.fit_predict(name, feats[train & ok], truth[train & ok].astype(int),
                                     feats[test], seed)
        ax.plot(tele.time[test], pred, '.', ms=1)
        ax.set_ylabel(name)
    axes[-1].set_xlabel('time (s)')
    fig.suptitle('slow drift on gyro x: labels (0 healthy, 1 drift, 2 bias); '
                 'baselines on their 30 % test rows')
    fig.tight_layout()
    fig.savefig(out_dir / 'vsadc_slow_labels.png', dpi=100)
    plt.close(fig)


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run the benchmark; write JSON, plot and the docs/results.md section."""
    config = {**pipeline.DEFAULTS, 'feature': 'paper'}
    seeds = QUICK_SEEDS if quick else SEEDS
    runs = {}
    for sc in SCENARIOS:
        runs[sc] = []
        for seed in seeds:
            runs[sc].append(one_run(sc, seed, config))
            print(f'  {sc} seed {seed}: vsadc {runs[sc][-1]["paper"]["vsadc"]}', flush=True)
    names = ['residual', 'vsadc', 'vsadc-literal', *baselines.methods()]
    aggregate: dict[str, Any] = {}
    warnings.simplefilter('ignore', RuntimeWarning)     # nanmean of never-detected delays
    for protocol in ('paper', 'smoothed', 'cross'):
        aggregate[protocol] = {
            sc: {name: {m: float(np.nanmean([r[protocol][name][m] for r in rs]))
                        for m in (*METRICS, 'delay_s', 'switches')}
                 for name in names if name in rs[0][protocol]}
            for sc, rs in runs.items()}
    detail = {sc: {**{k: float(np.nanmean([r['vsadc_full'][k] for r in rs]))
                      for k in (*METRICS, 'delay_s')},
                   **{k: float(np.nanmean([r[k] for r in rs]))
                      for k in ('onset_error_s', 'other_axes_alarm_pct')}}
              for sc, rs in runs.items()}
    result = {'config': config, 'seeds': list(seeds), 'method_order': names,
              'aggregate': aggregate, 'vsadc_detail': detail, 'runs': runs,
              'throughput': throughput(config, 0.5 if quick else 3.0),
              'tracking': tracking_study(config, seeds[:1])}
    report.write_json(out_dir, 'vsadc', result)
    _plot(out_dir, config, seeds[0])
    if not quick:
        report.update_section('vsadc', _markdown(result))
    else:
        print(_markdown(result))
    return result
