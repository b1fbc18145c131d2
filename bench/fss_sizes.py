"""FSS detection against fault size at realistic magnitudes, learned and baseline side by side.

Every window is judged against its wheel's nominal reference, a separate nominal window
of the same wheel (commissioning). The switching laws of stage 3 are estimated from
nominal commissioning windows (core/fss/laws.py), not copied from the simulator. The SVMs
are trained on windows with anomalies drawn x1.1-x3 (sim/fss.py ANOMALY_SIZE); the
baseline (core/fss/baseline.py) only sets its thresholds on the training set's nominal
windows. Tested on fresh windows per anomaly and size: probability of detecting the right
kind, ROC (right kind detected against nominal windows flagged with that kind as the
threshold varies), smallest size found >= 90 %.

Seeds are fixed before any result: development 11-14 (used while building, and by
``--quick``), scoring 2001-2003 and 2104 (the tables of docs/results.md; 1001-1004 were
set aside once a quick run had shown results on them, 2004 once the paper-Example table
had been read).
"""

from __future__ import annotations

from dataclasses import replace
import time

import numpy as np

from bench import fss_base_dry
from rwa_monitor.core.fss.baseline import (baseline_flags, baseline_scores, KINDS,
                                           nominal_thresholds)
from rwa_monitor.core.fss.classify import (noise_ratio_bound, relative_features,
                                           relative_verdict, train_model,
                                           viscous_significant, viscous_z)
from rwa_monitor.core.fss.laws import describe, estimate_systems
from rwa_monitor.core.fss.model import DEFAULT_SYSTEMS
from rwa_monitor.core.fss.pipeline import extract, FssConfig
from rwa_monitor.sim import fss

SIZES = (1.1, 1.25, 1.5, 2.0, 2.5, 3.0)
# The paper-Example scoring seed was 2004 until the FSS reference was refitted with the
# FSS jumps (issue 12, round 3); 2104 was fixed then, before any result on it was seen, and
# 2110 when the long-record reference changed (round 4; developed on 2100-2103).
SEEDS = {'development': {'laws': 11, 'train': 12, 'test': 13, 'paper': 2100},
         'scoring': {'laws': 2001, 'train': 2002, 'test': 2003, 'paper': 2110}}
BASELINE_FALSE_RATE = 0.02     # per anomaly, on the training set's nominal windows
WINDOW_HOURS = fss.WINDOW_SAMPLES / fss.RATE_HZ / 3600.0
PERIOD_HOURS = 20_000 / fss.RATE_HZ / 3600.0   # the node's window_period


def _pair(status: str, key: tuple, seed: int, size: float | None) -> tuple[dict, dict]:
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))
    sig = fss.simulate_wheel(fss.WINDOW_SAMPLES, status, rng, size=size)
    ref_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key + (1,)))
    ref = fss.simulate_wheel(fss.WINDOW_SAMPLES, 'nominal', ref_rng, wheel=sig['nominal'])
    return sig, ref


def _item(status: str, key: tuple, seed: int, size: float | None, config: FssConfig
          ) -> dict:
    sig, ref = _pair(status, key, seed, size)
    item = {'status': status, 'size': sig['size'],
            **fss.extraction_item(sig['speed'], sig['friction'], config)}
    r = fss.extraction_item(ref['speed'], ref['friction'], config)
    item['reference'] = {'features': r['features'], 'identifiable': r['identifiable'],
                         'ls': r['ls'], 'sigma': r['stats']['sigma'],
                         'viscous_se': r['stats']['viscous_se']}
    return item


def learned_decisions(model, item: dict) -> tuple[dict[str, float], bool]:
    """Return (decision per anomaly relative to the reference, unknown?).

    The SVM's w^T z + b on relative features; -inf where the diagnoser reports no
    anomaly whatever the SVM (an FSS with one level, a viscous coefficient that was not
    identifiable or not significantly above the reference's, core/calibrate.py
    ``diagnose_fss``); unknown by core/fss/classify.py relative_verdict (residual noise).
    """
    feats = relative_features(item['features'], item['reference']['features'])
    out = model.decision(feats)
    for name in out:
        if name.startswith('fss') and len(feats['levels'][int(name[3:]) - 1]) < 2:
            out[name] = -np.inf
    if not item['identifiable']:
        out['viscous'] = -np.inf
    ref = item['reference']
    if out['viscous'] > 0 and not viscous_significant(viscous_z(
            item['features']['viscous'], item['stats'].get('viscous_se', np.nan),
            ref['features']['viscous'], ref.get('viscous_se', np.nan))):
        out['viscous'] = -np.inf
    status, _, _ = relative_verdict({k: v > 0 for k, v in out.items()},
                                    item['stats']['sigma'], item['reference']['sigma'],
                                    noise_ratio_bound(model.spec.get('noise_ratio')))
    return out, status == 'unknown'


