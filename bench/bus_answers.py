"""Three answers on the Basilisk bus that were left open while the bus was not installed.

Run with the bus environment: ``PYTHONPATH=$PWD .venv-bsk/bin/python -m bench.bus_answers``
(``--parts equivalence,kinds,identify``). Telemetry is simulated (and cached) by
bench/bus_acceptance.py ``simulate``; default guidance and null speed (wheels cross zero).

1. Issue 25 item 2, streaming == batch on the bus: per file, wheel and mode (with and
   without the calibration of the fault-free commissioning run CALIBRATION_SEED), the
   events of ``LLRDetector`` fed row by row (``update``; ``update_nominal``, the node's
   call, with the calibration) then ``finish()``, of ``process_arrays`` + ``finish()`` (on
   the nominal residual with the calibration), of ``detect_batch_with_counters`` (the
   pipelines' call) and of ``rwa-monitor detect`` (the events file), compared field for
   field (the JSON of each event, floats as written); the counters too.
2. Issue 26 item 2, the kinds: on EVAL_SEEDS, each file a dry step (DRY) on one wheel and
   a viscous step (VISCOUS) on another at FAULT_TIME_S; per injected change the final kind
   (last revision, the end-of-record one included) of the first declaration at or after
   it: right / undecided / wrong, confirmed or not; every other first declaration is
   counted (false: healthy wheels and before the change; extra: after the change on the
   faulty wheel).
3. Issue 26 item 4: ``rwa-monitor identify FILE --wheel all`` (joint selection) and
   ``--separately`` on the fault-free files IDENTIFY_SEEDS: effect sets per wheel, the
   common set, flags, held-out RMSE against the noise floor.

Seeds fixed before any result on them was seen; none of 3100-3123 appears elsewhere in
bench/, test/ or docs/.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import tempfile
import time
from typing import Any

from bench.bus_acceptance import calibrate, simulate
from bench.bus_config import llr_config
from bench.report import RESULTS_DIR, table, update_section, write_json

CALIBRATION_SEED = 3100
EVAL_SEEDS = tuple(range(3101, 3113))
IDENTIFY_SEEDS = (3121, 3122, 3123)
HOURS = 3.0
FAULT_TIME_S = 5400.0
DRY, VISCOUS = 'dry=3e-4', 'viscous=3e-6'
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
PARTS = ('equivalence', 'kinds', 'identify')
SECTION = 'bus_answers'


def plan(seeds: tuple[int, ...] = EVAL_SEEDS) -> list[dict[str, Any]]:
    """Return the runs: run i has the dry step on wheel i % 4 and the viscous on another.

    The viscous wheel is 1, 2 or 3 places further (changing every four runs), so that over
    twelve runs each wheel carries three dry and three viscous steps.
    """
    runs = []
    for i, seed in enumerate(seeds):
        dry = WHEELS[i % 4]
        viscous = WHEELS[(i + 1 + (i // 4) % 3) % 4]
        runs.append({'seed': seed, 'changes': {dry: 'dry', viscous: 'viscous'},
                     'specs': [f'friction:{dry}:{FAULT_TIME_S:g}:{DRY}',
                               f'friction:{viscous}:{FAULT_TIME_S:g}:{VISCOUS}']})
    return runs


def event_texts(events) -> list[str]:
    """Return each event as the JSON text of the events file (every field, sorted keys)."""
    return [json.dumps(e if isinstance(e, dict) else e.to_json(), sort_keys=True)
            for e in events]


def detector_paths(tele, wheel: str, kwargs: dict[str, Any], nominal=None
                   ) -> dict[str, Any]:
    """Return the events and counters of one wheel through the three library paths."""
    from rwa_monitor.core.llr import detect_batch_with_counters, LLRDetector
    ch = tele.wheels[wheel]
    friction = ch.friction
    if nominal is not None:
        friction, _ = nominal.residual(tele.time, ch.speed, ch.friction)
    stream = LLRDetector(wheel, **kwargs)
    found = []
    rows = zip(tele.time.tolist(), ch.speed.tolist(), ch.friction.tolist())
    for t, w, f in rows:
        found.extend(stream.update_nominal(nominal.table, t, w, f) if nominal is not None
                     else stream.update(t, w, f))
    found.extend(stream.finish())
    arrays = LLRDetector(wheel, **kwargs)
    batch = arrays.process_arrays(tele.time, ch.speed, friction) + arrays.finish()
    pipeline, counters = detect_batch_with_counters(tele.time, ch.speed, friction,
                                                    component=wheel, **kwargs)
    return {'streaming': found, 'process_arrays': batch, 'detect_batch': pipeline,
            'counters': {'streaming': dict(stream.counters),
                         'process_arrays': dict(arrays.counters), 'detect_batch': counters}}


def cli_events(path: str, calibration: str | None) -> list[dict[str, Any]]:
    """Return the LLR events of ``rwa-monitor detect FILE [--calibration CAL] -o OUT``."""
    from rwa_monitor.cli.main import main as cli
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / 'events.json'
        args = ['detect', path, '-o', str(out)]
        if calibration:
            args += ['--calibration', calibration]
        code = cli(args)
        if code not in (0, 1):
            raise RuntimeError(f'rwa-monitor {" ".join(args)}: exit code {code}')
        events = json.loads(out.read_text())['events']
    return [e for e in events if e['detector'] == 'llr']


def compare_file(tele, kwargs: dict[str, Any], cal_path: str) -> dict[str, Any]:
    """Return, per mode and wheel, the event counts and whether every path agrees."""
    from rwa_monitor.core.nominal import NominalWheel
    from rwa_monitor.pipelines import calibrated
    cal = calibrated.load(cal_path)
    out: dict[str, Any] = {}
    for mode, cal_arg in (('calibrated', cal_path), ('uncalibrated', None)):
        cli = cli_events(str(tele.source), cal_arg)
        wheels = {}
        for wheel in tele.wheels:
            nominal = NominalWheel(cal['wheels'][wheel]) if cal_arg else None
            paths = detector_paths(tele, wheel, kwargs, nominal)
            ref = event_texts(paths['streaming'])
            mine = [e for e in cli if e['component'] == wheel]
            counters = paths['counters']
            wheels[wheel] = {
                'events': len(ref),
                'declarations': sum(e.revision == 0 for e in paths['streaming']),
                'process_arrays_equal': event_texts(paths['process_arrays']) == ref,
                'detect_batch_equal': event_texts(paths['detect_batch']) == ref,
                'detect_cli_equal': event_texts(mine) == event_texts(json.loads(json.dumps(
                    [e.to_json() for e in paths['streaming']]))),
                'counters_equal': (counters['streaming'] == counters['process_arrays']
                                   == counters['detect_batch']),
                'events_json': [e.to_json() for e in paths['detect_batch']]}
        out[mode] = wheels
    return out


def first_declarations(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Return each declaration (revision 0) with the kinds of its revisions, in order."""
    chains: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for e in events:
        chains.setdefault((e['component'], e['index']), []).append(e)
    out = []
    for chain in chains.values():
        chain.sort(key=lambda e: e['revision'])
        first, last = chain[0], chain[-1]
        out.append({'wheel': first['component'], 'time': first['time'],
                    'declared_time': first['declared_time'], 'kind': first['kind'],
                    'kinds': [e['kind'] for e in chain], 'final_kind': last['kind'],
                    'confirmed': bool(last.get('kind_confirmed', True)),
                    'final_step': bool(last.get('final', False)),
                    'reason': last.get('kind_reason', ''),
                    'z_dry': last.get('z_dry'), 'z_viscous': last.get('z_viscous')})
    return sorted(out, key=lambda d: d['declared_time'])


