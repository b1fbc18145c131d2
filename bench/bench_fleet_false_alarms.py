"""``python -m bench fleet_false_alarms``: declarations on healthy wheels of simulated fleets.

Issue 31 item 1. For each seed: a constellation from ``rwa-monitor simulate fleet``'s code
(``sim/fleet.py``: plan, passes), each spacecraft commissioned on its commissioning passes
as ``--calibrate`` does (``pipelines/calibrated.commission``), then ``detect``'s code
(``rwa_monitor.pipelines.detect`` with the calibration and the fleet's parameters,
config/fleet.yaml, as ``rwa-monitor fleet`` reads them) on the
spacecraft's passes joined in time order (not the fleet engine). Events are scored against
the plan's truth (what truth.json holds):

- healthy time of a wheel: every pass of a wheel that neither wears nor has a fault, and
  the passes of a faulty (non-wearing) wheel that end before its first fault;
- false declaration: a first declaration (revision 0) whose change estimate lies in a
  wheel's healthy time (a declaration on a wearing wheel is not false: its friction
  changes);
- a fault is found when a first declaration on its wheel is declared no earlier than the
  first sample carrying it, with its change estimated no earlier than the start of the
  pass that holds the last sample before the fault (a fault between passes is then
  estimated before the gap: counted as found and as *misdated*, not as false); its final
  kind is the kind of the last event of that change (the end-of-record revision
  included).

What the data allow (the maths of the detector, not its output):

- a fault is *testable by the archive's end* when at least ``w + k_verif`` tested samples
  (finite residual against the nominal) follow it: Algorithm 1 declares a change at
  sample ``k_min`` on the arrival of sample ``k_min + k_verif + w`` (docs/llr.md), so a
  fault followed by fewer cannot be declared by any run of the archive (a later run
  would);
- its kind is *told by the data* when the kind test has at least 95 % power on the tested
  samples after it: the true component's column made orthogonal to the other kind's
  column (``sign(w)`` and ``w``) carries ``z = |size| ||P w|| / sigma`` (sigma the
  simulator's noise std) of at least ``z(1 - category_level / 2) + z(0.95)``; below it
  the data after the fault cannot tell dry from viscous (a wheel at a nearly constant
  speed), and ``undecided`` is as right as the true kind (a named wrong kind or ``both``
  is wrong either way).

``--seeds`` picks seeds (development and acceptance seeds are kept apart by the user:
docs/results.md says which were which). Results: bench/results/fleet_false_alarms.json and
the ``fleet_false_alarms`` section of docs/results.md.
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import sys
import tempfile
import time
from typing import Any, Iterable, Sequence

import numpy as np

from bench import report

SETTINGS = {'spacecraft': 6, 'days': 4.0}
QUICK = {'spacecraft': 2, 'days': 3.0}
DEFAULT_SEEDS = tuple(range(1, 4))
GOAL_PER_100_H = 1.0
# The fleet report's trend flag level (docs/fleet.md, "Report").
TREND_LEVEL = 1.0e-3


def spacecraft_telemetry(plan: Any, craft: Any) -> tuple[list[Any], Any]:
    """Return (the commissioning records, every pass joined in time order).

    The joined record's ``aux['pass']`` numbers the passes (0, 1, ...), for the trend.
    """
    from rwa_monitor.sim.fleet import pass_telemetry
    from rwa_monitor.telemetry import Telemetry
    order = sorted(range(len(craft.passes)), key=lambda i: craft.passes[i].start_s)
    records = [pass_telemetry(plan, craft, i) for i in order]
    for i, tele in zip(order, records):
        tele.source = f'{craft.name}/{craft.passes[i].pass_id}.csv'
    parts = [r.columns() for r in records]
    joined = Telemetry.from_columns({k: np.concatenate([c[k] for c in parts])
                                     for k in parts[0]}, source=f'{craft.name} joined')
    joined.aux['pass'] = np.concatenate([np.full(len(r), float(i))
                                         for i, r in enumerate(records)])
    return records[:plan.commissioning_passes], joined


def detect_spacecraft(plan: Any, craft: Any, folder: pathlib.Path,
                      llr: dict[str, Any] | None = None) -> dict[str, Any]:
    """Commission, then run detect's code on the joined passes; return events and facts.

    ``llr``: llr_detector parameters to set over the fleet's (config/fleet.yaml).
    """
    import yaml
    from rwa_monitor.cli.cmd_detect import load_config
    from rwa_monitor.core.identify.model import plain
    from rwa_monitor.fleet.engine import fleet_parameters_file
    from rwa_monitor.pipelines import calibrated, detect
    commissioning, joined = spacecraft_telemetry(plan, craft)
    document, warnings, _ = calibrated.commission(commissioning)
    path = folder / f'{craft.name}.yaml'
    path.write_text(yaml.safe_dump(plain(document), sort_keys=False))
    config = load_config(fleet_parameters_file())
    block = config.setdefault('llr_detector', {}).setdefault('ros__parameters', {})
    block['calibration_file'] = str(path)
    block.update(llr or {})
    passes = joined.aux.pop('pass')
    events, summary = detect(joined.only('wheels'), config)
    wheels = summary['pipelines']['llr']['components'] if 'pipelines' in summary else {}
    residuals = nominal_residuals(document['calibration']['wheels'], joined)
    llr_events = [e for e in events if e.detector == 'llr']
    return {'events': llr_events, 'summary': wheels,
            'warnings': warnings, 'time': joined.time,
            'trend': trends(residuals, joined, passes, llr_events),
            'tested': {w: (joined.wheels[w].speed, np.isfinite(r))
                       for w, r in residuals.items()},
            'limits': data_limits(config)}


def nominal_residuals(blocks: dict[str, Any], joined: Any) -> dict[str, np.ndarray]:
    """Return per wheel the calibrated detector's input (NaN where not tested)."""
    from rwa_monitor.core.nominal import NominalWheel
    out = {}
    for wheel, block in blocks.items():
        ch = joined.wheels[wheel]
        out[wheel], _ = NominalWheel(block).residual(joined.time, ch.speed, ch.friction)
    return out


