"""Identification on a robot arm's joints: the measured robot-joint files (issue 35).

Each shared file of ../shared/data/measured/robot-joint/ (read in place; source
github.com/longshike/NNFM-A-Novel-Neural-Network-Modeling-Approach-for-Robot-Flexible-Joints-Friction,
commit a343d3a, see its SOURCE.md) is identified as ``rwa-monitor identify FILE`` does
(pipelines/identify.identify_wheel, default options). Reported on the held-out test rows
(fitting.held_out_mask: every third of 60 interleaved blocks, never used for a fit or a
decision): the baseline, the model after each effect in the order added (the final
nonlinear parameters, weights refitted at each stage on the training rows), and the four
published models' predictions on the same rows (CV, LuGre, PINN, NNFM). The residual
plots before and after go to docs/ (identify_joint_<file>_before.png / _after.png);
only summary numbers and those plots leave the data folder.

``python -m bench identify_joint`` (``--quick``: the first file only, a smoke run).
"""

from __future__ import annotations

import json
import pathlib
import time
from typing import Any

import numpy as np

from bench.report import REPO, table, update_section, write_json
from rwa_monitor.core.identify.fitting import Design
from rwa_monitor.core.identify.report import report
from rwa_monitor.pipelines.identify import identify_wheel
from rwa_monitor.pipelines.identify_report import plot_residuals
from rwa_monitor.telemetry import read_telemetry

# file stem, joint, goal (N m, held out): min(PINN, 1.2 x NNFM) of issue 35
FILES = (('franka_case3_middle_j2', 'j2', 0.120), ('franka_case4_slow_j7', 'j7', 0.042),
         ('franka_case4_middle_j7', 'j7', 0.037))
PUBLISHED = ('CV', 'LuGre', 'PINN', 'NNFM')
DOCS = REPO / 'docs'
MEANING = {
    'asymmetric_coulomb': 'torque offset / direction-dependent dry level',
    'frictional_lag': 'dry friction follows the motion with a first-order lag',
    'stick': 'static friction holds the drive torque in a stop, up to breakaway',
    'presliding_state': 'elastic pre-sliding over a displacement after a reversal',
    'presliding': 'dry term regularised across a speed band at zero',
    'gravity_load': 'torque periodic in the joint angle (a load not cancelled)',
    'load_dry': 'dry friction varying with the joint angle (load on the gears)',
    'gear_ripple': 'friction/torque periodic in position (transmission)',
    'inertia': 'torque proportional to dw/dt (inertia behind the sensor)',
    'stribeck': 'friction rising towards rest (Stribeck)',
    'stribeck_hysteresis': 'Stribeck excess only on leaving zero speed',
    'drag': 'friction growing faster than linearly with speed',
    'drift': 'slow change over the record',
    'periodic': 'a torque periodic in time',
    'smooth_speed': 'catch-all: unexplained speed dependence',
}


def folder() -> pathlib.Path:
    """Return the robot-joint folder: ../shared beside the repository or above it."""
    for parent in pathlib.Path(__file__).resolve().parents:
        candidate = parent / 'shared' / 'data' / 'measured' / 'robot-joint'
        if candidate.exists():
            return candidate
    return REPO.parent / 'shared' / 'data' / 'measured' / 'robot-joint'


def stages(selection) -> list[dict[str, Any]]:
    """Return the RMSE (train, validation, test) of the baseline and after each effect.

    Effects in the order the selection added them, with their final nonlinear
    parameters; the weights are refitted on the training rows at each stage.
    """
    design = selection.design
    nb = len(selection.baseline_names)
    current = Design(design.y, design.X[:, :nb], design.split)
    rows = []
    added = [(e.name, e.columns) for e in selection.effects]
    for name, columns in [('baseline', None)] + added:
        if columns is not None:
            current.add(design.X[:, columns])
        fit = current.fit()
        rows.append({'model': name, 'train': fit.rmse_train,
                     'validation': fit.rmse_validation, 'test': fit.rmse_test})
    return rows


def published(path: pathlib.Path, rows: np.ndarray, friction: np.ndarray,
              test: np.ndarray) -> dict[str, float]:
    """Return each published model's RMSE on the held-out test rows of ``rows``."""
    fits = np.genfromtxt(path, delimiter=',', names=True)
    out = {}
    for model in PUBLISHED:
        predicted = np.asarray(fits[f'{model}_friction'], dtype=float)[rows]
        out[model] = float(np.sqrt(np.mean((predicted[test] - friction[test]) ** 2)))
    return out


