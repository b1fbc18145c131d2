"""``python -m bench coastdown_kinds``: LLR kinds on real drum coast-downs (issue 35 item 3).

Every free drum coast of ../shared/data/measured/drum-coastdown (read in place) becomes a
record of friction ``J dw/dt`` (identify's differentiator, its half width chosen per run,
J from the pendulum swings). Commissioning: ``rwa-monitor calibrate`` on one coast (the
Greenspeed Scorcher, left, 90 psi) and on the two coasts of that tyre and pressure (left
and right). With the two-coast calibration, ``rwa-monitor detect --calibration`` (in
this process) on:

- each other coast alone (a healthy record: its declarations and coverage verdict);
- each coast joined 30 s later with itself less a dry rise of ``DRY_STEP`` N m (the same
  speeds and noise, so the change is a pure dry step: :func:`self_join`);
- pairs of two different coasts whose fitted levels differ by a dry step (``|d dry| >=
  DRY_STEP``, viscous within ``VISCOUS_REL``, drag within ``DRAG_REL`` of the pair's
  mean; the lower dry level first; :func:`pairs`), and the "flat" ones among them, whose
  fitted difference stays within ``FLAT_REL`` of its mean over 4-36 rad/s.

Besides, each self-join is run again commissioned on the two coasts of its own tyre and
pressure (:func:`same_machine`), each self-join not named dry gets the step check's
statistics of bench/coastdown_growth.py (:func:`why_not_dry`), and the self-joins are run
with other rises and another commissioning (:func:`variants`: data the kind rules were
not developed on).

The score is the final kind of the first change declared after the join. Results:
bench/results/coastdown_kinds.json, coastdown_kinds.png and the ``coastdown_kinds``
section of docs/results.md.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import pathlib
import tempfile
import time
from typing import Any

import numpy as np

from bench import report
from bench.bench_identify import MEASURED, NOT_A_FREE_COAST

COMMISSIONING = ('Greenspeed_Scorcher__Separate__Left__90_psi.csv',
                 'Greenspeed_Scorcher__Separate__Right__90_psi.csv')
# Another tyre's two coasts, for the self-joins of :func:`variants`.
OTHER_COMMISSIONING = ('Grandprix__Separate__Left__100_psi.csv',
                       'Grandprix__Separate__Right__100_psi.csv')
FLYWHEEL_FACTOR = 3.7     # the dry rise of the flywheel case, as a factor
GAP_S = 30.0
DRY_STEP = 0.05           # N m
VISCOUS_REL, DRAG_REL, FLAT_REL = 0.10, 0.03, 0.15
FLAT_SPEEDS = np.linspace(4.0, 36.0, 161)   # rad/s
KINDS = ('dry', 'undecided', 'both', 'viscous', 'none')


def coasts(quick: bool) -> dict[str, dict[str, Any]]:
    """Return run -> time, speed (rad/s), friction (N m) and fitted dry, viscous, drag."""
    from rwa_monitor.pipelines.identify import prepare
    from rwa_monitor.telemetry.coastdown import coastdown_runs, pendulum_inertia, read_coastdown
    inertia = pendulum_inertia(MEASURED, 'drum')
    runs = [run for run, body, _ in sorted(coastdown_runs(MEASURED))
            if body == 'drum' and not run.startswith(NOT_A_FREE_COAST)]
    if quick:
        runs = sorted(set(runs[::6]) | set(COMMISSIONING))
    out = {}
    for run in runs:
        data = prepare(read_coastdown(MEASURED, run, 'drum'), 'drum', inertia=inertia,
                       half_width='auto')
        w, f = data.speed, data.friction
        fit = np.linalg.lstsq(-np.column_stack([np.sign(w), w, w * np.abs(w)]), f,
                              rcond=None)[0]
        out[run] = {'time': data.time, 'speed': w, 'friction': f, 'dry': float(fit[0]),
                    'viscous': float(fit[1]), 'drag': float(fit[2])}
    return out


def write_record(path: pathlib.Path, parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
                 ) -> float:
    """Write coasts one after another, ``GAP_S`` apart; return the join time (s)."""
    times, join = [], float('nan')
    for i, (t, _, _) in enumerate(parts):
        shift = 0.0 if i == 0 else times[-1][-1] + GAP_S - t[0]
        times.append(t + shift)
        if i == 1:
            join = float(times[-1][0])
    table = np.column_stack([np.concatenate(times),
                             np.concatenate([p[1] for p in parts]),
                             np.concatenate([p[2] for p in parts])])
    np.savetxt(path, table, delimiter=',', header='time,drum_speed,drum_friction',
               comments='', fmt='%.17g')
    return join


def self_join(coast: dict[str, Any]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Return a coast and the same coast with its dry level raised by ``DRY_STEP``."""
    t, w, f = coast['time'], coast['speed'], coast['friction']
    return [(t, w, f), (t, w, f - DRY_STEP * np.sign(w))]