def data_limits(config: dict[str, Any]) -> dict[str, float]:
    """Return what the detector needs after a change: samples, and the kind test's z.

    ``samples``: ``w + k_verif`` (Algorithm 1 line 18, docs/llr.md); ``kind_z``: the z at
    which the kind test (two-sided, ``category_level``) has 95 % power.
    """
    from scipy.stats import norm

    from rwa_monitor.cli.cmd_detect import node_parameters
    from rwa_monitor.core.llr_config import LLRConfig, PARAMETERS
    cfg = LLRConfig.from_parameters(**{
        k: v for k, v in node_parameters(config, 'llr_detector').items() if k in PARAMETERS})
    return {'samples': float(cfg.window + cfg.k_verif),
            'kind_z': float(norm.isf(cfg.category_level / 2.0) + norm.isf(0.05))}


def kind_z(kind: str, delta_dry: float, delta_viscous: float, speed: np.ndarray,
           sigma: float) -> float:
    """Return the z of a change's own kind beyond the other kind's column.

    The size of the true component along its column made orthogonal to the other kind's
    column (``sign(w)`` for dry, ``w`` for viscous) over ``speed``, in noise std: the
    kind test's expected statistic. ``both``: the smaller of the two.
    """
    columns = {'dry': (np.sign(speed), speed, abs(delta_dry)),
               'viscous': (speed, np.sign(speed), abs(delta_viscous))}
    kinds = ('dry', 'viscous') if kind == 'both' else (kind,)
    out = math.inf
    for name in kinds:
        own, other, size = columns[name]
        scale = float(other @ other)
        rest = own - (own @ other / scale) * other if scale > 0.0 else own
        out = min(out, size * float(np.sqrt(rest @ rest)) / sigma)
    return out


def trends(residuals: dict[str, np.ndarray], joined: Any, passes: np.ndarray,
           events: Sequence[Any] = ()) -> dict[str, Any]:
    """Return per wheel the dry trend of the pass levels against nominal (the fleet's).

    As the fleet engine does (docs/fleet.md): ``pass_levels`` of each pass on the
    calibrated detector's input (``NominalWheel.residual``: NaN where not tested), then
    fleet/trends.py ``wheel_trends`` of them, with a jump at each confirmed step of
    ``events`` (``trend_steps``).
    """
    from rwa_monitor.core.trend import pass_levels
    from rwa_monitor.fleet.trends import trend_steps, wheel_trends
    bounds = np.flatnonzero(np.diff(passes)) + 1
    rows = []
    for wheel, residual in residuals.items():
        ch = joined.wheels[wheel]
        for i, seg in enumerate(np.split(np.arange(len(joined)), bounds)):
            lv = pass_levels(joined.time[seg], ch.speed[seg], residual[seg])
            rows.append({'spacecraft': '', 'wheel': wheel, 'pass': str(i),
                         't_start': lv.t_start, 't_end': lv.t_end, 'samples': lv.samples,
                         'dry': lv.dry, 'dry_se': lv.dry_se, 'viscous': lv.viscous,
                         'viscous_se': lv.viscous_se, 'relative_to': 'nominal'})
    steps = trend_steps(('', e) for e in events)
    out = {}
    for entry in wheel_trends(rows, None, steps):
        out[entry['wheel']] = {'dry_slope_nm_per_day': entry['dry_slope_per_day'],
                               'dry_slope_se': entry['dry_slope_se'],
                               'p_value': entry['dry_p_value'], 'passes': entry['passes'],
                               'steps_s': entry['steps_s']}
    return out