def score_kinds(run: dict[str, Any], events: list[dict[str, Any]]) -> dict[str, Any]:
    """Return the injected changes' first declarations and every other declaration."""
    decl = first_declarations(events)
    changes, false, extra = [], [], []
    for wheel in WHEELS:
        mine = [d for d in decl if d['wheel'] == wheel]
        expected = run['changes'].get(wheel)
        after = [d for d in mine if expected and d['declared_time'] >= FAULT_TIME_S]
        false += [d for d in mine if d not in after]
        extra += after[1:]
        if expected is None:
            continue
        entry: dict[str, Any] = {'wheel': wheel, 'expected': expected, 'detected': bool(after)}
        if after:
            d = after[0]
            verdict = ('right' if d['final_kind'] == expected else
                       'undecided' if d['final_kind'] == 'undecided' else 'wrong')
            entry.update(d, verdict=verdict, delay_s=d['declared_time'] - FAULT_TIME_S)
        changes.append(entry)
    return {'changes': changes, 'false': false, 'extra': extra}


def identify_file(path: str, out_dir: pathlib.Path) -> dict[str, Any]:
    """Return per wheel the joint and the separate identification of a bus file."""
    from rwa_monitor.cli.main import main as cli
    result: dict[str, Any] = {}
    for mode, extra in (('joint', []), ('separately', ['--separately'])):
        folder = out_dir / mode
        start = time.process_time()
        code = cli(['identify', path, '--wheel', 'all', '-o', str(folder)] + extra)
        if code != 0:
            raise RuntimeError(f'rwa-monitor identify {path} ({mode}): exit code {code}')
        summary = json.loads((folder / 'wheels.json').read_text())
        wheels = {}
        for wheel in WHEELS:
            rep = json.loads((folder / wheel / 'report.json').read_text())
            floor = rep['noise_floor']
            wheels[wheel] = {'effects': [e['name'] for e in rep['effects']],
                             'noise_floor': floor,
                             'before': rep['rmse_before']['held_out'] / floor,
                             'after': rep['rmse_after']['held_out'] / floor}
        result[mode] = {'wheels': wheels, 'summary': summary,
                        'cpu_s': time.process_time() - start}
    return result


