"""Work units of the LLR benchmark, run in worker processes (picklable, small results)."""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from bench.llr_peer import detect_offline
from rwa_monitor.sim.friction import (Anomaly, parse_anomaly, REGIMES, simulate_friction,
                                      simulate_friction_with_truth)
from rwa_monitor.sim.profiles import paper_profile

WHEEL = 'rw1'
# One change on each of rw2..rw4 (rw1 stays nominal), SI sizes of docs/simulators.md.
REALISTIC_ANOMALIES = ('rw2:dry:3600:+2e-4', 'rw3:viscous:7200:+3e-7',
                       'rw4:both:5000:+1e-4:+2e-7')


def series(profile: str, n: int, seed: int, delta_dry: float = 0.0,
           delta_viscous: float = 0.0, change: int = 0
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (time, speed, friction) of one wheel in the paper's scaled units, 1 Hz."""
    anomalies = []
    if delta_dry or delta_viscous:
        kind = 'both' if delta_dry and delta_viscous else 'dry' if delta_dry else 'viscous'
        anomalies = [Anomaly(WHEEL, kind, float(change), delta_dry, delta_viscous)]
    tele = simulate_friction(wheels=(WHEEL,), n_samples=n, rate_hz=1.0, profile=profile,
                             units='scaled', anomalies=anomalies, seed=seed)
    wheel = tele.wheels[WHEEL]
    return tele.time, wheel.speed, wheel.friction


def llr_events(time_s, speed, friction, params: dict[str, Any]) -> list:
    """Run the batch LLR detector of the core on one wheel."""
    from rwa_monitor.core.llr import detect_batch
    return detect_batch(time_s, speed, friction, component=WHEEL, **params)


def summarise_llr(events: Sequence, change: int | None, tol: int) -> dict[str, Any]:
    """Match first declarations to the change (|index - change| <= tol).

    Returns whether the change was detected, the localisation error and declaration
    delay (samples) of the first matching declaration, the kind of the latest event about
    that change (its last revision), and the number of unmatched first declarations.
    """
    first = [e for e in events if e.revision == 0]
    hits = [e for e in first if change is not None and abs(e.index - change) <= tol]
    out: dict[str, Any] = {'declared_any': bool(first), 'false': len(first) - len(hits),
                           'detected': bool(hits)}
    if hits:
        hit = min(hits, key=lambda e: e.declared_index)
        about = [e for e in events if abs(e.index - change) <= tol]
        final = max(about, key=lambda e: (e.declared_index, e.revision))
        out.update(error=hit.index - change, delay=hit.declared_index - change,
                   kind=hit.kind, final_kind=final.kind)
    return out


def scenario_task(task: dict[str, Any]) -> dict[str, Any]:
    """Run one seeded change scenario through the LLR (each parameter set) and the peer."""
    t, w, f = series(task['profile'], task['n'], task['seed'], task.get('dry', 0.0),
                     task.get('viscous', 0.0), task['change'])
    out: dict[str, Any] = {'llr': []}
    for params in task['llr']:
        events = llr_events(t, w, f, params)
        out['llr'].append(summarise_llr(events, task['change'], task['tol']))
    if task.get('peer'):
        start = time.perf_counter()
        bkps = detect_offline(w, f, noise_var=REGIMES['scaled']['noise_std_nm'] ** 2)
        elapsed = time.perf_counter() - start
        near = [b for b in bkps if abs(b - task['change']) <= task['tol']]
        best = min(near, key=lambda b: abs(b - task['change'])) if near else None
        out['peer'] = {'detected': best is not None, 'false': len(bkps) - len(near),
                       'error': None if best is None else best - task['change'],
                       'seconds': elapsed, 'samples': len(t)}
    return out


def arl_task(task: dict[str, Any]) -> dict[str, Any]:
    """Count false alarms of the LLR on one anomaly-free fig5 run."""
    t, w, f = series('fig5', task['n'], task['seed'])
    events = [e for e in llr_events(t, w, f, task['params']) if e.revision == 0]
    first = events[0].declared_index if events else None
    return {'alarms': len(events), 'samples': len(t), 'first': first}


def peer_false_task(task: dict[str, Any]) -> dict[str, Any]:
    """Count the peer's changes on one anomaly-free fig5 run."""
    t, w, f = series('fig5', task['n'], task['seed'])
    start = time.perf_counter()
    bkps = detect_offline(w, f, noise_var=REGIMES['scaled']['noise_std_nm'] ** 2)
    return {'alarms': len(bkps), 'samples': len(t), 'seconds': time.perf_counter() - start}


def _status_kb(field: str) -> int:
    """Return a memory field of /proc/self/status (VmRSS, VmHWM) in kB."""
    with open('/proc/self/status') as handle:
        for line in handle:
            if line.startswith(field + ':'):
                return int(line.split()[1])
    raise KeyError(field)


def memory_probe(n: int, params: dict[str, Any], chunk: int = 100_000) -> dict[str, Any]:
    """Stream ``n`` fig5 samples through one streaming detector; return RSS facts (kB).

    Run in a fresh process: the input is generated chunk by chunk, so what grows with
    ``n`` is the detector's state. ``rss_after_first_chunk`` is the baseline; the final
    RSS is compared with it, and the peak (VmHWM, this process image) across ``n``.
    """
    from rwa_monitor.core.llr import LLRDetector
    detector = LLRDetector(WHEEL, **params)
    rng = np.random.default_rng(0)
    baseline = None
    events = 0
    start = time.perf_counter()
    for k0 in range(0, n, chunk):
        k = np.arange(k0, min(n, k0 + chunk), dtype=float)
        speed = paper_profile('fig5', k)
        friction = -4.0 * np.sign(speed) - 0.01 * speed + rng.normal(0.0, 1.0, k.size)
        for t_k, w_k, f_k in zip(k.tolist(), speed.tolist(), friction.tolist()):
            events += len(detector.update(t_k, w_k, f_k))
        if baseline is None:
            baseline = _status_kb('VmRSS')
    return {'n': n, 'rss_after_first_chunk_kb': baseline, 'rss_final_kb': _status_kb('VmRSS'),
            'peak_rss_kb': _status_kb('VmHWM'), 'seconds': time.perf_counter() - start,
            'events': events}


def realistic_task(task: dict[str, Any]) -> dict[str, Any]:
    """Run the llr file pipeline on one seeded 4-wheel realistic SI file; match changes.

    A change is detected by a first declaration on its wheel whose estimated change is
    within one window of it; other first declarations are false alarms.
    """
    from rwa_monitor.pipelines import llr as pipeline
    tele, changes = simulate_friction_with_truth(
        n_wheels=4, duration_s=3600.0 * task['hours'], rate_hz=10.0, profile='realistic',
        anomalies=[parse_anomaly(a) for a in REALISTIC_ANOMALIES], seed=task['seed'])
    events = pipeline.run(tele, task['config'])
    tol = task['config']['window']
    first = [e for e in events if e.revision == 0]
    used, rows = set(), []
    for c in changes:
        hits = [e for e in first if e.component == c.wheel and abs(e.index - c.index) <= tol]
        row: dict[str, Any] = {'kind': c.kind, 'detected': bool(hits)}
        if hits:
            hit = min(hits, key=lambda e: e.declared_index)
            used.add(id(hit))
            about = [e for e in events
                     if e.component == c.wheel and abs(e.index - c.index) <= tol]
            final = max(about, key=lambda e: (e.declared_index, e.revision))
            row.update(error_s=hit.time - c.time_s, delay_s=hit.declared_time - c.time_s,
                       final_kind=final.kind)
        rows.append(row)
    return {'changes': rows, 'false': sum(id(e) not in used for e in first),
            'wheel_hours': task['hours'] * len(tele.wheels)}
