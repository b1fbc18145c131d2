"""Identification outputs: report.json, selection.json, report.md, plots, the model YAML.

The core (core/identify/) returns dictionaries and arrays; this module draws the residual
figures and writes every file through telemetry/atomic.py. Used by ``rwa-monitor
identify`` and the identify benchmark.
"""

from __future__ import annotations

import json
import math
import pathlib

import numpy as np

from rwa_monitor.core.identify import report as rep
from rwa_monitor.core.identify.consistency import sibling_name
from rwa_monitor.core.identify.effects import canonical_order
from rwa_monitor.core.identify.model import snippet
from rwa_monitor.core.identify.select import Selection
from rwa_monitor.telemetry.atomic import atomic_write, write_text_atomic

# What ``rwa-monitor identify -o DIR`` writes (one wheel, or one sub-folder per wheel):
# an existing DIR holding anything else is not replaced (telemetry/atomic.py).
FILES = ('report.json', 'selection.json', 'report.md', 'friction_model.yaml',
         'residuals_before.png', 'residuals_after.png')
OUTPUT_FILES = FILES + ('wheels.json', 'wheels.md', '*/') + tuple(f'*/{f}' for f in FILES)


def write_outputs(selection: Selection, out: pathlib.Path, title: str = '',
                  extra: dict | None = None) -> dict:
    """Write report.json, selection.json, report.md, the plots and the model snippet.

    ``extra`` holds keys added to report.json (``speed_rmse`` when friction was derived
    from speed with a known inertia) and to selection.json (their details).
    """
    import yaml
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = rep.report(selection)
    details = rep.details(selection)
    if extra:
        result.update(extra.get('report', {}))
        details.update(extra.get('details', {}))
    write_text_atomic(out / 'report.json', json.dumps(result, indent=2) + '\n')
    write_text_atomic(out / 'selection.json', json.dumps(details, indent=1) + '\n')
    write_text_atomic(out / 'report.md', rep.markdown(selection, result, title or 'telemetry'))
    write_text_atomic(out / 'friction_model.yaml',
                      '# Refined friction model from rwa-monitor identify (docs/identify.md).\n'
                      + yaml.safe_dump(snippet(selection), sort_keys=False))
    plot_residuals(selection, out / 'residuals_before.png', 'before')
    plot_residuals(selection, out / 'residuals_after.png', 'after')
    return result