def _healthy_until(craft: Any, wheel: str) -> float:
    """Return the time up to which a wheel is healthy (inf: always; -inf: wears)."""
    if craft.wear_per_day[wheel] > 0:
        return -math.inf
    faults = [f.time_s for f in craft.faults if f.wheel == wheel]
    return min(faults) if faults else math.inf


def score_spacecraft(plan: Any, craft: Any, found: dict[str, Any]) -> dict[str, Any]:
    """Score one spacecraft's events against the plan's truth."""
    pass_s = plan.pass_s
    starts = np.array(sorted(p.start_s for p in craft.passes))
    ends = starts + (int(math.floor(pass_s * plan.rate_hz + 1e-9)) - 1) / plan.rate_hz
    time = found['time']
    # First declarations and end-of-record events (revisions in between are left out).
    out: dict[str, Any] = {'spacecraft': craft.name, 'wheels': {}, 'warnings':
                           found['warnings'],
                           'events': [e.to_json() for e in found['events']
                                      if e.revision == 0 or e.details.get('final')]}
    for wheel in plan.wheels:
        events = [e for e in found['events'] if e.component == wheel]
        first = [e for e in events if e.revision == 0]
        limit = _healthy_until(craft, wheel)
        healthy_s = float(np.sum(np.clip(np.minimum(ends, limit) - starts, 0.0, None)
                                 + (ends < limit) / plan.rate_hz))
        faults = []
        for fault in (f for f in craft.faults if f.wheel == wheel):
            before = time[time < fault.time_s]
            after = time[time >= fault.time_s]
            lo = float(before[-1]) if before.size else -math.inf
            first_sample = float(after[0]) if after.size else math.inf
            # The fault's declaration: declared once a sample carries it, its change
            # estimated at or after the start of the pass that holds the last sample
            # before the fault (an estimate before that sample is misdated: the fault
            # fell in the gap after it, docs/fleet.md "False declarations").
            since = float(np.max(starts[starts <= lo], initial=-math.inf))
            hits = [e for e in first if e.time >= since - 1e-9
                    and e.declared_time >= first_sample]
            speed, tested = found['tested'][wheel]
            after_tested = tested & (time >= fault.time_s)
            z = kind_z(fault.kind, fault.delta_dry, fault.delta_viscous,
                       speed[after_tested], craft.noise_std)
            result = {'truth_kind': fault.kind, 'time_s': fault.time_s,
                      'first_sample_s': first_sample, 'found': bool(hits),
                      'tested_after': int(after_tested.sum()),
                      'testable': bool(after_tested.sum() >= found['limits']['samples']),
                      'kind_z': z, 'kind_told': bool(z >= found['limits']['kind_z'])}
            if hits:
                result.update(_brief(hits[0], time, events))
                result['misdated_s'] = max(0.0, lo - hits[0].time)
                result['event_index'] = hits[0].index
            result['right_kind'] = bool(hits) and (
                result['final_kind'] == fault.kind
                or (not result['kind_told'] and result['final_kind'] == 'undecided'))
            faults.append(result)
        found_at = {f.get('event_index') for f in faults}
        false = [e for e in first if e.time < limit and e.index not in found_at]
        entry: dict[str, Any] = {
            'wears': craft.wear_per_day[wheel] > 0, 'healthy_hours': healthy_s / 3600.0,
            'declarations': len(first),
            'false': [_brief(e, time) for e in false], 'faults': faults,
            'wear_declarations': ([_brief(e, time, events) for e in first]
                                  if craft.wear_per_day[wheel] > 0 else []),
            'wear_nm_per_day': craft.wear_per_day[wheel],
            'trend': found['trend'].get(wheel, {}),
            'verdict': found['summary'].get(wheel, {}).get('verdict'),
            'not_tested': found['summary'].get(wheel, {}).get('not_tested', {})}
        out['wheels'][wheel] = entry
    return out