def run_llr(out_dir: pathlib.Path, progress: Any = print) -> dict[str, Any]:
    """Calibrate, then compare the paths and score the kinds on every file."""
    params = llr_config()
    from rwa_monitor.core.schema import llr_kwargs
    kwargs = llr_kwargs(params)
    cal = calibrate(out_dir, CALIBRATION_SEED, HOURS)
    files = [{'seed': CALIBRATION_SEED, 'changes': {}, 'specs': []}] + plan()
    out: dict[str, Any] = {'calibration': cal, 'files': []}
    for run in files:
        start = time.perf_counter()
        tele = simulate(run['seed'], run['specs'], HOURS)
        compared = compare_file(tele, kwargs, cal['path'])
        entry = dict(run, wall_s=time.perf_counter() - start, modes={})
        for mode, wheels in compared.items():
            events = [e for w in wheels.values() for e in w.pop('events_json')]
            entry['modes'][mode] = {'wheels': wheels}
            if run['changes']:
                entry['modes'][mode]['kinds'] = score_kinds(run, events)
        out['files'].append(entry)
        progress(f'seed {run["seed"]}: {json.dumps(entry["modes"])[:400]}')
    return out


def kind_counts(files: list[dict[str, Any]], mode: str) -> dict[str, Any]:
    """Return per injected kind: changes, detected, right / undecided / wrong, confirmed."""
    counts: dict[str, Any] = {}
    for f in files:
        for c in f['modes'][mode].get('kinds', {}).get('changes', []):
            entry = counts.setdefault(c['expected'], {
                'changes': 0, 'detected': 0, 'right': 0, 'undecided': 0, 'wrong': 0,
                'wrong_confirmed': 0, 'right_at_declaration': 0, 'delays_s': []})
            entry['changes'] += 1
            if not c['detected']:
                continue
            entry['detected'] += 1
            entry[c['verdict']] += 1
            entry['wrong_confirmed'] += c['verdict'] == 'wrong' and c['confirmed']
            entry['right_at_declaration'] += c['kind'] == c['expected']
            entry['delays_s'].append(c['delay_s'])
    return counts


def _healthy_hours(files: list[dict[str, Any]]) -> float:
    return sum(len(WHEELS) * HOURS - len(f['changes']) * (HOURS - FAULT_TIME_S / 3600.0)
               for f in files if f['changes'])