def _roc(scores_kind: np.ndarray, scores_nominal: np.ndarray) -> dict:
    values = np.concatenate((scores_kind, scores_nominal))
    finite = np.unique(values[np.isfinite(values)])
    thresholds = np.concatenate(([np.inf], finite[::-1], [-np.inf]))
    tpr = [float(np.mean(scores_kind > t)) if scores_kind.size else 0.0
           for t in thresholds[1:]]
    fpr = [float(np.mean(scores_nominal > t)) for t in thresholds[1:]]
    tpr, fpr = [0.0] + tpr, [0.0] + fpr
    f, t = np.asarray(fpr), np.asarray(tpr)
    auc = float(np.sum(np.diff(f) * (t[1:] + t[:-1]) / 2.0))
    at5 = float(max((t for t, f in zip(tpr, fpr) if f <= 0.05), default=0.0))
    return {'fpr': fpr, 'tpr': tpr, 'auc': auc, 'detection_at_5pct_false': at5}


def smallest_found(rates: dict[float, float], level: float = 0.9) -> float | None:
    """Return the smallest size from which every larger size is detected >= level."""
    found = None
    for size in sorted(rates, reverse=True):
        if rates[size] < level:
            break
        found = size
    return found


def run_sizes(quick: bool, seeds: str | None = None) -> dict:
    """Run the experiment; return the results (JSON-ready).

    ``seeds``: 'development' or 'scoring'; None: development when ``quick``.
    """
    started = time.perf_counter()
    seeds = seeds or ('development' if quick else 'scoring')
    seed = SEEDS[seeds]
    n_laws, n_train, n_nominal, n_per = (3, 6, 12, 3) if quick else (10, 30, 60, 15)
    sizes = (1.25, 2.0, 3.0) if quick else SIZES
    declared = FssConfig()
    commissioning = []
    for j in range(n_laws):
        rng = np.random.default_rng(np.random.SeedSequence(seed['laws'], spawn_key=(j,)))
        sig = fss.simulate_wheel(fss.WINDOW_SAMPLES, 'nominal', rng)
        commissioning.append((sig['speed'], sig['friction']))
    systems, law_report = estimate_systems(commissioning, DEFAULT_SYSTEMS, declared)
    config = replace(declared, systems=systems)
    laws = {'declared': [describe(s) for s in DEFAULT_SYSTEMS],
            'estimated': [describe(s) for s in systems], 'report': law_report,
            'assignment': _assignment_check(seed['test'], 4 if quick else 10, config)}
    train = [_item(st, (s_idx, 0, j), seed['train'], None, config)
             for s_idx, st in enumerate(fss.STATUSES) for j in range(n_train)]
    model = train_model(train, relative=True)
    nominal_train = [baseline_scores(it['ls'], it['reference']['ls'])
                     for it in train if it['status'] == 'nominal']
    thresholds = nominal_thresholds(nominal_train, BASELINE_FALSE_RATE)
    test = [_item('nominal', (0, 0, j), seed['test'], None, config)
            for j in range(n_nominal)]
    for s_idx, kind in enumerate(KINDS, start=1):
        for z_idx, size in enumerate(sizes):
            test += [_item(kind, (s_idx, z_idx + 1, j), seed['test'], size, config)
                     for j in range(n_per)]
    rows = []
    for it in test:
        dec, unknown = learned_decisions(model, it)
        base = baseline_scores(it['ls'], it['reference']['ls'])
        rows.append({'status': it['status'], 'size': it['size'], 'learned': dec,
                     'unknown': unknown, 'baseline': base,
                     'baseline_flags': baseline_flags(base, thresholds)})
    results = {'seeds': seed, 'seed_set': seeds, 'sizes': list(sizes),
               'counts': {'commissioning': n_laws, 'train_per_status': n_train,
                          'test_nominal': n_nominal, 'test_per_size': n_per},
               'laws': laws, 'baseline_thresholds': thresholds,
               'baseline_false_rate': BASELINE_FALSE_RATE,
               **summarise(rows, sizes), 'seconds': time.perf_counter() - started}
    return results


