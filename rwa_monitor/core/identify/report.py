"""The identification report: report.json (DESIGN.md contract), markdown and plots.

report.json has exactly the keys of DESIGN.md: ``baseline`` (model and parameters),
``noise_floor`` (N m), ``rmse_before`` / ``rmse_after`` (each ``in_sample`` and
``held_out``, N m) and ``effects`` (``name``, ``parameters``, ``evidence``; listed in the
vocabulary's order, effects.canonical_order, so that wheels with the same effects read
the same; ``evidence.added_at_step`` keeps the order the selection added them in), plus
``dropped_rows`` (rows with a non-finite value, rows whose time does not increase) when
any input row was left out. Everything else (the steps of the selection with every
candidate's evidence, the residual tests before and after, the jumps) goes to
selection.json.
This module builds the dictionaries and the markdown text (no I/O, no plots);
pipelines/identify_report.py draws the figures and writes the files.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from rwa_monitor.core.identify.effects import canonical_order, FALLBACK
from rwa_monitor.core.identify.model import column_names, plain

# Input rows left out, reported in report.json when there are any (docs/contracts.md).
DROPPED = ('non_finite', 'time_not_increasing')
UNEXPLAINED = 'unexplained speed dependence'


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def effect_parameters(eff, coef: np.ndarray) -> dict:
    """Return an effect's parameters: its nonlinear ones and its named weights."""
    params = dict(plain(eff.params))
    weights = coef[eff.columns]
    if eff.kind in ('stribeck', 'stribeck_hysteresis'):
        params['static_excess_nm'] = float(weights[0])
    elif eff.kind == 'presliding':
        params['coulomb_replaced_nm'] = float(weights[0])
    elif eff.kind == 'asymmetric_coulomb':
        params['offset_nm'] = float(weights[0])
    elif eff.kind == 'drag':
        params['coefficient'] = float(weights[0])
    elif eff.kind == 'aux':
        params['coefficient'] = float(weights[0])
    elif eff.kind == 'drift':
        params['change_over_record'] = float(weights[0])
    elif eff.kind == 'periodic':
        params['amplitude_nm'] = float(np.hypot(weights[0], weights[1]))
        params['phase_rad'] = float(np.arctan2(-weights[1], weights[0]))
    elif eff.kind in MOTION_WEIGHTS:
        params.update(_motion_parameters(eff.kind, eff.params, weights))
    else:
        params['values_nm'] = [float(w) for w in weights]
    params['weights'] = dict(zip(column_names(eff.name, eff.kind, eff.params),
                                 [float(w) for w in weights]))
    return params


MOTION_WEIGHTS = ('frictional_lag', 'stick', 'presliding_state', 'gravity_load', 'load_dry',
                  'gear_ripple', 'inertia')


def _motion_parameters(kind: str, params: dict, weights: np.ndarray) -> dict:
    """Return the named weights of an effect with a state or a position (effects_motion)."""
    w = [float(v) for v in weights]
    if kind == 'frictional_lag':
        return {'coulomb_lagged_nm': w[0]}
    if kind == 'presliding_state':
        return {'coulomb_elastic_nm': w[0]}
    if kind == 'inertia':
        return {'inertia_kg_m2': w[0]}
    if kind == 'stick':
        return {'dry_released_nm': w[0], 'held_level_nm': w[1], 'breakaway_nm': w[2]}
    if kind in ('gravity_load', 'load_dry'):
        # a sin q + b cos q = A sin(q + phi)
        key = 'amplitude_nm' if kind == 'gravity_load' else 'dry_amplitude_nm'
        return {key: float(np.hypot(w[0], w[1])), 'phase_rad': float(np.arctan2(w[1], w[0]))}
    out = {'period_rad': 1.0 / float(params['cycles_per_rad'])}
    pairs = {'torque': w[:2], 'dry': w[-2:]}
    for part in ('torque', 'dry'):
        if params['component'] in (part, 'both'):
            key = 'amplitude_nm' if part == 'torque' else 'dry_amplitude_nm'
            out[key] = float(np.hypot(*pairs[part]))
    return out