def variants(cs: dict[str, dict[str, Any]], others: list[str], calibration: pathlib.Path,
             folder: pathlib.Path) -> dict[str, Any]:
    """Return the self-joins' kinds with other dry rises and another commissioning.

    Rises of 0.02 and 0.10 N m and of the coast's own fitted dry level times
    ``FLYWHEEL_FACTOR - 1`` (commissioning as in the main table), and the rise of
    ``DRY_STEP`` commissioned on :data:`OTHER_COMMISSIONING` (its two coasts left out).
    """
    sub = folder / 'other'
    sub.mkdir()
    other = calibrate(list(OTHER_COMMISSIONING), cs, sub)
    cases = [('a rise of 0.02 N m', calibration, lambda c: 0.02, others),
             ('a rise of 0.10 N m', calibration, lambda c: 0.10, others),
             (f'the dry level x{FLYWHEEL_FACTOR:g}', calibration,
              lambda c: (FLYWHEEL_FACTOR - 1.0) * abs(c['dry']), others)]
    if other['exit'] == 0:
        cases.append((f'a rise of {DRY_STEP:g} N m, commissioned on '
                      f'{OTHER_COMMISSIONING[0].split("__")[0]} at '
                      f'{OTHER_COMMISSIONING[0].split("__")[-1][:-4].replace("_", " ")}',
                      pathlib.Path(other['path']), lambda c: DRY_STEP,
                      [r for r in others if r not in OTHER_COMMISSIONING]))
    out: dict[str, Any] = {'other_commissioning': other, 'cases': {}}
    for name, calib, rise, runs in cases:
        rows = {}
        for run in runs:
            c = cs[run]
            t, w, f = c['time'], c['speed'], c['friction']
            csv = folder / f'variant_{len(rows)}.csv'
            join = write_record(csv, [(t, w, f), (t, w, f - rise(c) * np.sign(w))])
            rows[run] = first_after(detect(csv, calib)['events'], join)
        out['cases'][name] = rows
    return out


def _rel(a: float, b: float) -> float:
    return abs(a - b) / (0.5 * (abs(a) + abs(b)))


def pairs(cs: dict[str, dict[str, Any]], runs: list[str]) -> list[tuple[str, str, bool]]:
    """Return (first, second, flat) for each pair of runs that differ by a dry step."""
    out = []
    for a, b in itertools.combinations(runs, 2):
        x, y = cs[a], cs[b]
        if (abs(x['dry'] - y['dry']) >= DRY_STEP and _rel(x['viscous'], y['viscous'])
                <= VISCOUS_REL and _rel(x['drag'], y['drag']) <= DRAG_REL):
            first, second = (a, b) if x['dry'] <= y['dry'] else (b, a)
            g = FLAT_SPEEDS
            d = (cs[second]['dry'] - cs[first]['dry'] + (cs[second]['viscous']
                 - cs[first]['viscous']) * g + (cs[second]['drag'] - cs[first]['drag']) * g * g)
            flat = bool(np.sqrt(np.mean((d - d.mean()) ** 2)) <= FLAT_REL * abs(d.mean()))
            out.append((first, second, flat))
    return out


def _cli(argv: list[str]) -> tuple[int, str]:
    from rwa_monitor.cli.main import main
    text = io.StringIO()
    with contextlib.redirect_stdout(text), contextlib.redirect_stderr(text):
        code = main(argv)
    return code, text.getvalue()


def detect(csv: pathlib.Path, calibration: pathlib.Path) -> dict[str, Any]:
    """Return ``rwa-monitor detect --calibration``'s JSON for one record."""
    out = csv.with_suffix('.json')
    code, text = _cli(['detect', str(csv), '--calibration', str(calibration), '-o', str(out)])
    if code not in (0, 1, 3):
        raise RuntimeError(f'detect {csv.name}: exit {code}: {text.strip()}')
    return json.loads(out.read_text())