def markdown_equivalence(llr: dict[str, Any]) -> list[str]:
    """Return the streaming == batch table (one row per file and mode)."""
    rows, total, equal = [], 0, 0
    for f in llr['files']:
        what = ', '.join(f'{k} {w}' for w, k in f['changes'].items()) or 'none (commissioning)'
        for mode, m in f['modes'].items():
            ws = m['wheels'].values()
            checks = ('process_arrays_equal', 'detect_batch_equal', 'detect_cli_equal',
                      'counters_equal')
            total += len(ws) * len(checks)
            equal += sum(w[c] for w in ws for c in checks)
            rows.append([f['seed'], what, mode, ' / '.join(str(w['events']) for w in ws),
                         ' / '.join(str(w['declarations']) for w in ws)]
                        + [f'{sum(w[c] for w in ws)}/{len(ws)}' for c in checks])
    return [table(['seed', 'injected at 5400 s', 'mode', 'events rw1/rw2/rw3/rw4',
                   'declarations', '`process_arrays` == streaming', '`detect_batch` ==',
                   '`rwa-monitor detect` ==', 'counters =='], rows), '',
            f'Equal, field for field: {equal} of {total} comparisons.']


def markdown_kinds(llr: dict[str, Any]) -> list[str]:
    """Return the kinds table (both modes) and the per-change detail of the calibrated."""
    files = [f for f in llr['files'] if f['changes']]
    hours = _healthy_hours(files)
    rows = []
    for mode in ('calibrated', 'uncalibrated'):
        counts = kind_counts(files, mode)
        false = sum(len(f['modes'][mode]['kinds']['false']) for f in files)
        extra = sum(len(f['modes'][mode]['kinds']['extra']) for f in files)
        for kind, c in counts.items():
            delays = sorted(c['delays_s'])
            rows.append([mode, f'{kind} step', f'{c["detected"]}/{c["changes"]}',
                         f'{c["right"]} / {c["undecided"]} / {c["wrong"]}',
                         c['wrong_confirmed'], c['right_at_declaration'],
                         f'{delays[len(delays) // 2]:.0f} / {delays[-1]:.0f}' if delays
                         else '-', false if kind == 'dry' else '',
                         extra if kind == 'dry' else ''])
    detail = []
    for f in files:
        for c in f['modes']['calibrated']['kinds']['changes']:
            if not c['detected']:
                detail.append([f['seed'], c['wheel'], c['expected'], 'not detected'] + [''] * 4)
                continue
            detail.append([f['seed'], c['wheel'], c['expected'], ' -> '.join(c['kinds']),
                           f'{c["verdict"]}{" (confirmed)" if c["confirmed"] else ""}',
                           f'{_num(c["z_dry"])} / {_num(c["z_viscous"])}',
                           c['reason'] or '-', f'{c["delay_s"]:.0f}'])
    return [table(['mode', 'change', 'detected', 'final kind right / undecided / wrong',
                   'wrong and confirmed', 'right at declaration', 'delay median / max (s)',
                   f'false declarations ({hours:.0f} healthy wheel-h)',
                   'extra declarations after a change'], rows), '',
            'Calibrated, per injected change (first declaration at or after 5400 s; kinds '
            'of its revisions in order, the last is the end-of-record one when marked '
            'final):', '',
            table(['seed', 'wheel', 'injected', 'kinds', 'final', 'z dry / z viscous (final)',
                   'reason (undecided)', 'delay (s)'], detail), ''] + _kind_notes(files)


def _kind_notes(files: list[dict[str, Any]]) -> list[str]:
    """Return the wrong kinds, the other declarations and how far the estimates are."""
    lines = []
    for mode in ('calibrated', 'uncalibrated'):
        wrong = [(f['seed'], c) for f in files for c in f['modes'][mode]['kinds']['changes']
                 if c.get('verdict') == 'wrong']
        lines.append(f'- {mode}: final kind wrong: ' + ('none' if not wrong else '; '.join(
            f'seed {seed} {c["wheel"]} ({c["expected"]} injected): {" -> ".join(c["kinds"])}'
            f'{" confirmed" if c["confirmed"] else ""}, estimated change {c["time"]:.1f} s, '
            f'declared {c["declared_time"]:.1f} s, z dry {_num(c["z_dry"])}, z viscous '
            f'{_num(c["z_viscous"])}' for seed, c in wrong)))
        far = [c for f in files for c in f['modes'][mode]['kinds']['changes']
               if c['detected'] and abs(c['time'] - FAULT_TIME_S) > 600.0]
        lines.append(f'- {mode}: first declarations after the change whose estimated change '
                     f'time is more than 600 s from {FAULT_TIME_S:g} s (likely not the injected '
                     f'change): {len(far)} of {sum(len(f["changes"]) for f in files)}')
    other = [(f['seed'], d, what) for f in files for what in ('false', 'extra')
             for d in f['modes']['calibrated']['kinds'][what]]
    lines.append('- calibrated, every other declaration: ' + ('none' if not other else '; '.join(
        f'seed {seed} {d["wheel"]} ({what}): estimated change {d["time"]:.1f} s, declared '
        f'{d["declared_time"]:.1f} s, {" -> ".join(d["kinds"])}'
        f'{" (final step)" if d["final_step"] else ""}{", " + d["reason"] if d["reason"] else ""}'
        for seed, d, what in other)))
    return lines


