"""Plots and the docs/results.md section of the LLR benchmark."""

from __future__ import annotations

import math
import pathlib
from typing import Any

from bench.report import table

PAPER_SPEED = 88_000 / 5.6   # llr-realtime paper, III-D: 88,000 points in 5.6 s


def plots(out_dir: pathlib.Path, r: dict[str, Any]) -> None:
    """Write llr_fig3.png, llr_fig4.png, llr_fig5.png and llr_memory.png."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    out_dir.mkdir(parents=True, exist_ok=True)

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    for ax, size in zip(axes, ('0.3', '0.5')):
        bins = list(range(-300, 301, 20))
        ax.hist(r['fig3'][size]['llr']['errors'], bins=bins, alpha=0.6, label='online LLR')
        ax.hist(r['fig3'][size]['peer']['errors'], bins=bins, alpha=0.6,
                label='offline Binseg')
        ax.set_title(f'dry +{size} at k = 1500 (miss '
                     f'{100 * r["fig3"][size]["llr"]["miss_rate"]:.1f} %)')
        ax.set_xlabel('estimated change step - 1500')
    axes[0].set_ylabel('runs')
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out_dir / 'llr_fig3.png', dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    for rate, curve in r['fig4']['curves'].items():
        line, = ax.plot(curve['sizes'], curve['simulation'], '-o', label=f'r = {rate} sim')
        ax.plot(curve['sizes'], curve['theory'], '--', color=line.get_color(),
                label=f'r = {rate} Lemma 1')
    ax.set_xlabel('dry friction change (noise units)')
    ax.set_ylabel('detection probability')
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / 'llr_fig4.png', dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    cells = r['fig5']['cells']
    for window in sorted({c['window'] for c in cells}):
        row = [c for c in cells if c['window'] == window]
        seen = [c for c in row if c['alarms']]
        line, = ax.plot([c['rate'] for c in seen], [c['arl'] for c in seen], '-o',
                        label=f'w = {window}: ARL (cells with alarms)')
        ax.plot([c['rate'] for c in row], [c['arl_lower_95'] for c in row], ':^',
                color=line.get_color(), label=f'w = {window}: 95 % lower bound')
    rates = sorted({c['rate'] for c in cells})
    ax.plot(rates, [1 / x for x in rates], 'k--', label='1/r')
    ax.set_xscale('log')
    ax.set_yscale('log')
    ax.invert_xaxis()
    ax.set_xlabel('false positive rate r')
    ax.set_ylabel('run length to a false alarm (samples)')
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / 'llr_fig5.png', dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 3.5))
    mem = r['memory']['rows']
    ax.plot([m['n'] for m in mem], [m['peak_rss_kb'] / 1024 for m in mem], '-o',
            label='peak RSS')
    ax.plot([m['n'] for m in mem], [m['rss_after_first_chunk_kb'] / 1024 for m in mem],
            '-s', label='RSS after the first 1e5 samples')
    ax.set_xscale('log')
    ax.set_ylim(bottom=0)
    ax.set_xlabel('samples streamed')
    ax.set_ylabel('MB')
    ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir / 'llr_memory.png', dpi=110)
    plt.close(fig)


def _pct(x: float) -> str:
    return '-' if x is None or (isinstance(x, float) and math.isnan(x)) else f'{100 * x:.1f} %'


def _num(x: float, fmt: str) -> str:
    return format(float(format(x, fmt)) + 0.0, fmt)  # no '-0'


def _q(d: dict[str, float], fmt: str = '.0f') -> str:
    if d['median'] is None or math.isnan(d['median']):
        return '-'
    return f'{_num(d["median"], fmt)} [{_num(d["q25"], fmt)}, {_num(d["q75"], fmt)}]'


def markdown(r: dict[str, Any]) -> str:
    """Return the llr section of docs/results.md."""
    s = r['settings']
    out = ['## LLR friction detector (llr-realtime paper)', '',
           f'`python -m bench llr` on code {r["code"]}, {r["bench_seconds"]:.0f} s'
           + (f' (throughput and memory re-measured alone on code '
              f'{r["throughput_memory_code"]})' if r.get('throughput_memory_code') else '')
           + '; '
           'scaled units (noise std 1, '
           'given to both detectors), change at k = 1500 of 3000-sample runs; a change is '
           'detected by a declaration whose estimated step is within +-500 samples. '
           'Offline peer: binary segmentation with a model (1) least-squares cost, '
           'penalty 3 ln(n) (BIC-like), min segment 50, step grid 5 '
           '(`bench/llr_peer.py`). '
           'Plots: `bench/results/llr_fig3.png`, `llr_fig4.png`, `llr_fig5.png`, '
           '`llr_memory.png`.', '']
    out += ['### Fig. 3: localisation (w_k = 20 - 10cos(pi k/1200), r = 1e-5, w = 500, '
            f'k_verif = 250, {s["fig3_runs"]} runs)', '']
    rows = []
    for size in ('0.3', '0.5'):
        llr, peer = r['fig3'][size]['llr'], r['fig3'][size]['peer']
        rows.append([f'+{size}', _pct(llr['miss_rate']), _pct(llr['no_declaration_rate']),
                     _q(llr['error']), _q(llr['delay']), f'{llr["false_per_run"]:.2f}',
                     _pct(1 - peer['detection_rate']), _q(peer['error']),
                     f'{peer["false_per_run"]:.2f}'])
    out.append(table(['dry step', 'LLR miss', 'LLR no declaration (paper: 4.5 % for one '
                      'of them)', 'LLR loc. error median [IQR]', 'LLR delay median [IQR]',
                      'LLR false/run', 'peer miss', 'peer loc. error median [IQR]',
                      'peer false/run'], rows))
    rows = []
    for size in ('0.3', '0.5'):
        est = r['fig3'][size]['llr_noise_estimated']
        rows.append([f'+{size}', _pct(est['miss_rate']), _q(est['error']), _q(est['delay']),
                     f'{est["false_per_run"]:.2f}'])
    out += ['', 'Same runs, LLR with the noise variance estimated from the reference '
            'segment (`noise_std` unset, as on real telemetry):', '',
            table(['dry step', 'miss', 'loc. error median [IQR]', 'delay median [IQR]',
                   'false/run'], rows)]
    out += ['', '### Fig. 4: detection probability vs dry change (w_k = 20 + 5cos(pi k/1000), '
            f'w = 500, {r["fig4"]["runs_per_point"]} runs per point)', '']
    curves = r['fig4']['curves']
    sizes = next(iter(curves.values()))['sizes']
    rows = []
    for i, size in enumerate(sizes):
        row = [size]
        for curve in curves.values():
            row += [_pct(curve['simulation'][i]), _pct(curve['theory'][i])]
        rows.append(row)
    header = ['dry change']
    for rate in curves:
        header += [f'sim r={rate}', f'Lemma 1 r={rate}']
    out.append(table(header, rows))
    out += ['', 'Paper: simulated detection above the Lemma-1 curve, increasing with the '
            'change and with r (graph only, no numbers). Lemma 1 is evaluated at the true '
            'change step; the simulation counts any declaration within +-500 samples, so '
            'for tiny changes it includes false alarms in that span (~1000 r).', '',
            f'### Fig. 5: run length to a false alarm (w_k = 20 + 5cos(k/5000), no anomaly, '
            f'up to {r["fig5"]["max_runs_per_cell"]} runs x {r["fig5"]["samples_per_run"]} '
            'samples per cell, about 100/r samples)', '']
    rows = [[c['window'], f'{c["rate"]:g}', c['alarms'], c['samples'],
             '> samples' if c['alarms'] == 0 else f'{c["arl"]:.3g}',
             f'{c["arl_lower_95"]:.3g}', f'{c["one_over_r"]:.0f}',
             'yes' if c['arl_lower_95'] > c['one_over_r'] else
             ('yes (point)' if c['arl'] > c['one_over_r'] else 'no')]
            for c in r['fig5']['cells']]
    out.append(table(['w', 'r', 'alarms', 'samples', 'ARL', 'ARL 95 % lower bound',
                      '1/r (paper: ARL above it)', 'ARL > 1/r'], rows))
    out += ['', 'ARL = samples / alarms (restarts included); the lower bound is the '
            'one-sided 95 % Poisson bound. Sample budgets keep the section to a few minutes; '
            'a cell with no alarm only bounds the ARL from below.', '',
            f'### Categorisation (profile fig3, r = 1e-5, w = 500, {s["cat_runs"]} runs; '
            'viscous step 0.025 = a 0.5 torque step at 20 rad/s; change at 1500 of 8000 '
            'samples: the kind is re-checked at 2, 4, 8 L0 ~ 1500, 3000, 6000 samples after '
            'it; "once confirmed" = the last revision is confirmed and right; docs/llr.md '
            '"Categorisation")', '']
    rows = []
    for name, c in r['categorisation'].items():
        peer = c.get('peer')
        rows.append([name, f'{c["delta_dry"]:g} / {c["delta_viscous"]:g}',
                     _pct(c['llr']['detection_rate']), _pct(c['first_kind_accuracy']),
                     _pct(c['final_kind_accuracy']),
                     ', '.join(f'{k} {v}' for k, v in c['kinds'].items()),
                     _q(c['llr']['error']),
                     '-' if peer is None else _pct(peer['detection_rate']),
                     '-' if peer is None else _q(peer['error'])])
    out.append(table(['change', 'dry / viscous step', 'LLR detected', 'kind at declaration',
                      'kind once confirmed', 'final kinds', 'LLR loc. error',
                      'peer detected', 'peer loc. error'], rows))
    fa = r['peer_false_alarms']
    llr_cell = next((c for c in r['fig5']['cells']
                     if c['window'] == 500 and c['rate'] == 1e-5), None)
    out += ['', '### False alarms and speed of the peer', '',
            table(['detector', 'false alarms per 100k samples (fig5 profile, no anomaly)',
                   'samples/s'],
                  [['online LLR (r = 1e-5, w = 500)',
                    '-' if llr_cell is None else
                    f'{1e5 * llr_cell["alarms"] / llr_cell["samples"]:.2f}',
                    f'{min(x["batch_per_s"] for x in r["throughput"]["rows"]):.0f} (batch)'],
                   ['offline Binseg', f'{fa["per_100k"]:.2f} ({fa["samples"]} samples)',
                    f'{fa["samples_per_s"]:.0f}']]), '']
    re_ = r['realistic']
    out += ['### Realistic scenario (paper III-D analogue: SI units, realistic profile, '
            f'{re_["runs"]} seeded 3-hour 4-wheel files at 10 Hz, w = 400, r = 1e-4, noise '
            'estimated; `rwa-monitor detect` pipeline)', '',
            'Changes: ' + ', '.join(f'`{a}`' for a in re_['anomalies']) + '; rw1 nominal. '
            'Detected = first declaration on the wheel within one window (40 s).', '']
    rows = [[kind, f'{re_[kind]["detected"]}/{re_[kind]["changes"]}',
             _q(re_[kind]['error_s'], '.1f'), _q(re_[kind]['delay_s'], '.1f'),
             _pct(re_[kind]['kind_accuracy'])] for kind in ('dry', 'viscous', 'both')]
    out.append(table(['change', 'detected', 'loc. error s median [IQR]',
                      'delay s median [IQR]', 'kind once confirmed'], rows))
    out += ['', f'False alarms: {re_["false"]} in {re_["wheel_hours"]:.0f} wheel-hours '
            f'({re_["false_per_wheel_hour"]:.3f} per wheel-hour). The paper shows this '
            'scenario as a plot only ("detects most anomalies").', '']
    out += ['### Throughput (realistic SI profile, w = 400, r = 1e-4, noise estimated; '
            'one wheel; samples per CPU second of the process, so that a shared, loaded '
            'machine does not count other work)', '']
    rows = [[row['n'], f'{row["stream_per_s"]:.0f}', f'{row["batch_per_s"]:.0f}',
             f'{row["stream_s"]:.2f}', f'{row["batch_s"]:.3f}',
             'yes' if row['same_events'] else '**no**',
             f'{PAPER_SPEED:.0f} (88,000 in 5.6 s)' if row['n'] == 88_000 else '']
            for row in r['throughput']['rows']]
    out.append(table(['samples', 'streaming samples/s', 'batch samples/s', 'streaming s',
                      'batch s', 'batch events == streaming events', 'paper'], rows))
    out += ['', '### Memory of one streaming detector (fresh process, RSS)', '']
    rows = [[f'{m["n"]:.0e}', m['rss_after_first_chunk_kb'], m['peak_rss_kb'],
             m['growth_kb'], f'{m["seconds"]:.0f}'] for m in r['memory']['rows']]
    out.append(table(['samples', 'RSS after 1e5 (kB)', 'peak RSS VmHWM (kB)',
                      'final RSS - RSS after 1e5 (kB)', 'seconds'], rows))
    if r['memory'].get('skipped'):
        out += ['', 'Not run (over the %.0f s budget at the measured streaming rate): %s '
                'samples.' % (r['memory']['budget_s'],
                              ', '.join(f'{n:.0e}' for n in r['memory']['skipped']))]
    out += ['', '### Goals', '']
    rows = []
    for g in r['goals']:
        value = g['value']
        if isinstance(value, list):
            value = ' vs '.join(f'{v:.4g}' for v in value)
        elif isinstance(value, float):
            value = f'{value:.4g}'
        rows.append([g['goal'], value, 'met' if g['met'] else '**not met**'])
    out.append(table(['goal', 'measured', ''], rows))
    return '\n'.join(out)
