"""Acceptance of the calibrated detectors on the Basilisk bus (part of bench ``bus``).

Default guidance and null speed (wheels cross zero). One fault-free 3-hour run
(seed CALIBRATION_SEED) is calibrated with ``rwa-monitor calibrate``'s functions; the
evaluation runs use seeds EVAL_SEEDS, fixed before any result was seen (development used
seeds below 100). Run i injects fault FAULTS[i % 4] on wheel WHEELS[(i + i // 4) % 4] at
FAULT_TIME_S. The LLR pipeline runs on each run with and without the calibration.

Throughput (:func:`throughput`): on the first evaluation run, per wheel, the streaming
path (llr_detector's: ``LLRDetector.update_nominal``, the nominal lookup and the sample in
one compiled call; nodes/calibration.py) and the batch
path (``NominalWheel.residual`` + ``detect_batch``), with and without calibration,
SPEED_REPEATS times each in the main process after the pool has finished; medians of
samples per CPU second of the process (the shared machine's load inflates wall time).

Per run and mode: declarations (revision 0) per wheel with change and declaration
times, the final kind (last revision of that change) and whether it is confirmed.
"""

from __future__ import annotations

import pathlib
import time
from typing import Any

import numpy as np
from scipy import stats

# Fixed before any result of this session was seen. Earlier acceptance runs used
# calibration seed 1000 / evaluation 3000-3009, then 4020 / 4000-4019, then 6020 /
# 6000-6019: those are spent (seen while developing) and are development seeds now, like
# every seed below 100.
# 40 runs, 10 per fault, so that one miss in a fault still reads 90 % (with 5 runs per
# fault the 90 % goal allowed no miss at all).
CALIBRATION_SEED = 7020
EVAL_SEEDS = tuple(range(7000, 7020)) + tuple(range(7100, 7120))
SPENT_SEEDS = '3000-3009, 4000-4020 and 6000-6020'
STREAMING_GOAL = 300_000.0   # samples/s, issue 12 item 3 (model (1) throughput kept)
BATCH_GOAL = 3_000_000.0
SPEED_REPEATS = 5
HOURS = 3.0
FAULT_TIME_S = 5400.0
RAMP_S = 1800.0
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
FAULTS = (('dry step', 'dry', 'dry=3e-4'),
          ('viscous step', 'viscous', 'viscous=3e-6'),
          ('dry ramp', 'dry', f'dry=3e-4,ramp={RAMP_S:g}'),
          ('viscous ramp', 'viscous', f'viscous=3e-6,ramp={RAMP_S:g}'))