def one_file(stem: str, joint: str, goal: float, where: pathlib.Path) -> dict[str, Any]:
    """Identify one file as the command does; return its numbers and write its plots."""
    tele = read_telemetry(where / f'{stem}.csv')
    start, cpu = time.perf_counter(), time.process_time()
    selection, _ = identify_wheel(tele, joint)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    data = selection.data
    test = selection.design.split.test
    rep = report(selection)
    for which in ('before', 'after'):
        plot_residuals(selection, DOCS / f'identify_joint_{stem}_{which}.png', which)
    steps = stages(selection)
    final = steps[-1]['test']
    return {'file': stem, 'joint': joint, 'samples': len(data), 'goal_nm': goal,
            'seconds': seconds, 'cpu_seconds': cpu_seconds,
            'noise_floor': data.noise_floor, 'jumps': len(selection.segments.starts) - 1,
            'stages': steps, 'final_test': final, 'met': bool(final <= goal),
            'published_test': published(where / f'{stem}_published_fits.csv', data.rows,
                                        data.friction, test),
            'effects': [{'name': e['name'], 'parameters': e['parameters']}
                        for e in rep['effects']],
            'stop_reason': selection.stop_reason,
            'failing_after': list(selection.diagnostics_after['failing'])}


def run(out_dir: pathlib.Path, quick: bool = False) -> dict[str, Any]:
    """Identify every shared robot-joint file; write JSON, plots and the docs section."""
    where = folder()
    if not where.exists():
        results: dict[str, Any] = {'skipped': f'{where} absent'}
    else:
        whole = json.loads((where / 'published_rmse.json').read_text())
        files = FILES[:1] if quick else FILES
        results = {'quick': quick, 'files': [one_file(*f, where) for f in files],
                   'published_whole_file': {f'{s}.csv': whole.get(f'{s}.csv', {})
                                            for s, _, _ in files}}
    write_json(out_dir, 'identify_joint', results)
    update_section('identify_joint', markdown(results))
    return results


def _fmt(value: float) -> str:
    return f'{value:.4f}'


def markdown(res: dict[str, Any]) -> str:
    """Return the docs/results.md section of this bench."""
    lines = ["## identify on a robot arm's joints (issue 35)", '',
             '`python -m bench identify_joint`'
             + (' --quick (smoke run, not a result)' if res.get('quick') else '') + '. '
             'Data: ../shared/data/measured/robot-joint (github.com/longshike/NNFM-A-Novel-'
             'Neural-Network-Modeling-Approach-for-Robot-Flexible-Joints-Friction, commit '
             'a343d3a; read in place). RMSE in N m on the held-out test rows (every third '
             'of 60 interleaved time blocks, never used to fit or to decide; '
             'docs/identify.md section 5); the published models on the same rows. '
             'Method: docs/identify.md section 4b.', '']
    if 'skipped' in res:
        return '\n'.join(lines + [f'Not run: {res["skipped"]}.'])
    summary = []
    for f in res['files']:
        p = f['published_test']
        summary.append([f['file'], f['stages'][0]['test'], f['final_test'], f['goal_nm'],
                        'met' if f['met'] else 'NOT met', p['CV'], p['LuGre'], p['PINN'],
                        p['NNFM'], f['final_test'] / p['NNFM'], f['noise_floor'], f['jumps'],
                        f'{f["seconds"]:.0f} / {f["cpu_seconds"]:.0f}'])
    lines += [table(['file', 'ours before', 'ours after', 'goal', '', 'CV', 'LuGre', 'PINN',
                     'NNFM', 'after / NNFM', 'noise floor', 'jumps',
                     'time wall / CPU (s)'], summary), '']
    for f in res['files']:
        p = f['published_test']
        rows = [[s['model'], MEANING.get(s['model'].split(':')[0], ''), _fmt(s['train']),
                 _fmt(s['validation']), _fmt(s['test'])] for s in f['stages']]
        rows += [[f'published {m}', "(the paper's fit, same rows)", '', '', _fmt(p[m])]
                 for m in PUBLISHED]
        lines += [f'### {f["file"]} ({f["samples"]} samples)', '',
                  table(['model (effects added in this order)', 'physics',
                         'RMSE train', 'validation', 'held out'], rows), '',
                  'Effects and parameters: ' + '; '.join(
                      f'`{e["name"]}` ' + ', '.join(
                          f'{k} {v:.4g}' if isinstance(v, float) else f'{k} {v}'
                          for k, v in e['parameters'].items()
                          if k not in ('weights', 'sin_mean', 'cos_mean', 'half_width'))
                      for e in f['effects']) + '.', '',
                  f'Stopped: {f["stop_reason"]}. Residual tests still failing after: '
                  f'{", ".join(f["failing_after"]) or "none"}.', '',
                  f'![before](identify_joint_{f["file"]}_before.png) '
                  f'![after](identify_joint_{f["file"]}_after.png)', '']
    return '\n'.join(lines)
