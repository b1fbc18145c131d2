"""The section of docs/results.md of bench/bus_answers.py, from its results alone.

The results carry their own ``setup`` (seeds, durations, fault sizes), so this module
imports nothing from the bench that runs them.
"""

from __future__ import annotations

import json
from typing import Any

from bench.report import table


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


def _healthy_hours(files: list[dict[str, Any]], setup: dict[str, Any]) -> float:
    hours, after = setup['hours'], setup['hours'] - setup['fault_time_s'] / 3600.0
    return sum(len(setup['wheels']) * hours - len(f['changes']) * after
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


def markdown_kinds(llr: dict[str, Any], setup: dict[str, Any]) -> list[str]:
    """Return the kinds table (both modes) and the per-change detail of the calibrated."""
    files = [f for f in llr['files'] if f['changes']]
    hours = _healthy_hours(files, setup)
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
                   'reason (undecided)', 'delay (s)'], detail), ''] + _kind_notes(
                       files, setup['fault_time_s'])


def _kind_notes(files: list[dict[str, Any]], fault_time_s: float) -> list[str]:
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
               if c['detected'] and abs(c['time'] - fault_time_s) > 600.0]
        lines.append(f'- {mode}: first declarations after the change whose estimated change '
                     f'time is more than 600 s from {fault_time_s:g} s (likely not the injected '
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
        for w in fitted:
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


def markdown(results: dict[str, Any]) -> str:
    """Return the section of docs/results.md."""
    setup = results['setup']
    seeds = setup['eval_seeds']
    lines = ['## Bus check of this round (`python -m bench.bus_answers`)', '',
             f'Basilisk bus, default guidance and null speed (wheels cross zero), '
             f'{setup["hours"]:g}-hour files at 4 Hz (43,200 samples per wheel); LLR '
             f'parameters of config/rwa_monitor.yaml; seeds fixed before any result was '
             f'seen (none of 3100-3123 was used before in bench/, test/ or docs/). '
             f'Calibration: the fault-free commissioning run, seed '
             f'{setup["calibration_seed"]} (`rwa-monitor calibrate`). Run on '
             f'{results.get("date", "?")}, load average {results.get("load", "?")}.', '']
    llr = results.get('llr')
    if llr:
        lines += ['### Streaming == batch on bus files (issue 25 item 2)', '',
                  'Per file, mode and wheel: `LLRDetector.update` row by row '
                  '(`update_nominal`, the call of the calibrated node) then '
                  '`finish()`, against `process_arrays` + `finish()`, `detect_batch_with_'
                  'counters` and `rwa-monitor detect [--calibration]`; every field of every '
                  'event (its events-file JSON) and the counters. Files: seed '
                  f'{setup["calibration_seed"]} (commissioning) and seeds {seeds[0]}-'
                  f'{seeds[-1]} (a dry step {setup["dry"]} N m on one wheel and a viscous '
                  f'step {setup["viscous"]} N m s/rad on another, at '
                  f'{setup["fault_time_s"]:g} s).', '']
        lines += markdown_equivalence(llr) + ['']
        lines += ['### Kinds on the bus (issue 26 item 2)', '',
                  'Final kind = the last revision (the end-of-record one included) of the '
                  'first declaration at or after the change on its wheel; false = any other '
                  'declaration on a healthy wheel or before the change; extra = a further '
                  'declaration on the faulty wheel after the change.', '']
        lines += markdown_kinds(llr, setup) + ['']
    ident = results.get('identify')
    if ident:
        lines += ['### `rwa-monitor identify` on the four identical wheels (issue 26 item 4)',
                  '', '`rwa-monitor identify FILE --wheel all` (joint selection, the default) '
                  'and `--separately`, on fault-free files, seeds '
                  f'{", ".join(map(str, setup["identify_seeds"]))}; held-out RMSE over the '
                  'noise floor.', '']
        lines += markdown_identify(ident) + ['']
    return '\n'.join(lines)