def first_after(events: list[dict[str, Any]], join: float) -> dict[str, Any]:
    """Return the final kind of the first LLR change declared at or after ``join``."""
    changes: dict[int, list[dict[str, Any]]] = {}
    for event in events:
        if event.get('detector') == 'llr':
            changes.setdefault(int(event['index']), []).append(event)
    declared = {k: min(e['declared_time'] for e in v) for k, v in changes.items()}
    before = sum(1 for t in declared.values() if t < join)
    after = sorted((t, k) for k, t in declared.items() if t >= join)
    if not after:
        return {'kind': 'none', 'before': before}
    last = max(changes[after[0][1]], key=lambda e: e.get('revision', 0))
    return {'kind': last['kind'], 'before': before, 'reason': last.get('kind_reason'),
            'change_after_join_s': last['time'] - join,
            'delta_dry_nm': last.get('delta_dry_nm'),
            'delta_viscous_nms': last.get('delta_viscous_nms'),
            'declared_after_join_s': after[0][0] - join, 'z_dry': last.get('z_dry'),
            'z_viscous': last.get('z_viscous')}


def why_not_dry(csv: pathlib.Path, calibration: pathlib.Path, join: float,
                first: dict[str, Any]) -> dict[str, Any]:
    """Return :func:`coastdown_growth.growth_statistics` of a self-join not named dry."""
    import yaml
    from bench.coastdown_growth import growth_statistics
    from rwa_monitor.core.llr_config import LLRConfig
    from rwa_monitor.core.nominal import NominalWheel
    config = LLRConfig.from_parameters('drum')
    wheel = NominalWheel(yaml.safe_load(calibration.read_text())['calibration']['wheels']['drum'])
    t, w, f = np.loadtxt(csv, delimiter=',', skiprows=1).T
    residual = wheel.residual(t, w, f)[0]
    stats = growth_statistics(t, w, residual, join + first['change_after_join_s'],
                              config.window, config.z_threshold)
    stats['shared_speed_shape'] = {str(k): v for k, v in stats['shared_speed_shape'].items()}
    return stats


def same_machine(cs: dict[str, dict[str, Any]], folder: pathlib.Path) -> dict[str, Any]:
    """Return the self-joins of each coast commissioned on its own tyre and pressure.

    The commissioning: the left and the right coast of the same tyre at the same
    pressure (the coast itself among them: the nominal of its own machine). A
    commissioning that ``calibrate`` refuses is counted, not used.
    """
    out: dict[str, Any] = {'refused': 0, 'joins': {}}
    for run in sorted(cs):
        if run in COMMISSIONING:
            continue
        mate = run.replace('Left', 'Right') if 'Left' in run else run.replace('Right', 'Left')
        if mate not in cs:
            continue
        sub = folder / f'same_{len(out["joins"]) + out["refused"]}'
        sub.mkdir()
        cal = calibrate(sorted([run, mate]), cs, sub)
        if cal['exit'] != 0:
            out['refused'] += 1
            continue
        csv = sub / 'self.csv'
        join = write_record(csv, self_join(cs[run]))
        out['joins'][run] = first_after(detect(csv, pathlib.Path(cal['path']))['events'], join)
    return out