def report(selection) -> dict:
    """Return report.json's content (DESIGN.md contract)."""
    base, final = selection.baseline_fit, selection.final_fit
    nb = len(selection.baseline_names)
    parameters = {n: float(c) for n, c in zip(selection.baseline_names, base.coef[:nb])}
    for i, start in enumerate(selection.segments.starts[1:], start=1):
        parameters[f'jump{i}_time_s'] = float(selection.data.time[start])
    effects = []
    order = canonical_order([e.name for e in selection.effects])
    added = {e.name: i for i, e in enumerate(selection.effects, start=1)}
    for eff in sorted(selection.effects, key=lambda e: order.index(e.name)):
        evidence = {k: _finite(v) for k, v in plain(eff.evidence).items()}
        evidence['added_at_step'] = added[eff.name]
        params = effect_parameters(eff, final.coef)
        if eff.name == FALLBACK:
            params['meaning'] = UNEXPLAINED
            params['size_rms_nm'] = catch_all_size(selection, eff)
        effects.append({'name': eff.name, 'parameters': params, 'evidence': evidence})
    out = {'baseline': {'model': 'coulomb+viscous', 'parameters': parameters},
           'noise_floor': float(selection.data.noise_floor),
           'rmse_before': {'in_sample': base.rmse_train, 'held_out': base.rmse_test},
           'rmse_after': {'in_sample': final.rmse_train, 'held_out': final.rmse_test},
           'effects': effects}
    counts = selection.data.counts
    dropped = {key: int(counts.get(f'{key}_rows', 0)) for key in DROPPED}
    if any(dropped.values()):
        out['dropped_rows'] = dropped
    return out


def catch_all_size(selection, eff) -> float:
    """Return the RMS (N m) over every row of what a catch-all adds beyond the model.

    Its fitted part less what the model's other columns can hold of it (least squares):
    the hats of `smooth_speed` also span the Coulomb and viscous columns.
    """
    x = selection.design.X
    part = x[:, eff.columns] @ selection.final_fit.coef[eff.columns]
    others = np.delete(x, np.arange(x.shape[1])[eff.columns], axis=1)
    beyond = part - others @ np.linalg.lstsq(others, part, rcond=None)[0]
    return float(np.sqrt(np.mean(beyond ** 2)))


def reversals(selection) -> dict:
    """Return where the record's speed sign changes fall: in training or held-out rows.

    A reversal between rows k and k + 1 belongs to the held-out rows when both rows are
    held out (core/identify/fitting.py ``held_out_mask``), to the training rows when
    neither is. Every effect near zero speed (hysteresis, pre-sliding, lag) is shaped by
    reversals: when all of a record's reversals fall in held-out blocks, those effects
    are fitted on approaches to zero only, and the held-out RMSE measures how they
    extrapolate to a reversal (found on a 30-minute bus record, seed 3, rw2: both of its
    reversals held out, held out 8.6e-5 -> 1.66e-4 N m against a floor of 5.2e-5).
    Keys ``total``, ``held_out``, ``training`` and ``note`` (None unless all are held out).
    """
    from rwa_monitor.core.identify.fitting import held_out_mask
    w = np.asarray(selection.data.speed, dtype=float)
    sign = np.sign(w)
    k = np.flatnonzero((sign[1:] != sign[:-1]) & (sign[1:] != 0) & (sign[:-1] != 0))
    test = held_out_mask(len(w))
    held = int(np.count_nonzero(test[k] & test[k + 1]))
    train = int(np.count_nonzero(~test[k] & ~test[k + 1]))
    note = None
    if held and not train:
        note = (f'all {held} speed reversal(s) of the record fall in held-out rows and none '
                'in the training rows: effects near zero speed were fitted without a '
                'reversal, so the held-out RMSE includes their extrapolation to one (a '
                'record with more reversals tests them)')
    return {'total': int(k.size), 'held_out': held, 'training': train, 'note': note}


def _tests(diag: dict) -> dict:
    return {k: {kk: _finite(vv) for kk, vv in plain(v).items()}
            for k, v in diag['tests'].items()}