def _num(value: float | None) -> str:
    return '-' if value is None else f'{value:.1f}'


def markdown_identify(ident: dict[str, Any]) -> list[str]:
    """Return the identification table: per file and wheel, joint and separate."""
    rows, notes, worst, same = [], [], {'joint': 0.0, 'separately': 0.0}, {}
    for seed, res in ident.items():
        fitted = res['joint']['summary']['wheels']
        for w in WHEELS:
            j, s = res['joint']['wheels'][w], res['separately']['wheels'][w]
            rows.append([seed, w, f'{j["noise_floor"]:.3g}', f'{j["before"]:.3f}',
                         ', '.join(j['effects']) or '(none)', f'{j["after"]:.3f}',
                         _parameters(fitted[w]['effects']),
                         ', '.join(s['effects']) or '(none)', f'{s["after"]:.3f}'])
        for mode in worst:
            worst[mode] = max([worst[mode]] + [v['after'] for v in res[mode]['wheels'].values()])
            same[mode] = same.get(mode, 0) + (len({tuple(sorted(v['effects'])) for v in res[
                mode]['wheels'].values()}) == 1)
        joint, alone = (res[m]['summary'].get('consistency', {}) for m in ('joint',
                                                                           'separately'))
        notes.append(f'seed {seed}: joint common set {", ".join(joint.get("reference", []))}'
                     f', flagged {_flags(joint)}; separately flagged {_flags(alone)}; '
                     f'{res["joint"]["cpu_s"]:.0f} s CPU joint, '
                     f'{res["separately"]["cpu_s"]:.0f} s separately')
    return [table(['seed', 'wheel', 'noise floor (N m)', 'held-out before / floor',
                   'joint: effects', 'joint: after / floor',
                   'joint: hysteresis speed, excess; stribeck speed, excess; band',
                   'separately: effects', 'separately: after / floor'], rows), '',
            f'Same effect set on the four wheels: joint {same["joint"]} of {len(ident)} files, '
            f'separately {same["separately"]} of {len(ident)}; worst held-out RMSE / floor: '
            f'joint {worst["joint"]:.3f}, separately {worst["separately"]:.3f}.', ''] + [
                f'- {n}' for n in notes]


def _parameters(effects: dict[str, dict[str, Any]]) -> str:
    """Return the fitted speeds (rad/s) and sizes (N m) of the bus's three effects."""
    parts = []
    for name in ('stribeck_hysteresis', 'stribeck'):
        if name in effects:
            e = effects[name]
            parts.append(f'{e["velocity_rad_s"]:.3f}, {e["static_excess_nm"]:.2e}')
    if 'presliding' in effects:
        parts.append(f'{effects["presliding"]["band_rad_s"]:.3f}')
    return '; '.join(parts) or '-'


def _flags(consistency: dict[str, Any]) -> str:
    flagged = consistency.get('flagged') or {}
    return '; '.join(f'{w} {json.dumps(v, sort_keys=True)}' for w, v in flagged.items()) or 'none'


def run_identify(out_dir: pathlib.Path, progress: Any = print) -> dict[str, Any]:
    """Identify the four wheels of each fault-free file, jointly and separately."""
    out = {}
    for seed in IDENTIFY_SEEDS:
        tele = simulate(seed, [], HOURS)
        out[seed] = identify_file(str(tele.source), out_dir / f'identify{seed}')
        progress(f'identify seed {seed}: ' + '; '.join(
            f'{m} {w} {v["effects"]} {v["after"]:.3f}' for m, r in out[seed].items()
            for w, v in r['wheels'].items()))
    return out