def calibrate(runs: list[str], cs: dict[str, dict[str, Any]], folder: pathlib.Path
              ) -> dict[str, Any]:
    """Calibrate on ``runs``; return the exit code, message and tested speeds."""
    files = []
    for run in runs:
        path = folder / f'cal_{len(files)}.csv'
        c = cs[run]
        write_record(path, [(c['time'], c['speed'], c['friction'])])
        files.append(str(path))
    out = folder / f'cal_{len(runs)}_runs'
    code, text = _cli(['calibrate', *files, '-o', str(out)])
    facts = {'runs': runs, 'exit': code, 'message': text.strip().splitlines()[-1] if text else '',
             'samples': int(sum(cs[r]['speed'].size for r in runs))}
    if code == 0:
        import yaml
        wheel = yaml.safe_load((out / 'calibration.yaml').read_text())[
            'calibration']['wheels']['drum']
        facts.update(path=str(out / 'calibration.yaml'),
                     tested_speeds_rad_s=wheel.get('tested_speeds_rad_s'),
                     tested_samples=wheel.get('tested_samples'))
    return facts


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run the measurement; write coastdown_kinds.json, its plot and the results section."""
    start = time.perf_counter()
    cs = coasts(quick)
    others = [r for r in cs if r not in COMMISSIONING]
    results: dict[str, Any] = {'quick': quick, 'dry_step_nm': DRY_STEP, 'gap_s': GAP_S}
    with tempfile.TemporaryDirectory(prefix='bench-coastdown-') as tmp:
        folder = pathlib.Path(tmp)
        results['calibration_one'] = calibrate(list(COMMISSIONING[:1]), cs, folder)
        cal = calibrate(list(COMMISSIONING), cs, folder)
        results['calibration'] = cal
        if cal['exit'] != 0:
            raise RuntimeError(f'the two-coast calibration was refused: {cal["message"]}')
        calibration = pathlib.Path(cal['path'])
        singles, selfs = {}, {}
        for run_name in others:
            c = cs[run_name]
            csv = folder / f'single_{len(singles)}.csv'
            write_record(csv, [(c['time'], c['speed'], c['friction'])])
            doc = detect(csv, calibration)
            component = doc['summary']['pipelines']['llr']['components']['drum']
            singles[run_name] = {'declarations': sum(e.get('detector') == 'llr'
                                                     for e in doc['events']),
                                 'verdict': component.get('verdict')}
            csv = folder / f'self_{len(selfs)}.csv'
            join = write_record(csv, self_join(c))
            selfs[run_name] = first_after(detect(csv, calibration)['events'], join)
            if selfs[run_name]['kind'] not in ('dry', 'none'):
                selfs[run_name]['growth'] = why_not_dry(csv, calibration, join,
                                                        selfs[run_name])
        results['same_machine'] = same_machine(cs, folder)
        results['variants'] = variants(cs, others, calibration, folder)
        joined = {}
        for first, second, flat in pairs(cs, others):
            csv = folder / f'pair_{len(joined)}.csv'
            join = write_record(csv, [(cs[r]['time'], cs[r]['speed'], cs[r]['friction'])
                                      for r in (first, second)])
            joined[f'{first[:-4]}+{second[:-4]}'] = {
                **first_after(detect(csv, calibration)['events'], join), 'flat': flat,
                **{f'fitted_{k}_difference': cs[second][k] - cs[first][k]
                   for k in ('dry', 'viscous', 'drag')}}
    results.update(singles=singles, self_joins=selfs, pairs=joined,
                   elapsed_s=time.perf_counter() - start)
    results['summary'] = summarise(results)
    report.write_json(out_dir, 'coastdown_kinds', results)
    plot(results, out_dir / 'coastdown_kinds.png')
    if not quick:
        report.update_section('coastdown_kinds', markdown(results))
    print(json.dumps(results['summary'], indent=1), flush=True)
    return results


def _counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    return {k: sum(r['kind'] == k for r in rows) for k in KINDS}


def summarise(results: dict[str, Any]) -> dict[str, Any]:
    """Return the counts of the tables."""
    singles = results['singles'].values()
    pairs_ = list(results['pairs'].values())
    return {'singles': len(singles),
            'singles_examined': sum(s['verdict'] == 'examined' for s in singles),
            'singles_with_declarations': sum(s['declarations'] > 0 for s in singles),
            'self_joins': _counts(list(results['self_joins'].values())),
            'pairs': _counts(pairs_), 'pairs_n': len(pairs_),
            'flat': _counts([p for p in pairs_ if p['flat']]),
            'flat_n': sum(p['flat'] for p in pairs_),
            'declared_before_join': sum(r['before'] > 0 for r in
                                        [*results['self_joins'].values(), *pairs_]),
            'same_machine': _counts(list(results['same_machine']['joins'].values())),
            'same_machine_n': len(results['same_machine']['joins']),
            'same_machine_refused': results['same_machine']['refused'],
            'variants': {name: _counts(list(rows.values())) for name, rows
                         in results['variants']['cases'].items()},
            'not_dry': _growth_counts(results['self_joins'])}


def _growth_counts(selfs: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Return how the self-joins not named dry stand against the growth limit."""
    rows = [r for r in selfs.values() if 'growth' in r]
    limit = [r['growth']['limit'] for r in rows]
    knots = list(rows[0]['growth']['shared_speed_shape']) if rows else []
    below = {k: int(sum(r['growth']['shared_speed_shape'][k] <= x for r, x in zip(rows, limit)))
             for k in knots}
    return {'n': len(rows),
            'after_only_above_limit': int(sum(r['growth']['after_only'] > x
                                              for r, x in zip(rows, limit))),
            'shared_speed_shape_at_or_below_limit': below,
            'change_before_join': int(sum(r['change_after_join_s'] < 0 for r in rows))}


