"""The identification report: report.json (DESIGN.md contract), markdown and plots.

report.json has exactly the keys of DESIGN.md: ``baseline`` (model and parameters),
``noise_floor`` (N m), ``rmse_before`` / ``rmse_after`` (each ``in_sample`` and
``held_out``, N m) and ``effects`` (in the order added: ``name``, ``parameters``,
``evidence``). Everything else (the steps of the selection with every candidate's
evidence, the residual tests before and after, the jumps) goes to selection.json.
This module builds the dictionaries and draws the figures; the CLI writes the files.
"""

from __future__ import annotations

import math
import pathlib
from typing import Any

import numpy as np

from rwa_monitor.core.identify.model import _plain, column_names


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def effect_parameters(eff, coef: np.ndarray) -> dict:
    """Return an effect's parameters: its nonlinear ones and its named weights."""
    params = dict(_plain(eff.params))
    weights = coef[eff.columns]
    if eff.kind == 'stribeck':
        params['static_excess_nm'] = float(weights[0])
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
    else:
        params['values_nm'] = [float(w) for w in weights]
    params['weights'] = dict(zip(column_names(eff.name, eff.kind, eff.params),
                                 [float(w) for w in weights]))
    return params


def report(selection) -> dict:
    """Return report.json's content (DESIGN.md contract)."""
    base, final = selection.baseline_fit, selection.final_fit
    nb = len(selection.baseline_names)
    parameters = {n: float(c) for n, c in zip(selection.baseline_names, base.coef[:nb])}
    for i, start in enumerate(selection.segments.starts[1:], start=1):
        parameters[f'jump{i}_time_s'] = float(selection.data.time[start])
    effects = []
    for eff in selection.effects:
        effects.append({'name': eff.name,
                        'parameters': effect_parameters(eff, final.coef),
                        'evidence': {k: _finite(v) for k, v in _plain(eff.evidence).items()}})
    return {'baseline': {'model': 'coulomb+viscous', 'parameters': parameters},
            'noise_floor': float(selection.data.noise_floor),
            'rmse_before': {'in_sample': base.rmse_train, 'held_out': base.rmse_held_out},
            'rmse_after': {'in_sample': final.rmse_train, 'held_out': final.rmse_held_out},
            'effects': effects}


def _tests(diag: dict) -> dict:
    return {k: {kk: _finite(vv) for kk, vv in _plain(v).items()}
            for k, v in diag['tests'].items()}


def details(selection) -> dict:
    """Return selection.json's content: steps, tests before/after, jumps, data counts."""
    data = selection.data
    return _plain({'wheel': data.wheel, 'samples': len(data), 'derived_friction': data.derived,
                   'counts': data.counts, 'notes': data.notes,
                   'jumps': selection.segments.evidence,
                   'first_pass_jumps': selection.first_pass_jumps,
                   'stop_reason': selection.stop_reason,
                   'tests_before': _tests(selection.diagnostics_before),
                   'failing_before': selection.diagnostics_before['failing'],
                   'tests_after': _tests(selection.diagnostics_after),
                   'failing_after': selection.diagnostics_after['failing'],
                   'steps': selection.steps})


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
        lines += ['', 'Effects, in the order added:', '']
        for e in rep['effects']:
            ev = e['evidence']
            shown = {k: v for k, v in e['parameters'].items()
                     if k != 'weights' and not isinstance(v, list)}
            lines.append(f'- `{e["name"]}`: {shown}; LR {ev["lr"]:.1f} on {ev["dof"]} dof '
                         f'(p = {ev["p_value"]:.2g}, level {ev["level"]:.2g}); held-out '
                         f'RMSE {ev["rmse_held_out"]:.4g}')
    else:
        lines += ['', 'No effect added: the baseline model explains the data.']
    lines += ['', f'Stopped: {selection.stop_reason}.',
              f'Residual tests failing before: {selection.diagnostics_before["failing"]}; '
              f'after: {selection.diagnostics_after["failing"]}.', '',
              '![before](residuals_before.png) ![after](residuals_after.png)', '']
    return '\n'.join(lines)