def markdown(results: dict[str, Any]) -> str:
    """Return the section of docs/results.md."""
    lines = ['## Bus check of this round (`python -m bench.bus_answers`)', '',
             f'Basilisk bus, default guidance and null speed (wheels cross zero), {HOURS:g}-hour '
             f'files at 4 Hz (43,200 samples per wheel); LLR parameters of '
             f'config/rwa_monitor.yaml; seeds fixed before any result was seen (none of '
             f'3100-3123 was used before in bench/, test/ or docs/). Calibration: the '
             f'fault-free commissioning run, seed {CALIBRATION_SEED} (`rwa-monitor '
             f'calibrate`). Run on {results.get("date", "?")}, load average '
             f'{results.get("load", "?")}.', '']
    llr = results.get('llr')
    if llr:
        lines += ['### Streaming == batch on bus files (issue 25 item 2)', '',
                  f'Per file, mode and wheel: `LLRDetector.update` row by row '
                  '(`update_nominal`, the call of the calibrated node) then '
                  '`finish()`, against `process_arrays` + `finish()`, `detect_batch_with_'
                  f'counters` and `rwa-monitor detect [--calibration]`; every field of every '
                  f'event (its events-file JSON) and the counters. Files: seed '
                  f'{CALIBRATION_SEED} (commissioning) and seeds {EVAL_SEEDS[0]}-'
                  f'{EVAL_SEEDS[-1]} (a dry step {DRY} N m on one wheel and a viscous step '
                  f'{VISCOUS} N m s/rad on another, at {FAULT_TIME_S:g} s).', '']
        lines += markdown_equivalence(llr) + ['']
        lines += ['### Kinds on the bus (issue 26 item 2)', '',
                  'Final kind = the last revision (the end-of-record one included) of the '
                  'first declaration at or after the change on its wheel; false = any other '
                  'declaration on a healthy wheel or before the change; extra = a further '
                  'declaration on the faulty wheel after the change.', '']
        lines += markdown_kinds(llr) + ['']
    ident = results.get('identify')
    if ident:
        lines += ['### `rwa-monitor identify` on the four identical wheels (issue 26 item 4)', '',
                  f'`rwa-monitor identify FILE --wheel all` (joint selection, the default) and '
                  f'`--separately`, on fault-free files, seeds '
                  f'{", ".join(map(str, IDENTIFY_SEEDS))}; held-out RMSE over the noise floor.',
                  '']
        lines += markdown_identify(ident) + ['']
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the parts asked, write bench/results/bus_answers.json and the docs section."""
    import os

    from rwa_monitor.sim.basilisk_config import available
    parser = argparse.ArgumentParser(prog='python -m bench.bus_answers')
    parser.add_argument('--parts', default='llr,identify',
                        help='llr and/or identify; empty: render docs/results.md from the JSON')
    parser.add_argument('--out', type=pathlib.Path, default=pathlib.Path(
        tempfile.gettempdir()) / 'bus_answers')
    opts = parser.parse_args(argv)
    if not available():
        print('the optional Basilisk extra is absent (make test-bsk creates .venv-bsk)')
        return 0
    parts = [p for p in opts.parts.split(',') if p]
    results: dict[str, Any] = {}
    previous = RESULTS_DIR / f'{SECTION}.json'
    if previous.is_file():   # the parts not run again are kept
        kept = json.loads(previous.read_text())
        results.update({k: kept[k] for k in ('date', 'load', 'llr', 'identify') if k in kept})
    if not parts:            # render the section again from the JSON
        update_section(SECTION, markdown(results))
        return 0
    results['date'] = time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())
    start_load = os.getloadavg()[0]
    opts.out.mkdir(parents=True, exist_ok=True)
    if 'llr' in parts:
        results['llr'] = run_llr(opts.out)
    if 'identify' in parts:
        results['identify'] = run_identify(opts.out)
    results['load'] = f'{start_load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end'
    write_json(RESULTS_DIR, SECTION, results)
    update_section(SECTION, markdown(results))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