def markdown(results: dict[str, Any]) -> str:
    """Return the docs/results.md section."""
    s, one, cal = results['summary'], results['calibration_one'], results['calibration']
    rows = [[name, n, *(counts[k] for k in KINDS)] for name, n, counts in (
        ('a coast joined with itself less a dry rise of '
         f'{results["dry_step_nm"]:g} N m (a pure dry step)', len(results['self_joins']),
         s['self_joins']),
        ('two coasts whose fitted levels differ by a dry step', s['pairs_n'], s['pairs']),
        ('of which flat (fitted difference within 15 % of its mean, 4-36 rad/s)',
         s['flat_n'], s['flat']))]
    tested = ', '.join(f'{lo:.1f} to {hi:.1f}' for lo, hi in cal['tested_speeds_rad_s'])
    growth = [[name[:-4], r['kind'], f'{r["change_after_join_s"]:.0f}',
               f'{r["growth"]["after_only"]:.0f}',
               *(f'{v:.1f}' for v in r['growth']['shared_speed_shape'].values()),
               f'{r["growth"]["limit"]:.1f}']
              for name, r in results['self_joins'].items() if 'growth' in r]
    knots = list(next(iter(r['growth']['shared_speed_shape'] for r in
                           results['self_joins'].values() if 'growth' in r), []))
    rows.append(['the same coasts, each commissioned on the two coasts of its own tyre and '
                 f'pressure ({s["same_machine_refused"]} such commissionings refused)',
                 s['same_machine_n'], *(s['same_machine'][k] for k in KINDS)])
    for name, counts in s['variants'].items():
        rows.append([f'a coast joined with itself with {name} (not used while developing '
                     'the speed-order rule)', len(results['variants']['cases'][name]),
                     *(counts[k] for k in KINDS)])
    return '\n'.join([
        '`python -m bench coastdown_kinds` (issue 35 item 3): drum coasts of '
        '../shared/data/measured/drum-coastdown read in place, friction J dw/dt; '
        f'records {GAP_S:g} s apart; `detect --calibration` with the default detector; '
        f'{results["elapsed_s"]:.0f} s.',
        '',
        f'- Commissioning on one coast ({one["samples"]} samples): exit {one["exit"]}: '
        f'"{one["message"]}".',
        f'- Commissioning on the two coasts of one tyre and pressure ({cal["samples"]} '
        f'samples): accepted, tested at {tested} rad/s ({cal["tested_samples"]} samples).',
        f'- Healthy coasts alone, with that calibration: {s["singles"]} records, '
        f'{s["singles_examined"]} examined, **{s["singles_with_declarations"]} with a '
        'declaration**.',
        f'- Declarations before the join: {s["declared_before_join"]}.',
        '',
        report.table(['records (final kind of the first change declared after the join)',
                      'n', *KINDS], rows),
        '',
        "Self-joins not named dry: the step check's statistic (bench/coastdown_growth.py: "
        "white-noise least squares on the nominal residual, against the detector's "
        'limit over its time shapes) on the after segment alone, and with a speed shape '
        'of k knots shared by the before and the after segment.',
        '',
        report.table(['coast', 'kind', 'change after join (s)', 'after alone',
                      *(f'shared shape, k = {k}' for k in knots), 'limit'], growth),
        '',
        'Plot: bench/results/coastdown_kinds.png.'])


def plot(results: dict[str, Any], path: pathlib.Path) -> None:
    """Draw the kinds of each set of records as stacked bars."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    s = results['summary']
    sets = [('pure dry step', s['self_joins']), ('pairs', s['pairs']), ('flat pairs', s['flat'])]
    fig, ax = plt.subplots(figsize=(7.5, 3.6), dpi=120)
    left = np.zeros(len(sets))
    colours = {'dry': '#2e7d32', 'undecided': '#9e9e9e', 'both': '#ef6c00',
               'viscous': '#1565c0', 'none': '#e0e0e0'}
    for kind in KINDS:
        values = np.array([counts[kind] for _, counts in sets], dtype=float)
        ax.barh([name for name, _ in sets], values, left=left, color=colours[kind], label=kind)
        left += values
    ax.invert_yaxis()
    ax.set_xlabel('records (final kind of the first change after the join)')
    ax.set_title('LLR kinds on joins of real drum coast-downs')
    ax.legend(ncol=5, fontsize=8, loc='lower center', bbox_to_anchor=(0.5, -0.45))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
