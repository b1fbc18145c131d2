"""Three answers on the Basilisk bus that were left open while the bus was not installed.

Run with the bus environment: ``PYTHONPATH=$PWD .venv-bsk/bin/python -m bench.bus_answers``
(``--parts llr,identify``; ``--parts ''`` renders the section again from the JSON).
Telemetry is simulated (and cached) by bench/bus_acceptance.py ``simulate``; default
guidance and null speed (wheels cross zero). Results: bench/results/bus_answers.json and
the section ``bus_answers`` of docs/results.md (bench/bus_answers_report.py).

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
from bench.bus_answers_report import markdown
from bench.bus_config import llr_config
from bench.report import RESULTS_DIR, update_section, write_json

CALIBRATION_SEED = 3100
EVAL_SEEDS = tuple(range(3101, 3113))
IDENTIFY_SEEDS = (3121, 3122, 3123)
HOURS = 3.0
FAULT_TIME_S = 5400.0
DRY, VISCOUS = 'dry=3e-4', 'viscous=3e-6'
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
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
    results['setup'] = {'hours': HOURS, 'fault_time_s': FAULT_TIME_S, 'wheels': WHEELS,
                        'calibration_seed': CALIBRATION_SEED, 'eval_seeds': EVAL_SEEDS,
                        'identify_seeds': IDENTIFY_SEEDS, 'dry': DRY, 'viscous': VISCOUS}
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