def identifiability(selection) -> dict:
    """Return which named effects this run can and cannot show, with the reasons.

    A run whose speed never reverses or never comes to rest cannot show hysteresis; one
    that spins one way cannot show an asymmetric Coulomb level; constant channels
    cannot show their effect.
    """
    from rwa_monitor.core.identify.effects import named_candidates
    cands = named_candidates(selection.data, selection.residual_after())
    return {'testable': sorted({c.name for c in cands if c.skipped is None}),
            'not_identifiable': {c.name: c.skipped for c in cands if c.skipped is not None}}


def details(selection) -> dict:
    """Return selection.json's content: steps, tests before/after, jumps, data counts."""
    data = selection.data
    return plain({'wheel': data.wheel, 'samples': len(data), 'derived_friction': data.derived,
                  'counts': data.counts, 'notes': data.notes,
                  'jumps': selection.segments.evidence,
                  'first_pass_jumps': selection.first_pass_jumps,
                  'stop_reason': selection.stop_reason,
                  'identifiability': identifiability(selection),
                  'reversals': reversals(selection),
                  'history': {'zero_passages': selection.data.past.passages,
                              'left_zero_samples':
                              int(selection.data.past.left_zero.sum())},
                  'tests_before': _tests(selection.diagnostics_before),
                  'failing_before': selection.diagnostics_before['failing'],
                  'tests_after': _tests(selection.diagnostics_after),
                  'failing_after': selection.diagnostics_after['failing'],
                  'steps': selection.steps,
                  'named_sets_compared': selection.alternatives})


def markdown(selection, rep: dict, title: str) -> str:
    """Return the short markdown report."""
    lines = [f'# Identification: {title}', '',
             f'Wheel `{selection.data.wheel}`, {len(selection.data)} samples'
             f'{" (friction from speed, eq. 1b)" if selection.data.derived else ""}.',
             f'Noise floor {rep["noise_floor"]:.3g} N m.', '',
             '| model | RMSE in sample (N m) | RMSE held out (N m) |', '|---|---|---|',
             f'| baseline (Coulomb + viscous) | {rep["rmse_before"]["in_sample"]:.4g} | '
             f'{rep["rmse_before"]["held_out"]:.4g} |',
             f'| refined | {rep["rmse_after"]["in_sample"]:.4g} | '
             f'{rep["rmse_after"]["held_out"]:.4g} |', '']
    jumps = [k for k in rep['baseline']['parameters'] if k.startswith('jump')]
    lines.append(f'Baseline: {len(jumps)} friction jump(s) segmented.')
    if rep['effects']:
        lines += ['', "Effects (the vocabulary's order; evidence.added_at_step: the order "
                  'added):', '']
        for e in rep['effects']:
            ev = e['evidence']
            shown = {k: v for k, v in e['parameters'].items()
                     if k != 'weights' and not isinstance(v, list)}
            lines.append(f'- `{e["name"]}`: {shown}; LR {ev["lr"]:.1f} on {ev["dof"]} dof '
                         f'(p = {ev["p_value"]:.2g}, level {ev["level"]:.2g}); validation '
                         f'RMSE {ev["rmse_validation"]:.4g}')
    else:
        lines += ['', 'No effect added: the baseline model explains the data.']
    ident = identifiability(selection)
    for name, reason in ident['not_identifiable'].items():
        lines += ['', f'`{name}` {reason}.']
    if ident['not_identifiable']:
        lines += ['', f'Identifiable from this run: {", ".join(ident["testable"])}.']
    for e in rep['effects']:
        if e['name'] == FALLBACK:
            size = e['parameters']['size_rms_nm']
            lines += ['', f'{UNEXPLAINED.capitalize()}: {size:.3g} N m rms '
                      f'({size / rep["noise_floor"]:.2g} x the noise floor), held by '
                      f'`{FALLBACK}` after no named effect was significant any more '
                      '(not physics: a shape to look at).']
    note = reversals(selection)['note']
    if note:
        lines += ['', f'Held out: {note}.']
    lines += ['', f'Stopped: {selection.stop_reason}.',
              f'Residual tests failing before: {selection.diagnostics_before["failing"]}; '
              f'after: {selection.diagnostics_after["failing"]}.', '',
              '![before](residuals_before.png) ![after](residuals_after.png)', '']
    return '\n'.join(lines)