def summarise(rows: list[dict], sizes) -> dict:
    """Return detection per kind and size, false flags, ROC and smallest sizes found."""
    nominal = [r for r in rows if r['status'] == 'nominal']
    detection: dict = {'learned': {}, 'baseline': {}, 'unknown': {}}
    false = {'learned': {}, 'baseline': {}}
    roc: dict = {'learned': {}, 'baseline': {}}
    smallest: dict = {'learned': {}, 'baseline': {}}
    for kind in KINDS:
        rates_l, rates_b, unknown = {}, {}, {}
        for size in sizes:
            sel = [r for r in rows if r['status'] == kind and r['size'] == size]
            rates_l[size] = float(np.mean([r['learned'][kind] > 0 and not r['unknown']
                                           for r in sel]))
            rates_b[size] = float(np.mean([r['baseline_flags'][kind] for r in sel]))
            unknown[size] = float(np.mean([r['unknown'] for r in sel]))
        detection['learned'][kind] = rates_l
        detection['baseline'][kind] = rates_b
        detection['unknown'][kind] = unknown
        false['learned'][kind] = float(np.mean([r['learned'][kind] > 0 and not r['unknown']
                                                for r in nominal]))
        false['baseline'][kind] = float(np.mean([r['baseline_flags'][kind]
                                                 for r in nominal]))
        smallest['learned'][kind] = smallest_found(rates_l)
        smallest['baseline'][kind] = smallest_found(rates_b)
        of_kind = [r for r in rows if r['status'] == kind]
        for name, key in (('learned', 'learned'), ('baseline', 'baseline')):
            sk = np.array([r[key][kind] for r in of_kind], dtype=float)
            sn = np.array([r[key][kind] for r in nominal], dtype=float)
            sk = np.where(np.isnan(sk), -np.inf, sk)
            sn = np.where(np.isnan(sn), -np.inf, sn)
            roc[name][kind] = _roc(sk, sn)
    learned_any = [any(v > 0 for v in r['learned'].values()) and not r['unknown']
                   for r in nominal]
    any_false = {'learned': float(np.mean(learned_any)),
                 'baseline': float(np.mean([any(r['baseline_flags'].values())
                                            for r in nominal])),
                 'unknown': float(np.mean([r['unknown'] for r in nominal]))}
    wrong = {}
    for kind in KINDS:
        sel = [r for r in rows if r['status'] == kind]
        wrong[kind] = {'learned': float(np.mean([any(r['learned'][k] > 0 for k in KINDS
                                                     if k != kind) and not r['unknown']
                                                 for r in sel])),
                       'baseline': float(np.mean([any(r['baseline_flags'][k] for k in KINDS
                                                      if k != kind) for r in sel]))}
    return {'detection': detection, 'false_flags': false, 'any_false': any_false,
            'wrong_kind': wrong, 'roc': roc, 'smallest_90': smallest}


def _assignment_check(seed: int, count: int, estimated: FssConfig) -> dict:
    """Return per law set the accepted changepoints on a true jump given to its FSS.

    Declared and estimated laws, on nominal windows of the test seed (spawn key 9).
    """
    out = {}
    for name, config in (('declared', FssConfig()), ('estimated', estimated)):
        right = matched = 0
        for j in range(count):
            rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(9, j)))
            sig = fss.simulate_wheel(fss.WINDOW_SAMPLES, 'nominal', rng)
            true = np.flatnonzero(sig['jump'])
            ext = extract(sig['speed'], sig['friction'], config)
            if not (true.size and ext.accepted.size):
                continue
            dist = np.abs(ext.accepted[:, None] - true[None, :])
            hit = dist.min(axis=1) <= 3
            nearest = sig['jump'][true][dist.argmin(axis=1)]
            matched += int(hit.sum())
            right += int(np.sum(hit & (nearest == ext.systems_of)))
        out[name] = right / max(matched, 1)
    out['windows'] = count
    return out


PAPER_WHEEL = {'base_dry': 1.0, 'viscous': 1.0, 'noise_std': 0.025}   # normalised
PAPER_CASES = (('nominal', 'nominal', None), ('dry +50 %', 'dry', 1.5),
               ('viscous +50 %', 'viscous', 1.5))


def _si_window(status: str, key: tuple, seed: int, size: float | None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))
    sig = fss.simulate_wheel(fss.WINDOW_SAMPLES, status, rng, wheel=PAPER_WHEEL, size=size)
    speed, friction = fss.to_si(sig['speed'], sig['friction'])
    return np.arange(speed.size) / fss.RATE_HZ, speed, friction


def model1_block(time: np.ndarray, speed: np.ndarray, friction: np.ndarray) -> dict:
    """Return a calibration block whose nominal friction model is model (1) alone.

    The same contract as core/calibrate.py ``calibrate_wheel`` (friction_model, noise,
    speed range, fss reference through its own ``noise_profile`` and ``fss_reference``),
    with the nominal fitted by least squares on coulomb + viscous only.
    """
    from rwa_monitor.core import calibrate as cal
    h = -np.column_stack([np.sign(speed), speed])
    dry, viscous = np.linalg.lstsq(h, friction, rcond=None)[0]
    model = {'weights': {'dry': float(dry), 'viscous': float(viscous)}, 'effects': []}
    noise = cal.noise_profile(speed, friction - cal.nominal_prediction(model, speed))
    return {'friction_model': model, 'noise': noise,
            'speed_range_rad_s': [float(np.min(speed)), float(np.max(speed))],
            'fss': cal.fss_reference(speed, friction, model, noise)}


