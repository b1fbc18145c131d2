"""Cases of the detection-power benchmark (``python -m bench llr_power``).

Detection against fault size, ROC against false alarms per hour, the llr-realtime paper's
Figs. 6-7 experiment, and categorisation against how much the speed varied after the
change. Data from :mod:`rwa_monitor.sim.friction` (paper profiles in scaled units at
1 Hz, the realistic profile in SI units at 10 Hz).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench import llr_cases
from rwa_monitor.core import keys
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth


def outcome(events: list, change: int, tol: int, kind: str | None) -> dict[str, Any]:
    """Match the first declaration near ``change``; return detection, delay and kind class.

    Kind class of the last revision about the change: ``right`` (confirmed, correct),
    ``undecided``, ``wrong`` (confirmed, incorrect); ``guess_right``: its best guess.
    """
    first = [e for e in events if e.revision == 0]
    hits = [e for e in first if abs(e.index - change) <= tol]
    out: dict[str, Any] = {'detected': bool(hits), 'false': len(first) - len(hits)}
    if not hits:
        return out
    hit = min(hits, key=lambda e: e.declared_index)
    about = [e for e in events if e.index == hit.index]
    final = max(about, key=lambda e: (e.declared_index, e.revision))
    out['delay'] = hit.declared_index - change
    if kind is not None:
        guess = final.details.get(keys.KIND_GUESS) or final.kind
        if final.kind == 'undecided':
            out['kind_class'] = 'undecided'
        else:
            out['kind_class'] = 'right' if final.kind == kind else 'wrong'
        out['guess_right'] = guess == kind
    return out


def paper_task(task: dict[str, Any]) -> dict[str, Any]:
    """One run on a paper profile (scaled units): detection, delay and kind."""
    t, w, f = llr_cases.series(task['profile'], task['n'], task['seed'], task['dry'],
                               task['viscous'], task.get('change', 0))
    events = llr_cases.llr_events(t, w, f, task['params'])
    if not (task['dry'] or task['viscous']):
        return {'alarms': sum(e.revision == 0 for e in events), 'samples': task['n']}
    res = outcome(events, task['change'], task['tol'], task.get('kind'))
    if task.get('curve'):
        res['declared'] = [e.declared_index for e in events if e.revision == 0
                           and abs(e.index - task['change']) <= task['tol']]
    return res


def realistic_task(task: dict[str, Any]) -> dict[str, Any]:
    """One SI realistic-profile run with one change; kind outcome and post-change speed."""
    from rwa_monitor.core.llr import detect_batch
    anomaly = Anomaly('rw1', task['kind'], task['change_s'], task['dry'], task['viscous'])
    tele, changes = simulate_friction_with_truth(wheels=('rw1',), n_samples=task['n'],
                                                 rate_hz=10.0, profile='realistic',
                                                 anomalies=[anomaly], seed=task['seed'])
    wheel = tele.wheels['rw1']
    events = detect_batch(tele.time, wheel.speed, wheel.friction, window=400)
    at = changes[0].index
    res = outcome(events, at, 400, task['kind'])
    after = np.abs(wheel.speed[at:])
    res['speed_std_after'] = float(np.std(after))
    return res


def smallest(sizes: list[float], probs: list[float], level: float = 0.9) -> float:
    """Return the smallest size whose detection probability (and all larger) >= level."""
    ok = [s for i, s in enumerate(sizes) if all(p >= level for p in probs[i:])]
    return min(ok) if ok else math.nan