def plan(seeds: tuple[int, ...] = EVAL_SEEDS) -> list[dict[str, Any]]:
    """Return the evaluation runs: seed, fault name, expected kind, wheel, spec."""
    runs = []
    for i, seed in enumerate(seeds):
        name, kind, spec = FAULTS[i % len(FAULTS)]
        wheel = WHEELS[(i + i // len(FAULTS)) % len(WHEELS)]
        runs.append({'seed': seed, 'fault': name, 'expected': kind, 'wheel': wheel,
                     'spec': f'friction:{wheel}:{FAULT_TIME_S:g}:{spec}'})
    return runs


def _cache_path(seed: int, specs: list[str], hours: float) -> pathlib.Path:
    """Return the cached telemetry file of a run, keyed by the simulator's source too."""
    import hashlib

    import rwa_monitor.sim as sim
    from bench.report import REPO
    digest = hashlib.sha256(repr((seed, specs, hours)).encode())
    for name in ('basilisk.py', 'basilisk_config.py'):
        digest.update((pathlib.Path(sim.__file__).parent / name).read_bytes())
    return REPO / 'data' / 'generated' / 'bus_acceptance' / (
        f'seed{seed}-{digest.hexdigest()[:16]}.csv')


def simulate(seed: int, specs: list[str], hours: float = HOURS):
    """Return the bus telemetry of one run (default scenario), cached in data/generated.

    The cache key holds the seed, the faults, the duration and the simulator's source,
    so a re-scored acceptance (e.g. after a detector change) reuses the same telemetry.
    The detectors always read the CSV file (10 significant digits), first run or not.
    """
    from rwa_monitor.telemetry import read_telemetry, write_telemetry
    path = _cache_path(seed, specs, hours)
    if path.is_file():
        return read_telemetry(path)
    from rwa_monitor.sim.basilisk import BasiliskBus
    from rwa_monitor.sim.basilisk_config import BusConfig, parse_fault
    tele = BasiliskBus(BusConfig(), [parse_fault(s) for s in specs], seed=seed).run(
        hours * 3600.0)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_telemetry(path, tele)
    return read_telemetry(path)   # the file, as a user has it, cached or not


def calibrate(out_dir: pathlib.Path, seed: int = CALIBRATION_SEED,
              hours: float = HOURS) -> dict[str, Any]:
    """Simulate the fault-free commissioning run, calibrate, write out_dir/calibration."""
    from rwa_monitor.pipelines import calibrated
    start = time.perf_counter()
    tele = simulate(seed, [], hours)
    tele.source = f'bus seed {seed}'
    sim_s = time.perf_counter() - start
    start = time.perf_counter()
    document, warnings, arrays = calibrated.commission([tele])
    cal_s = time.perf_counter() - start
    calibrated.write(document, arrays, out_dir / 'calibration')
    wheels = document['calibration']['wheels']
    return {'seed': seed, 'hours': hours, 'sim_wall_s': sim_s, 'calibrate_wall_s': cal_s,
            'warnings': warnings,
            'path': str(out_dir / 'calibration' / 'calibration.yaml'),
            'wheels': {w: {'effects': [e['name'] for e in b['friction_model']['effects']],
                           'noise_std_nm': b['noise']['std_nm'],
                           'band_rad_s': b['noise']['low_speed_band']['speed_abs_below_rad_s'],
                           'band_std_nm': b['noise']['low_speed_band']['std_nm'],
                           'speed_range_rad_s': b['speed_range_rad_s']}
                       for w, b in wheels.items()}}


def _declarations(events) -> list[dict[str, Any]]:
    final: dict[tuple[str, int], Any] = {}
    first: dict[tuple[str, int], Any] = {}
    for e in events:
        key = (e.component, e.index)
        if e.revision == 0:
            first[key] = e
        if key not in final or e.revision >= final[key].revision:
            final[key] = e
    return [{'wheel': e.component, 'time': e.time, 'declared_time': e.declared_time,
             'kind': e.kind, 'final_kind': final[k].kind,
             'final_confirmed': bool(final[k].details.get('kind_confirmed', True))}
            for k, e in sorted(first.items(), key=lambda kv: kv[1].declared_time)]


def evaluate(run: dict[str, Any], cal_path: str, params: dict[str, Any]) -> dict[str, Any]:
    """Simulate one evaluation run and run the LLR pipeline with and without calibration."""
    from rwa_monitor.pipelines import llr
    start = time.perf_counter()
    tele = simulate(run['seed'], [run['spec']])
    out = dict(run, sim_wall_s=time.perf_counter() - start, samples=len(tele))
    for mode, extra in (('calibrated', {'calibration_file': cal_path}),
                        ('uncalibrated', {})):
        start = time.perf_counter()
        events, summary = llr.run_with_summary(tele, {**params, **extra})
        wall = time.perf_counter() - start
        out[mode] = {'declarations': _declarations(events), 'wall_s': wall,
                     'samples_per_s': len(tele) * len(tele.wheels) / wall,
                     'not_tested': {w: s.get('not_tested') for w, s in summary.items()}}
    out['fss'] = fss_flags(tele, cal_path)
    return out


def fss_flags(tele, cal_path: str) -> dict[str, Any]:
    """Return the window diagnosis flags of each wheel (whole run), with and without."""
    from rwa_monitor.core.fss.pipeline import diagnose, FssConfig
    from rwa_monitor.telemetry.fss_model import load_model
    from rwa_monitor.pipelines import calibrated
    cal = calibrated.load(cal_path)
    model, config = load_model(), FssConfig()
    out: dict[str, Any] = {'calibrated': {}, 'uncalibrated': {}}
    for w, ch in tele.wheels.items():
        res = calibrated.diagnose_wheel(cal['wheels'][w], tele.time, ch.speed, ch.friction,
                                        model, config)
        out['calibrated'][w] = {'flags': res['anomalies'], 'status': res['status']}
        res = diagnose(ch.speed, ch.friction, tele.time, model, config)
        out['uncalibrated'][w] = {'flags': res['anomalies']}
    return out


def score(results: list[dict[str, Any]], mode: str, hours: float = HOURS
          ) -> dict[str, Any]:
    """Return the acceptance numbers of one mode over the evaluation runs."""
    healthy_hours = 0.0
    false_alarms = 0
    other_wheel = 0
    per_fault: dict[str, dict[str, Any]] = {}
    for r in results:
        decl = r[mode]['declarations']
        healthy_hours += (len(WHEELS) - 1) * hours + FAULT_TIME_S / 3600.0
        before = [d for d in decl if d['wheel'] == r['wheel']
                  and d['declared_time'] < FAULT_TIME_S]
        others = [d for d in decl if d['wheel'] != r['wheel']]
        false_alarms += len(before) + len(others)
        other_wheel += len([d for d in others if d['declared_time'] >= FAULT_TIME_S])
        after = [d for d in decl if d['wheel'] == r['wheel']
                 and d['declared_time'] >= FAULT_TIME_S]
        entry = per_fault.setdefault(r['fault'], {'runs': 0, 'detected': 0, 'delays_s': [],
                                                  'right_kind': 0, 'confirmed': 0,
                                                  'right_confirmed': 0,
                                                  'extra_declarations': 0})
        entry['runs'] += 1
        if after:
            d = after[0]
            entry['detected'] += 1
            entry['delays_s'].append(d['declared_time'] - FAULT_TIME_S)
            entry['right_kind'] += d['final_kind'] == r['expected']
            entry['confirmed'] += d['final_confirmed']
            entry['right_confirmed'] += d['final_confirmed'] and d['final_kind'] == r[
                'expected']
            entry['extra_declarations'] += len(after) - 1
    for entry in per_fault.values():
        delays = entry['delays_s']
        entry['delay_median_s'] = float(np.median(delays)) if delays else None
        entry['delay_max_s'] = float(np.max(delays)) if delays else None
    fss_runs = [r for r in results if 'fss' in r]
    fss_healthy = [r['fss'][mode][w] for r in fss_runs for w in r['fss'][mode]
                   if w != r['wheel']]
    fss_faulty = [(r, r['fss'][mode][r['wheel']]) for r in fss_runs]
    fss = {'healthy_wheels': len(fss_healthy),
           'healthy_flagged': sum(any(x['flags'].values()) for x in fss_healthy),
           'healthy_unknown': sum(x.get('status') == 'unknown' for x in fss_healthy),
           'faulty_wheels': len(fss_faulty),
           'faulty_right_flag': sum(bool(x['flags'].get(r['expected'])) for r, x in fss_faulty),
           'faulty_unknown': sum(x.get('status') == 'unknown' for _, x in fss_faulty)}
    after_hours = len(results) * (len(WHEELS) - 1) * (hours - FAULT_TIME_S / 3600.0)
    rate_elsewhere = (false_alarms - other_wheel) / (healthy_hours - after_hours)
    chance = rate_elsewhere * after_hours
    return {'healthy_wheel_hours': healthy_hours, 'false_alarms': false_alarms, 'fss': fss,
            'other_wheels_after_fault_chance': chance,
            'other_wheels_after_fault_p': float(stats.poisson.sf(other_wheel - 1, chance)),
            'false_alarms_per_wheel_hour': false_alarms / healthy_hours,
            'other_wheels_after_fault': other_wheel, 'per_fault': per_fault}


def _chance(mode: dict[str, Any]) -> str:
    """Return the expected count and Poisson P(>= observed) at the rate elsewhere."""
    if 'other_wheels_after_fault_chance' not in mode:
        return 'not computed'
    return (f'{mode["other_wheels_after_fault_chance"]:.1f}, P(>= '
            f'{mode["other_wheels_after_fault"]}) = {mode["other_wheels_after_fault_p"]:.2f}')


def _ranges(seeds: list[int]) -> str:
    """Return seeds as runs of consecutive values, e.g. '7000-7019, 7100-7119'."""
    runs: list[list[int]] = []
    for s in seeds:
        if runs and s == runs[-1][-1] + 1:
            runs[-1].append(s)
        else:
            runs.append([s])
    return ', '.join(f'{r[0]}-{r[-1]}' if len(r) > 1 else f'{r[0]}' for r in runs)


def _met(ok: bool, gap: str = '') -> str:
    return 'met' if ok else f'**not met**{f" ({gap})" if gap else ""}'


def markdown(acc: dict[str, Any], r: float, rate_hz: float) -> list[str]:
    """Return the lines of the acceptance table (both modes side by side, goals judged)."""
    from bench.report import table
    bound = 2.0 * r * rate_hz * 3600.0
    cal, raw = acc['score']['calibrated'], acc['score']['uncalibrated']
    seeds = [run['seed'] for run in acc['runs']]
    fa = cal['false_alarms_per_wheel_hour']
    rows = [['false alarms / healthy wheel-hour',
             f'{fa:.3f} ({cal["false_alarms"]} in {cal["healthy_wheel_hours"]:.0f} h)',
             f'{raw["false_alarms_per_wheel_hour"]:.3f} ({raw["false_alarms"]})',
             f'<= {bound:.3g}', _met(fa <= bound, f'x{fa / bound:.1f} the bound')],
            ['declarations on the other wheels after the fault',
             cal['other_wheels_after_fault'], raw['other_wheels_after_fault'], '0',
             _met(cal['other_wheels_after_fault'] == 0,
                  f'{cal["other_wheels_after_fault"]} in {len(seeds)} runs; by chance at '
                  f'the rate elsewhere {_chance(cal)}')],
            ['FSS (whole 3-h run): healthy wheels flagged',
             _fss_cell(cal['fss']), _fss_cell(raw['fss']), '0',
             _met(cal['fss']['healthy_flagged'] == 0,
                  f'{cal["fss"]["healthy_flagged"]} wheels')]]
    for name, entry in cal['per_fault'].items():
        detected = entry['detected'] / entry['runs']
        right = (entry['right_confirmed'] / entry['confirmed']) if entry['confirmed'] else 0.0
        gaps = []
        if detected < 0.95:
            gaps.append(f'detected {100 * detected:.0f} %')
        if right < 0.90:
            gaps.append(f'right kind once confirmed {100 * right:.0f} %')
        rows.append([f'{name}: detected, right kind (once confirmed), median / max delay',
                     _fault_cell(entry), _fault_cell(raw['per_fault'][name]),
                     '>= 95 %, >= 90 %', _met(not gaps, ', '.join(gaps))])
    speed = acc.get('throughput')
    if speed:
        med = speed['median_samples_per_s']
        rows += [['LLR streaming samples/s (median, one wheel; node path)',
                  f'{med["stream_cal"]:,.0f}', f'{med["stream"]:,.0f}',
                  f'>= {STREAMING_GOAL:,.0f}',
                  _met(med['stream_cal'] >= STREAMING_GOAL,
                       f'x{STREAMING_GOAL / med["stream_cal"]:.1f} short')],
                 ['LLR batch samples/s (median, one wheel)',
                  f'{med["batch_cal"]:,.0f}', f'{med["batch"]:,.0f}',
                  f'>= {BATCH_GOAL:,.0f}',
                  _met(med['batch_cal'] >= BATCH_GOAL,
                       f'x{BATCH_GOAL / med["batch_cal"]:.1f} short')]]
    lines = ['### Acceptance: calibrated detectors on the realistic bus', '',
             f'Default guidance and null speed (wheels cross zero). Calibration: one '
             f'fault-free {acc["calibration"]["hours"]:g}-hour run, seed '
             f'{acc["calibration"]["seed"]} (`rwa-monitor calibrate`). Evaluation: '
             f'{len(seeds)} fresh {HOURS:g}-hour runs, seeds {_ranges(seeds)} (fixed '
             f'before any result was seen; development used seeds below 100 and the seeds of '
             f'earlier acceptance runs, {SPENT_SEEDS}), one fault '
             f'per run on one wheel at {FAULT_TIME_S:g} s (steps: dry +3e-4 N m, viscous '
             f'+3e-6 N m s/rad; ramps to the same sizes over {RAMP_S:g} s), '
             f'{len(seeds) // len(FAULTS)} runs per fault. LLR parameters of '
             f'config/rwa_monitor.yaml (r = {r:g}). Bound: 2 r x samples per wheel-hour = '
             f'{bound:.3g}. `python -m bench bus` (bench/bus_acceptance.py).', '',
             table(['measure', 'calibrated', 'without calibration', 'goal',
                    'calibrated: goal'], rows), '']
    lines += ['A false alarm is a first declaration on a healthy wheel, or on the faulty '
              'wheel before the fault. "Right kind (once confirmed)": the final kind of the '
              'first declaration after the fault, counted over the declarations whose kind '
              'the detector confirmed (`kind_confirmed`). At the bound, the other three '
              f'wheels would draw {bound * 3 * (HOURS - FAULT_TIME_S / 3600.0) * len(seeds):.1f}'
              ' declarations after the faults of these runs by chance alone: the goal 0 '
              'asks for a false-alarm rate well below r, as the detector has on white noise '
              '(section "LLR friction detector", Fig. 5). "By chance at the rate elsewhere": '
              'the declarations expected on those wheel-hours at the calibrated false-alarm '
              'rate of all other healthy wheel-hours (before the faults, and healthy wheels '
              'before them), with the Poisson probability of at least the count seen; a '
              'small probability would mean the fault leaks into the other wheels.', '']
    ramps = {n: e for n, e in cal['per_fault'].items() if 'ramp' in n and e['detected']}
    if ramps:
        lines += ['Ramps: at the first declaration the ramp had reached '
                  + ', '.join(f'{100 * min(e["delay_median_s"] / RAMP_S, 1.0):.0f} % '
                              f'({name}, median)' for name, e in ramps.items())
                  + ' of its size, and extra declarations of the same ramp followed ('
                  + ', '.join(f'{e["extra_declarations"]} in {e["detected"]} {name}s'
                              for name, e in ramps.items())
                  + '). A ramp is named by the growth tests of the categorisation (a level '
                  'growing in time in one direction; docs/llr.md "Kinds on ramps"); its kind '
                  'at declaration is often both or undecided and becomes the right one at the '
                  "re-checks; a re-declaration that the first change's growth explains is a "
                  'revision of it, not a new declaration (development numbers: '
                  'docs/calibration.md, "Kinds on ramps").', '']
    c = acc['calibration']
    described = '; '.join(
        f'{w}: effects {", ".join(v["effects"]) or "none"}, noise {v["noise_std_nm"]:.3g} N m, '
        f'band |w| < {v["band_rad_s"]:g} rad/s (std {v["band_std_nm"]:.3g})'
        for w, v in c['wheels'].items())
    warned = f'. Warnings: {"; ".join(c["warnings"])}' if c['warnings'] else '. No warning.'
    lines += [f'Calibration (seed {c["seed"]}): {described}{warned}', '']
    if speed:
        lines += [f'Throughput: {speed["wheels"]} wheels x {speed["samples_per_wheel"]} '
                  f'samples of evaluation seed {seeds[0]}, {speed["repeats"]} repeats, '
                  "medians; streaming = llr_detector's per-sample call "
                  '`LLRDetector.update_nominal` (nominal lookup and sample in one compiled '
                  'call, docs/architecture.md "Compiled kernels"), batch = '
                  '`NominalWheel.residual` + '
                  '`detect_batch`; "without calibration" = the same detector on the raw '
                  f'friction. Batch events equal streaming events: {_same_text(speed)}. '
                  'CPU time of '
                  'the process (time.process_time): the 2-core machine is shared with other '
                  'sessions, whose load inflates wall time many-fold.', '']
    return lines


def _same_text(speed: dict[str, Any]) -> str:
    full, keys = speed['batch_events_equal_streaming'], speed.get(
        'batch_events_equal_streaming_keys')
    if not isinstance(full, dict):
        return 'yes' if full else 'NO'
    out = []
    for mode, label in (('calibrated', 'calibrated'), ('plain', 'without calibration')):
        if full[mode]:
            out.append(f'{label}: yes, every field')
        elif keys and keys[mode]:
            out.append(f'{label}: same wheels, kinds, change and declaration rows and '
                       'revisions; floating-point fields differ in the last digits')
        else:
            out.append(f'{label}: NO')
    return '; '.join(out)


def _fss_cell(fss: dict[str, Any]) -> str:
    return (f'{fss["healthy_flagged"]}/{fss["healthy_wheels"]} (unknown '
            f'{fss["healthy_unknown"]}); faulty wheel: its kind flagged '
            f'{fss["faulty_right_flag"]}/{fss["faulty_wheels"]}')


def _fault_cell(entry: dict[str, Any]) -> str:
    runs = entry['runs']
    if not entry['detected']:
        return f'0/{runs}'
    return (f'{entry["detected"]}/{runs}, {entry["right_kind"]}/{entry["detected"]} '
            f'({entry["right_confirmed"]}/{entry["confirmed"]}), '
            f'{entry["delay_median_s"]:.0f} / {entry["delay_max_s"]:.0f} s')


def throughput(tele, cal_path: str, params: dict[str, Any],
               repeats: int = SPEED_REPEATS) -> dict[str, Any]:
    """Return the median samples/s of the calibrated and plain LLR, streaming and batch."""
    from rwa_monitor.core.calibrate import NominalWheel
    from rwa_monitor.core.llr import detect_batch, LLRDetector
    from rwa_monitor.core.schema import llr_kwargs
    from rwa_monitor.pipelines import calibrated
    cal = calibrated.load(cal_path)
    kwargs = llr_kwargs(params)
    rates: dict[str, list[float]] = {k: [] for k in ('stream_cal', 'batch_cal', 'stream',
                                                     'batch')}
    same = {'calibrated': True, 'plain': True}
    same_keys = {'calibrated': True, 'plain': True}
    for _ in range(repeats):
        for wheel, ch in tele.wheels.items():
            nominal = NominalWheel(cal['wheels'][wheel])
            n = len(tele)
            t, w, f = tele.time.tolist(), ch.speed.tolist(), ch.friction.tolist()
            for mode in ('cal', ''):
                start = time.process_time()
                if mode:
                    residual, _ = nominal.residual(tele.time, ch.speed, ch.friction)
                else:
                    residual = ch.friction
                batch = detect_batch(tele.time, ch.speed, residual, component=wheel, **kwargs)
                rates['batch' + ('_cal' if mode else '')].append(n / (time.process_time()
                                                                      - start))
                detector = LLRDetector(wheel, **kwargs)
                found = []
                start = time.process_time()
                if mode:
                    table = nominal.table
                    for t_k, w_k, f_k in zip(t, w, f):
                        out = detector.update_nominal(table, t_k, w_k, f_k)
                        if out:
                            found.extend(out)
                else:
                    for t_k, w_k, f_k in zip(t, w, f):
                        out = detector.update(t_k, w_k, f_k)
                        if out:
                            found.extend(out)
                rates['stream' + ('_cal' if mode else '')].append(n / (time.process_time()
                                                                       - start))
                found.extend(detector.finish())   # the end of record, as detect_batch
                name = 'calibrated' if mode else 'plain'
                same[name] &= [e.to_json() for e in batch] == [e.to_json() for e in found]
                keys_batch = [_event_key(e) for e in batch]
                same_keys[name] &= keys_batch == [_event_key(e) for e in found]
    return {'samples_per_wheel': len(tele), 'wheels': len(tele.wheels), 'repeats': repeats,
            'median_samples_per_s': {k: float(np.median(v)) for k, v in rates.items()},
            'batch_events_equal_streaming': same,
            'batch_events_equal_streaming_keys': same_keys}


def _event_key(event) -> tuple:
    return (event.component, event.kind, event.index, event.declared_index, event.revision)


def _worker(job: tuple) -> dict[str, Any]:
    return evaluate(*job)


def run(out_dir: pathlib.Path, params: dict[str, Any], quick: bool = False,
        processes: int = 2, progress: Any = None, seeds: tuple[int, ...] = EVAL_SEEDS,
        calibration_seed: int = CALIBRATION_SEED, speed: bool = True) -> dict[str, Any]:
    """Calibrate, then evaluate the runs, ``processes`` at a time; return the results."""
    import multiprocessing
    acc: dict[str, Any] = {'calibration': calibrate(out_dir, calibration_seed)}
    print(f'  calibration: {acc["calibration"]}', flush=True)
    runs = plan(seeds[:2] if quick else seeds)
    jobs = [(r, acc['calibration']['path'], params) for r in runs]
    with multiprocessing.get_context('spawn').Pool(processes) as pool:
        acc['runs'] = []
        for result in pool.imap(_worker, jobs):
            acc['runs'].append(result)
            if progress is not None:
                progress(acc)
            print(f'  seed {result["seed"]} {result["fault"]} on {result["wheel"]}: '
                  f'calibrated {len(result["calibrated"]["declarations"])} / uncalibrated '
                  f'{len(result["uncalibrated"]["declarations"])} declarations', flush=True)
    acc['score'] = {mode: score(acc['runs'], mode) for mode in ('calibrated', 'uncalibrated')}
    if progress is not None:
        progress(acc)
    if not speed:
        return acc
    tele = simulate(runs[0]['seed'], [runs[0]['spec']])
    acc['throughput'] = throughput(tele, acc['calibration']['path'], params,
                                   1 if quick else SPEED_REPEATS)
    print(f'  throughput: {acc["throughput"]}', flush=True)
    return acc


def summarise(tele, events: list[dict[str, Any]], tolerance_s: float = 1800.0) -> list[str]:
    """Return lines counting LLR declarations against the truth columns of a bus file.

    A wheel's true changes are the times its ``truth_<wheel>_dry`` / ``_viscous`` level
    starts to move; a declaration is a detection when it comes after a true change of
    its wheel and within ``tolerance_s`` of it, a false alarm otherwise.
    """
    lines = []
    first = [e for e in events if e.get('detector') == 'llr' and e.get('revision', 0) == 0]
    for wheel in tele.wheels:
        starts = []
        for part in ('dry', 'viscous'):
            level = tele.truth.get(f'{wheel}_{part}')
            if level is not None:
                moved = np.flatnonzero(np.diff(level) != 0)
                if moved.size:
                    starts.append(float(tele.time[moved[0] + 1]))
        mine = [e for e in first if e['component'] == wheel]
        hits = [e for e in mine if any(0.0 <= e['declared_time'] - s <= tolerance_s
                                       for s in starts)]
        detected = [s for s in starts if any(0.0 <= e['declared_time'] - s <= tolerance_s
                                             for e in mine)]
        text = (f'{wheel}: {len(starts)} true change(s) at '
                f'{", ".join(f"{s:.0f} s" for s in starts) or "-"}; detected {len(detected)}'
                f'; false alarms {len(mine) - len(hits)}')
        for e in hits:
            text += (f'; declared {e["kind"]} at {e["declared_time"]:.1f} s (delay '
                     f'{e["declared_time"] - min(starts):.0f} s)')
        lines.append(text)
    return lines


def summarise_gyro(tele, events: list[dict[str, Any]], tolerance_s: float = 1800.0
                   ) -> list[str]:
    """Return lines counting the VSADC declarations against the gyro truth labels.

    A declaration is an event of kind ``drift`` or ``bias`` (the returns to ``healthy``
    are counted apart). It detects a true fault when it is on the fault's axis, declared
    at or after its start and within ``tolerance_s``; its kind is right when it names the
    fault's kind; any other declaration is a false alarm.
    """
    from rwa_monitor.cli.cmd_demo import gyro_faults
    faults = gyro_faults(tele)
    mine = [e for e in events if e.get('detector') == 'vsadc']
    lines = []
    for axis in ('gyro_x', 'gyro_y', 'gyro_z'):
        true = [(kind, start) for a, kind, start in faults if a == axis and kind != 'healthy']
        declared = [e for e in mine if e['component'] == axis
                    and e['kind'] in ('drift', 'bias')]
        returns = sum(e['kind'] == 'healthy' for e in mine if e['component'] == axis)

        def hit(e: dict[str, Any]) -> bool:
            return any(0.0 <= e['declared_time'] - s <= tolerance_s for _, s in true)
        hits = [e for e in declared if hit(e)]
        found = sum(any(0.0 <= e['declared_time'] - s <= tolerance_s for e in declared)
                    for _, s in true)
        text = (f'{axis}: {len(true)} true fault(s) '
                f'{", ".join(f"{k} at {s:.0f} s" for k, s in true) or "-"}; detected '
                f'{found}; false alarms {len(declared) - len(hits)}; returns to healthy '
                f'{returns}')
        for e in hits[:1]:
            start = min(s for _, s in true)
            right = e['kind'] in [k for k, _ in true]
            text += (f'; declared {e["kind"]} ({"right" if right else "wrong"} kind) at '
                     f'{e["declared_time"]:.1f} s (delay {e["declared_time"] - start:.0f} s)')
        lines.append(text)
    return lines


LIVE_NODES = ('rwa_monitor.nodes.llr_detector', 'rwa_monitor.nodes.vsadc_detector')


def live(path: pathlib.Path, calibration: pathlib.Path, timeout_s: float = 3600.0
         ) -> list[str]:
    """Replay a bus file live through the detector nodes with a calibration; summarise.

    The replay node feeds llr_detector and vsadc_detector (``calibration_file`` set on
    both, config/rwa_monitor.yaml otherwise) in one process (``rwa-monitor demo``'s
    runner, no live view); the events the nodes publish on ``anomalies`` are counted
    against the file's truth columns, wheels and gyro axes.
    """
    from rwa_monitor.cli.cmd_demo import run_demo
    from rwa_monitor.telemetry import read_telemetry
    result = run_demo(pathlib.Path(path), live=False, modules=LIVE_NODES,
                      overrides={'calibration_file': str(calibration)}, timeout_s=timeout_s)
    tele = read_telemetry(path)
    wheel_events = [e.to_json() for e in result.events]
    gyro_events = [{**e['fields'], 'component': e['fields'].get('component'),
                    'declared_time': e['fields'].get('declaration_time_s')}
                   for e in result.other_events]
    same = ([(e.component, e.kind, e.index, e.declared_index) for e in result.events]
            == [(e.component, e.kind, e.index, e.declared_index)
                for e in result.pipeline_events])
    lines = [f'live: {result.rows} rows through replay -> llr_detector + vsadc_detector '
             f'(calibration_file {calibration}) in {result.wall_s:.0f} s '
             f'({result.executor} executor)',
             f'llr_detector events identical to `rwa-monitor detect --calibration` on the '
             f'file: {"yes" if same else "NO"} ({len(result.events)} incl. revisions)']
    lines += ['wheels (llr_detector):'] + ['  ' + x for x in summarise(tele, wheel_events)]
    lines += ['gyro axes (vsadc_detector):'] + ['  ' + x
                                                for x in summarise_gyro(tele, gyro_events)]
    lines += [f'note: {n}' for n in result.notes]
    return lines


def development(args: list[str]) -> int:
    """``dev --seeds A-B --calibration-seed S [--out DIR] [--speed]``: score other seeds.

    For development: the same calibration, runs and scores as the acceptance, on seeds of
    the caller's choice, printed and written to DIR/bus_acceptance_dev.json; docs untouched.
    """
    import argparse
    import json

    from bench.bus_config import llr_config
    from rwa_monitor.telemetry.atomic import write_text_atomic
    parser = argparse.ArgumentParser(prog='python -m bench.bus_acceptance dev')
    parser.add_argument('--seeds', required=True, help='first-last, e.g. 10-29')
    parser.add_argument('--calibration-seed', type=int, required=True)
    parser.add_argument('--out', type=pathlib.Path, default=pathlib.Path('/tmp/bus_dev'))
    parser.add_argument('--speed', action='store_true', help='also measure throughput')
    opts = parser.parse_args(args)
    first, _, last = opts.seeds.partition('-')
    seeds = tuple(range(int(first), int(last or first) + 1))
    if set(seeds) & set(EVAL_SEEDS) or opts.calibration_seed in EVAL_SEEDS + (
            CALIBRATION_SEED,):
        parser.error('these seeds are the acceptance seeds: choose development seeds')
    opts.out.mkdir(parents=True, exist_ok=True)
    acc = run(opts.out, llr_config(), seeds=seeds, calibration_seed=opts.calibration_seed,
              speed=opts.speed)
    write_text_atomic(opts.out / 'bus_acceptance_dev.json', json.dumps(acc, indent=1))
    print('\n'.join(markdown_scores(acc)))
    return 0


def markdown_scores(acc: dict[str, Any]) -> list[str]:
    """Return a short plain summary of the scores of both modes."""
    lines = []
    for mode, sc in acc['score'].items():
        lines.append(f'{mode}: false alarms {sc["false_alarms"]} in '
                     f'{sc["healthy_wheel_hours"]:.0f} h, other wheels after fault '
                     f'{sc["other_wheels_after_fault"]}, fss {sc["fss"]}')
        for name, entry in sc['per_fault'].items():
            lines.append(f'  {name}: {_fault_cell(entry)}')
    return lines


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.bus_acceptance FILE EVENTS.json``, ``live FILE CAL [EVENTS]``, ``dev``.

    ``live`` also writes its summary (and, given the events of ``detect`` without
    calibration on the same file, their summary) to bench/results/demo_bus.json, which
    the bus section of docs/results.md shows (bench/bench_bus.py).
    """
    import json
    import sys

    from bench.report import RESULTS_DIR
    from rwa_monitor.telemetry import read_telemetry
    from rwa_monitor.telemetry.atomic import write_text_atomic
    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == 'dev':
        return development(args[1:])
    if args and args[0] == 'live':
        lines = live(pathlib.Path(args[1]), pathlib.Path(args[2]))
        print('\n'.join(lines), flush=True)
        raw = []
        if len(args) > 3:
            events = json.loads(pathlib.Path(args[3]).read_text())['events']
            raw = summarise(read_telemetry(args[1]), events)
        RESULTS_DIR.mkdir(parents=True, exist_ok=True)
        write_text_atomic(RESULTS_DIR / 'demo_bus.json', json.dumps(
            {'command': 'make demo-bus', 'file': args[1], 'calibration': args[2],
             'date_utc': time.strftime('%Y-%m-%d %H:%M', time.gmtime()),
             'live': lines, 'without_calibration': raw}, indent=2) + '\n')
        return 0
    tele = read_telemetry(args[0])
    events = json.loads(pathlib.Path(args[1]).read_text())['events']
    print('\n'.join(summarise(tele, events)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