def plot_residuals(selection, path: pathlib.Path, which: str) -> None:
    """Draw the residual diagnostics (``which`` = 'before' or 'after') to a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    data = selection.data
    diag = selection.diagnostics_before if which == 'before' else selection.diagnostics_after
    resid = selection.residual_before() if which == 'before' else selection.residual_after()
    aux_keys = [k for k in diag['binned'] if k.startswith('aux:')]
    history = [k for k in ('since_zero', 'acceleration', 'position', 'since_reversal')
               if k in diag['binned']]
    panels = ['speed', 'approach', 'time', 'direction', 'acf', 'std', 'spectrum'] + \
        history + aux_keys
    cols = 3
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(13, 3.3 * rows), squeeze=False)
    for ax, name in zip(axes.flat, panels):
        if name in diag['binned']:
            b = diag['binned'][name]
            x = _axis_values(data, name)
            step = max(1, len(x) // 4000)
            if name == 'speed' and data.past is not None:
                for mask, colour, label in ((data.past.receding, 'C0', 'abs(w) rising'),
                                            (data.past.approaching, 'C1', 'abs(w) falling')):
                    ax.plot(x[mask][::step], resid[mask][::step], '.', ms=1, color=colour,
                            alpha=0.5, label=label)
            else:
                ax.plot(x[::step], resid[::step], '.', ms=1, color='0.75')
            ax.errorbar(b['centre'], b['mean'], yerr=b['band'], fmt='o-', ms=3, color='C3',
                        label='bin mean, 95 %')
            ax.axhline(0, color='k', lw=0.5)
            span = max(4 * data.noise_floor, 1.5 * np.max(np.abs(b['mean']) + b['band']))
            ax.set_ylim(-span, span)
            ax.set_xlabel(AXIS_LABELS.get(name, name[4:]))
            if name == 'speed':
                ax.legend(fontsize=7, markerscale=6)
            ax.set_ylabel('residual (N m)')
            test = diag['tests'][name]
            ax.set_title(f'vs {name}: p = {test["p_value"]:.2g}', fontsize=9)
        elif name == 'approach':
            a = diag.get('approach')
            if a is not None and len(a['centre']):
                ax.errorbar(a['centre'], a['mean'], yerr=a['band'], fmt='o-', ms=3,
                            color='C3')
                ax.axhline(0, color='k', lw=0.5)
                ax.set_xscale('log')
                ax.set_title(f'rising minus falling: p = {a["p_value"]:.2g}', fontsize=9)
            else:
                ax.set_title('rising minus falling: not testable', fontsize=9)
            ax.set_xlabel('abs(speed) (rad/s)')
            ax.set_ylabel('residual difference (N m)')
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
    with atomic_write(path, 'wb') as handle:
        fig.savefig(handle, dpi=90, format='png')
    plt.close(fig)


AXIS_LABELS = {'speed': 'speed (rad/s)', 'time': 'time (s)',
               'since_zero': 'time since the last zero passage (s)',
               'acceleration': 'dw/dt (rad/s^2)', 'position': 'position = integral of speed (rad)',
               'since_reversal': 'distance since the last reversal (rad)'}


def _axis_values(data, name: str) -> np.ndarray:
    if name == 'speed':
        return data.speed
    if name == 'time':
        return data.time
    past = data.past
    history = {'since_zero': 'since_zero_s', 'acceleration': 'rate',
               'position': 'position', 'since_reversal': 'distance_since_reversal'}
    if name in history:
        values = getattr(past, history[name])
        return np.where(np.isfinite(values), values, np.nan)
    return data.aux[name[4:]]


def side_by_side(results: dict[str, dict], consistency: dict | None = None) -> dict:
    """Return every wheel's effects and fit side by side, with the consistency check.

    ``consistency``: the joint selection's (pipelines.identify.identify_wheels); without
    it the wheels' effect sets are compared with the majority's.
    """
    from rwa_monitor.core.identify.consistency import compare_effects
    names = {w: [e['name'] for e in r['effects']] for w, r in results.items()}
    wheels = {}
    for w, r in results.items():
        wheels[w] = {'effects': {e['name']: {k: v for k, v in e['parameters'].items()
                                             if k != 'weights' and not isinstance(v, list)}
                                 for e in r['effects']},
                     'noise_floor': r['noise_floor'],
                     'held_out_before': r['rmse_before']['held_out'],
                     'held_out_after': r['rmse_after']['held_out'],
                     'held_out_after_over_floor': r['rmse_after']['held_out']
                     / r['noise_floor']}
    return {'wheels': wheels,
            'consistency': compare_effects(names) if consistency is None else consistency}


def wheels_markdown(summary: dict) -> str:
    """Return the side-by-side table of every wheel's effects (markdown)."""
    wheels = summary['wheels']
    effects = canonical_order({sibling_name(e, w) for w, v in wheels.items()
                               for e in v['effects']})
    lines = ['| wheel | held-out / floor | ' + ' | '.join(effects) + ' |',
             '|---|---|' + '---|' * len(effects)]
    for w, v in wheels.items():
        cells = []
        own = {sibling_name(e, w): p for e, p in v['effects'].items()}
        for e in effects:
            p = own.get(e)
            cells.append('-' if p is None else ', '.join(
                f'{k}={x:.3g}' if isinstance(x, float) else f'{k}={x}' for k, x in p.items()))
        lines.append(f'| {w} | {v["held_out_after_over_floor"]:.3f} | ' + ' | '.join(cells)
                     + ' |')
    c = summary['consistency']
    lines.append('')
    if c.get('rule') == 'joint':
        lines.append('Wheels declared identical: effects selected on their pooled evidence; '
                     'a wheel is flagged when its own data contradict its siblings '
                     '(docs/identify.md, "Identical wheels").')
        for w, names in c.get('not_testable', {}).items():
            lines.append(f'{w}: its data cannot show {", ".join(names)}.')
    if c['consistent']:
        lines.append(f'Every wheel has the same effects: {", ".join(c["reference"]) or "none"}.')
    for w, d in c['flagged'].items():
        lines.append(f"FLAG {w}: effects differ from its siblings' (reference "
                     f'{", ".join(c["reference"]) or "none"}): missing '
                     f'{", ".join(d["missing"]) or "-"}, extra {", ".join(d["extra"]) or "-"}.')
    for reason in summary.get('not_examined', {}).values():
        lines.append(f'NOT EXAMINED {reason}.')
    return '\n'.join(lines) + '\n'