def plot_residuals(selection, path: pathlib.Path, which: str) -> None:
    """Draw the residual diagnostics (``which`` = 'before' or 'after') to a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    data = selection.data
    diag = selection.diagnostics_before if which == 'before' else selection.diagnostics_after
    resid = selection.residual_before() if which == 'before' else selection.residual_after()
    aux_keys = [k for k in diag['binned'] if k.startswith('aux:')]
    panels = ['speed', 'time', 'direction', 'acf', 'std', 'spectrum'] + aux_keys
    cols = 3
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(13, 3.3 * rows), squeeze=False)
    for ax, name in zip(axes.flat, panels):
        if name in diag['binned']:
            b = diag['binned'][name]
            x = data.speed if name == 'speed' else data.time if name == 'time' else \
                data.aux[name[4:]]
            step = max(1, len(x) // 4000)
            ax.plot(x[::step], resid[::step], '.', ms=1, color='0.75')
            ax.errorbar(b['centre'], b['mean'], yerr=b['band'], fmt='o-', ms=3, color='C3',
                        label='bin mean, 95 %')
            ax.axhline(0, color='k', lw=0.5)
            span = max(4 * data.noise_floor, 1.5 * np.max(np.abs(b['mean']) + b['band']))
            ax.set_ylim(-span, span)
            ax.set_xlabel({'speed': 'speed (rad/s)', 'time': 'time (s)'}.get(name, name[4:]))
            ax.set_ylabel('residual (N m)')
            test = diag['tests'][name]
            ax.set_title(f'vs {name}: p = {test["p_value"]:.2g}', fontsize=9)
        elif name == 'direction':
            pos, neg = resid[data.speed > 0], resid[data.speed < 0]
            for part, label in ((pos, 'w > 0'), (neg, 'w < 0')):
                if len(part) > 1:
                    ax.hist(part, bins=40, label=label, density=True, alpha=0.6)
            ax.set_xlabel('residual (N m)')
            ax.legend(fontsize=7)
            test = diag['tests'].get('direction')
            extra = f': p = {test["p_value"]:.2g}' if test else ''
            ax.set_title('by spin direction' + extra, fontsize=9)
        elif name == 'acf':
            acf = diag['acf']
            n = len(resid[::diag['acf_stride']])
            ax.bar(np.arange(1, len(acf) + 1), acf, color='C0')
            ax.axhline(1.96 / np.sqrt(n), color='C3', ls='--')
            ax.axhline(-1.96 / np.sqrt(n), color='C3', ls='--')
            ax.set_xlabel(f'lag (x{diag["acf_stride"]} samples)')
            ax.set_title(f'autocorrelation: Ljung-Box p = '
                         f'{diag["tests"]["whiteness"]["p_value"]:.2g}', fontsize=9)
        elif name == 'std':
            v = diag['binned_std']
            ax.plot(v['centre'], v['std'], 'o-')
            ax.axhline(data.noise_floor, color='k', ls='--', label='noise floor')
            ax.set_xlabel('speed (rad/s)')
            ax.set_ylabel('residual std (N m)')
            ax.legend(fontsize=7)
            ax.set_title('variance vs speed', fontsize=9)
        elif name == 'spectrum':
            s = diag['spectrum']
            ax.semilogy(s['frequency_hz'][1:], s['power'][1:] + 1e-300, lw=0.6)
            ax.set_xlabel('frequency (Hz)')
            ax.set_title(f'spectrum: Fisher g p = '
                         f'{diag["tests"]["spectrum"]["p_value"]:.2g}', fontsize=9)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis('off')
    model = 'baseline' if which == 'before' else 'refined'
    rmse = np.sqrt(np.mean(resid ** 2))
    fig.suptitle(f'{data.wheel}: residuals {which} ({model} model), RMSE {rmse:.3g} N m')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