def paper_examples(model, quick: bool, seed: int | None = None) -> dict:
    """Return the paper-Example windows judged against a calibration from another window.

    A wheel of the FSS paper's Examples 1-2 with nominal base dry 1 and viscous 1
    (normalised; SI through sim/fss.py's scales, the project's sign). Calibration: one
    separate nominal window, by core/calibrate.py ``calibrate_wheel`` (what
    ``rwa-monitor calibrate`` writes) and by a model-(1) nominal (:func:`model1_block`).
    Then ``count`` windows of each case through core/calibrate.py ``diagnose_fss`` with
    the given (shipped) model, and the same windows without calibration.
    """
    from rwa_monitor.core import calibrate as cal
    from rwa_monitor.core.fss.pipeline import diagnose
    if seed is None:
        seed = SEEDS['development' if quick else 'scoring']['paper']
    count = 3 if quick else 10
    t, w, f = _si_window('nominal', (0,), seed, None)
    started = time.perf_counter()
    identified, warnings = cal.calibrate_wheel('rw1', t, w, f)
    seconds = time.perf_counter() - started
    # A longer commissioning record: three windows of the same wheel end to end (6.7 h),
    # in which the slow FSS visits its lowest configuration (see docs/fss.md).
    parts = [(t, w, f)] + [_si_window('nominal', (0, k), seed, None) for k in (1, 2)]
    long = [np.concatenate([p[i] for p in parts]) for i in range(3)]
    long[0] = np.arange(long[1].size) / fss.RATE_HZ
    blocks = {'calibrate': identified, 'model1': model1_block(t, w, f),
              'model1_3windows': model1_block(*long)}
    out: dict = {'seed': seed, 'windows_per_case': count,
                 'calibrate_seconds': seconds,
                 'calibrate_warnings': len(warnings),
                 'calibrate_effects': [e['name'] for e in
                                       identified['friction_model'].get('effects') or []],
                 'references': {k: b['fss'] for k, b in blocks.items()},
                 'model_thresholds': single_thresholds(model), 'cases': {}}
    for c_idx, (label, status, size) in enumerate(PAPER_CASES, start=1):
        rows = {name: [] for name in list(blocks) + ['uncalibrated']}
        for j in range(count):
            t, w, f = _si_window(status, (c_idx, j), seed, size)
            for name, block in blocks.items():
                res = cal.diagnose_fss(block, t, w, f, model, FssConfig())
                ref = block['fss']
                rows[name].append({'status': res['status'], 'flags': res['anomalies'],
                                   'base_dry': res['estimates']['base_dry_nm']
                                   / ref['base_dry_nm'],
                                   'viscous': res['estimates']['viscous_nms']
                                   / ref['viscous_nms']})
            res = diagnose(w, f, t, model, FssConfig())
            rows['uncalibrated'].append({
                'status': 'anomalous' if any(res['anomalies'].values()) else 'nominal',
                'flags': res['anomalies'],
                'base_dry': res['estimates']['base_dry_nm'] / fss.TORQUE_SCALE_NM,
                'viscous': res['estimates']['viscous_nms'] * fss.SPEED_SCALE_RAD_S
                / fss.TORQUE_SCALE_NM})
        out['cases'][label] = {name: verdicts(status, r) for name, r in rows.items()}
    out['base_dry_information'] = fss_base_dry.run(quick)
    return out


def single_thresholds(model) -> dict[str, float]:
    """Return the relative base dry and viscous at which the model's SVM flags (w z + b = 0)."""
    out = {}
    for name in ('dry', 'viscous'):
        entry = model.spec['models'][name]
        out[name] = float(entry['mean'][0]
                          - entry['intercept'] * entry['scale'][0] / entry['coef'][0])
    return out


def verdicts(expected: str, rows: list[dict]) -> dict:
    """Return counts: named right, missed, wrong class, unknown; median estimates."""
    right = missed = wrong = unknown = 0
    for r in rows:
        flagged = {k for k, v in r['flags'].items() if v}
        if r['status'] == 'unknown':
            unknown += 1
        elif expected == 'nominal':
            right += not flagged
            wrong += bool(flagged)
        elif flagged == {expected}:
            right += 1
        elif flagged - {expected}:
            wrong += 1
        else:
            missed += 1
    return {'windows': len(rows), 'right': right, 'missed': missed, 'wrong': wrong,
            'unknown': unknown,
            'base_dry_median': float(np.median([r['base_dry'] for r in rows])),
            'base_dry_std': float(np.std([r['base_dry'] for r in rows], ddof=1))
            if len(rows) > 1 else float('nan'),
            'viscous_median': float(np.median([r['viscous'] for r in rows]))}