def _brief(event: Any, time: np.ndarray, events: Iterable[Any] = ()) -> dict[str, Any]:
    """Return the facts of a first declaration (and its final kind among ``events``)."""
    same = [e for e in events if e.index == event.index] or [event]
    last = same[-1]
    return {'change_time_s': event.time, 'declared_time_s': event.declared_time,
            'kind': event.kind, 'final_kind': last.kind,
            'kind_shape': last.details.get('kind_shape'),
            'p_value': event.p_value, 'delta_dry_nm': event.details.get('delta_dry_nm'),
            'delta_viscous_nms': event.details.get('delta_viscous_nms'),
            'revisions': len(same) - 1}


def run_seed(seed: int, spacecraft: int, days: float, folder: pathlib.Path,
             llr: dict[str, Any] | None = None) -> dict[str, Any]:
    """Simulate, calibrate, detect and score one constellation."""
    from rwa_monitor.sim.fleet import plan_fleet
    plan = plan_fleet(spacecraft=spacecraft, days=days, seed=seed)
    crafts = []
    for craft in plan.spacecraft:
        start = time.perf_counter()
        found = detect_spacecraft(plan, craft, folder, llr)
        crafts.append(score_spacecraft(plan, craft, found))
        crafts[-1]['wall_s'] = time.perf_counter() - start
        print(f'  seed {seed} {craft.name}: {_line(crafts[-1])}', flush=True)
    return {'seed': seed, 'spacecraft': crafts, **totals(crafts)}


def _line(craft: dict[str, Any]) -> str:
    parts = []
    for wheel, entry in craft['wheels'].items():
        tags = [f'{len(entry["false"])} false'] if entry['false'] else []
        tags += [f'fault {f["truth_kind"]}: '
                 + (f'found {f["final_kind"]}' if f['found'] else 'missed')
                 for f in entry['faults']]
        if entry['wears']:
            tags.append(f'wears, {len(entry["wear_declarations"])} declared')
        if tags:
            parts.append(f'{wheel} ' + ', '.join(tags))
    return '; '.join(parts) or 'quiet'


def totals(crafts: list[dict[str, Any]]) -> dict[str, Any]:
    """Sum the false declarations, healthy hours and faults over spacecraft."""
    wheels = [w for c in crafts for w in c['wheels'].values()]
    false = sum(len(w['false']) for w in wheels)
    hours = sum(w['healthy_hours'] for w in wheels)
    faults = [f for w in wheels for f in w['faults']]
    return {'false': false, 'healthy_hours': hours,
            'false_per_100_h': 100.0 * false / hours if hours else math.nan,
            'faults': len(faults), 'faults_found': sum(f['found'] for f in faults),
            'faults_right_kind': sum(f['found'] and f['final_kind'] == f['truth_kind']
                                     for f in faults),
            'faults_misdated': sum(f.get('misdated_s', 0.0) > 0 for f in faults),
            'faults_testable': sum(f['testable'] for f in faults),
            'faults_testable_found': sum(f['testable'] and f['found'] for f in faults),
            'faults_kind_told': sum(f['found'] and f['kind_told'] for f in faults),
            'faults_right_kind_as_told': sum(f['right_kind'] for f in faults),
            'wear_declarations': sum(len(w['wear_declarations']) for w in wheels),
            'wear_declarations_ramp': sum(d['kind_shape'] == 'ramp' for w in wheels
                                          for d in w['wear_declarations']),
            'wheels_not_examined': sum(w['verdict'] not in (None, 'examined')
                                       for w in wheels),
            'wearing_wheels': sum(w['wears'] for w in wheels),
            'wearing_trend_flagged': sum(w['wears'] and _trend_flag(w) for w in wheels),
            'other_trend_flagged': sum(not w['wears'] and _trend_flag(w) for w in wheels)}


def _trend_flag(wheel: dict[str, Any]) -> bool:
    """Return the report's trend flag: a dry slope with p < TREND_LEVEL (docs/fleet.md)."""
    p = wheel.get('trend', {}).get('p_value', math.nan)
    return bool(p < TREND_LEVEL)


def evaluate(seeds: Iterable[int], spacecraft: int, days: float,
             llr: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run every seed; return per-seed results and the totals.

    ``llr``: llr_detector parameters set over the fleet's (another operating point).
    """
    with tempfile.TemporaryDirectory(prefix='fleet_fa_') as tmp:
        runs = [run_seed(s, spacecraft, days, pathlib.Path(tmp), llr) for s in seeds]
    crafts = [c for r in runs for c in r['spacecraft']]
    return {'settings': {'spacecraft': spacecraft, 'days': days,
                         'seeds': [r['seed'] for r in runs], 'llr': dict(llr or {})},
            'runs': runs, 'totals': totals(crafts), 'goal_false_per_100_h': GOAL_PER_100_H}


def markdown(result: dict[str, Any], label: str) -> str:
    """Return the docs/results.md table of one evaluation."""
    s = result['settings']
    rows = [[r['seed'], *_cells(r)] for r in result['runs']]
    rows.append(['all', *_cells(result['totals'])])
    return (f'{label}: {s["spacecraft"]} spacecraft x {s["days"]:g} days per seed, '
            f'seeds {_span(s["seeds"])}{_setting(s)}; goal at most {GOAL_PER_100_H:g} false first '
            'declaration per 100 healthy wheel-hours.\n\n'
            + report.table(['seed', 'false', 'healthy wheel-hours', 'per 100 h',
                            'faults found (of those testable)',
                            'right final kind (as the data tell it)',
                            'wearing wheels: declarations', 'trend flag: wearing / others'],
                           rows))


def _setting(settings: dict[str, Any]) -> str:
    rate = settings.get('llr', {}).get('false_alarm_rate')
    if rate is None:
        return ", the fleet's parameters (config/fleet.yaml)"
    return f", r = {rate:g} set over the fleet's parameters"


def _cells(t: dict[str, Any]) -> list[Any]:
    return [t['false'], f'{t["healthy_hours"]:.1f}', f'{t["false_per_100_h"]:.2f}',
            f'{t["faults_found"]}/{t["faults"]} ({t.get("faults_testable_found", "-")}/'
            f'{t.get("faults_testable", "-")}; {t.get("faults_misdated", 0)} misdated)',
            f'{t["faults_right_kind"]}/{t["faults"]} ({t.get("faults_right_kind_as_told", "-")}'
            f'/{t["faults_found"]}; kind told by the data {t.get("faults_kind_told", "-")})',
            f'{t["wear_declarations"]} ({t["wear_declarations_ramp"]} ramp)',
            f'{t.get("wearing_trend_flagged", "-")}/{t.get("wearing_wheels", "-")} / '
            f'{t.get("other_trend_flagged", "-")}']


def _span(seeds: list[int]) -> str:
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f'{seeds[0]}-{seeds[-1]}'
    return ', '.join(map(str, seeds))


def run(out: pathlib.Path, quick: bool, seeds: Iterable[int] = DEFAULT_SEEDS,
        label: str = 'development', name: str = 'fleet_false_alarms',
        llr: dict[str, Any] | None = None) -> dict[str, Any]:
    """Evaluate, write the JSON and the results.md section; return the result."""
    settings = QUICK if quick else SETTINGS
    result = evaluate(seeds, settings['spacecraft'], settings['days'], llr)
    result['label'] = label
    result['machine'] = report.machine()
    report.write_json(out, name, result)
    t = result['totals']
    print(f'{label}: {t["false"]} false first declarations in {t["healthy_hours"]:.1f} '
          f'healthy wheel-hours ({t["false_per_100_h"]:.2f} per 100 h); faults found '
          f'{t["faults_found"]}/{t["faults"]} (testable {t["faults_testable_found"]}/'
          f'{t["faults_testable"]}), right kind {t["faults_right_kind"]} (as the data tell '
          f'it {t["faults_right_kind_as_told"]}/{t["faults_found"]})')
    if not quick:
        report.update_section(name, markdown(result, label))
    return result


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(','):
        lo, _, hi = part.partition('-')
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: ``python -m bench.bench_fleet_false_alarms --seeds 1-20``."""
    parser = argparse.ArgumentParser(prog='python -m bench.bench_fleet_false_alarms')
    parser.add_argument('--seeds', default='1-3', help='e.g. 1-20 or 9001-9030')
    parser.add_argument('--label', default='development')
    parser.add_argument('--name', default='fleet_false_alarms',
                        help='JSON / results.md section name')
    parser.add_argument('--out', type=pathlib.Path, default=report.RESULTS_DIR)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--false-alarm-rate', type=float, default=None,
                        help="the LLR's r (default: the fleet's, config/fleet.yaml)")
    args = parser.parse_args(argv)
    os.environ.setdefault('PYTHONHASHSEED', '0')
    llr = ({} if args.false_alarm_rate is None
           else {'false_alarm_rate': args.false_alarm_rate})
    run(args.out, args.quick, _seeds(args.seeds), args.label, args.name, llr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
