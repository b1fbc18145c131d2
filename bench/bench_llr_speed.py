"""``python -m bench llr_speed``: LLR speed beside per-sample drift detectors, same stream.

One nominal (fault-free) stream of 200,000 samples (SI realistic profile, one wheel, 10 Hz,
seed 7; :func:`rwa_monitor.sim.friction.simulate_friction`) goes, in each round, through:

- our LLR detector sample by sample (``LLRDetector.update`` in a Python loop: its C
  method, and its Python path with the C call not armed) and over the whole arrays
  (``detect_batch``), parameters of bench_llr's throughput case (w = 400, r = 1e-4,
  noise level and AR model estimated);
- the river library's ADWIN and PageHinkley drift detectors (default parameters) on the
  friction torque, one ``update`` per sample in the same kind of Python loop.

Samples per CPU second of this process (``time.process_time``: a loaded shared machine
changes the wall clock, not the work); medians over the rounds, and the ratios to ADWIN
measured in the same run. False alarms: declarations of ours (``revision`` 0), drift
flags of the others, on this fault-free stream. The floors: calls that do nothing, one
per sample, made each way a per-sample update can call compiled code. Peak memory: the
RSS high-water mark of a fresh process that runs one detector both ways on the stream.
Goals (issue 25): streaming >= ADWIN, batch >= 7 x ADWIN, peak RSS < 250 MB.
"""

from __future__ import annotations

import json
import os
import pathlib
import statistics
import subprocess
import sys
import time
from typing import Any

from bench import report

N = 200_000
PARAMS = {'window': 400, 'k_verif': 'auto', 'false_alarm_rate': 1e-4, 'noise_std': 'auto'}
FLOORS = ('empty Python call', 'empty compiled call', 'empty ctypes call', 'empty C call')
GOALS = {'streaming_vs_adwin': 1.0, 'batch_vs_adwin': 7.0, 'peak_rss_mb': 250.0}
# VmHWM: the high-water mark of this process's own memory (ru_maxrss would also count
# the benchmark process it was forked from, on Linux).
RSS_SCRIPT = '''
import json, sys
from bench.bench_llr_speed import stream
from rwa_monitor.core.llr import detect_batch, LLRDetector
t, w, f = stream()
det = LLRDetector('rw1', **json.loads(sys.argv[1]))
for row in zip(t.tolist(), w.tolist(), f.tolist()):
    det.update(*row)
detect_batch(t, w, f, component='rw1', **json.loads(sys.argv[1]))
with open('/proc/self/status') as status:
    print(next(int(line.split()[1]) for line in status if line.startswith('VmHWM')) / 1024.0)
'''


def stream():
    """Return ``(time, speed, friction)`` of the nominal benchmark stream."""
    from rwa_monitor.sim.friction import simulate_friction
    tele = simulate_friction(wheels=('rw1',), n_samples=N, rate_hz=10.0, seed=7)
    wheel = tele.wheels['rw1']
    return tele.time, wheel.speed, wheel.friction


def _ours_streaming(rows: list[tuple[float, float, float]]) -> tuple[float, list]:
    from rwa_monitor.core.llr import LLRDetector
    det = LLRDetector('rw1', **PARAMS)
    events = []
    start = time.process_time()
    for t_k, w_k, f_k in rows:
        found = det.update(t_k, w_k, f_k)
        if found:
            events.extend(found)
    return time.process_time() - start, events


def _ours_batch(t, w, f) -> tuple[float, list]:
    from rwa_monitor.core.llr import detect_batch
    start = time.process_time()
    events = detect_batch(t, w, f, component='rw1', **PARAMS)
    return time.process_time() - start, events


def _river(name: str, values: list[float]) -> tuple[float, int]:
    from river import drift
    detector = getattr(drift, name)()
    alarms = 0
    start = time.process_time()
    for x in values:
        detector.update(x)
        if detector.drift_detected:
            alarms += 1
    return time.process_time() - start, alarms


def _ours_python_path(rows: list[tuple[float, float, float]]) -> float:
    """Return the samples per CPU s of our streaming update with the C call never armed."""
    from unittest import mock

    from rwa_monitor.core import llr_cstep, llr_detector
    with mock.patch.object(llr_cstep, 'step_address', return_value=None), \
            mock.patch.object(llr_detector, '_C_CALL', False):
        return len(rows) / _ours_streaming(rows)[0]


def _empty_calls(rows: list[tuple[float, float, float]]) -> dict[str, float]:
    """Return the samples per CPU s of calls that do nothing, per way of calling.

    Each takes our step's arguments: ``Python call``, a Python function of three floats;
    ``compiled call``, a numba function of two state arrays and three floats through its
    dispatcher (``llr_kernel.step``'s way); ``ctypes call``, a numba C function of two
    pointers, two lengths and three floats through ctypes; ``C call``, that C function
    through the detector's C method (core/_stepcall.c, ``llr_cstep``'s way). The floor of
    a per-sample update made each way.
    """
    import ctypes

    import numpy as np
    from numba import carray, cfunc, njit, types

    from rwa_monitor.core import _stepcall

    def python(t, w, f):
        return 0

    @njit('int64(float64[::1], int64[::1], float64, float64, float64)')
    def compiled(fs, ints, t, w, f):
        return 0

    @cfunc(types.int64(types.CPointer(types.float64), types.int64,
                       types.CPointer(types.int64), types.int64,
                       types.float64, types.float64, types.float64))
    def nothing(fs, n_fs, ints, n_ints, t, w, f):
        return carray(ints, (n_ints,))[0]

    class Owner(_stepcall.StepOwner):
        def update(self, t, w, f):
            return []
        update = _stepcall.CompiledUpdate(update, 'update')

    fs, ints = np.zeros(8), np.zeros(8, dtype=np.int64)
    owner = Owner()
    owner._step_arm(nothing.address, fs, ints)
    c_type = ctypes.CFUNCTYPE(ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p,
                              ctypes.c_int64, ctypes.c_double, ctypes.c_double, ctypes.c_double)
    by_ctypes = c_type(nothing.address)
    fs_p, ints_p = fs.ctypes.data, ints.ctypes.data

    def python_loop():
        for t_k, w_k, f_k in rows:
            python(t_k, w_k, f_k)

    def compiled_loop():
        for t_k, w_k, f_k in rows:
            compiled(fs, ints, t_k, w_k, f_k)

    def ctypes_loop():
        for t_k, w_k, f_k in rows:
            by_ctypes(fs_p, 8, ints_p, 8, t_k, w_k, f_k)

    def c_loop():
        for t_k, w_k, f_k in rows:
            owner.update(t_k, w_k, f_k)

    rates = {}
    for name, loop in (('Python', python_loop), ('compiled', compiled_loop),
                       ('ctypes', ctypes_loop), ('C', c_loop)):
        start = time.process_time()
        loop()
        rates[f'empty {name} call'] = len(rows) / (time.process_time() - start)
    return rates


def _peak_rss_mb() -> float:
    env = dict(os.environ, PYTHONPATH=str(report.REPO))
    out = subprocess.run([sys.executable, '-c', RSS_SCRIPT, json.dumps(PARAMS)], env=env,
                         cwd=report.REPO, check=True, capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def measure(rounds: int) -> dict[str, Any]:
    """Return the per-round CPU times, the medians, ratios, false alarms and peak RSS."""
    t, w, f = stream()
    rows = list(zip(t.tolist(), w.tolist(), f.tolist()))
    friction = f.tolist()
    _ours_batch(t[:5000], w[:5000], f[:5000])   # compile / load the kernels first
    per_s: dict[str, list[float]] = {k: [] for k in (
        'ours streaming', 'ours batch', 'ADWIN', 'PageHinkley', 'ours streaming, Python path',
        *FLOORS)}
    alarms: dict[str, int] = {}
    same = True
    for round_no in range(rounds):
        seconds, streamed = _ours_streaming(rows)
        per_s['ours streaming'].append(N / seconds)
        seconds, batch = _ours_batch(t, w, f)
        per_s['ours batch'].append(N / seconds)
        same &= [e.to_json() for e in batch] == [e.to_json() for e in streamed]
        alarms['ours streaming'] = sum(e.revision == 0 for e in streamed)
        alarms['ours batch'] = sum(e.revision == 0 for e in batch)
        for name in ('ADWIN', 'PageHinkley'):
            seconds, alarms[name] = _river(name, friction)
            per_s[name].append(N / seconds)
        per_s['ours streaming, Python path'].append(_ours_python_path(rows))
        alarms['ours streaming, Python path'] = '-'
        for name, rate in _empty_calls(rows).items():
            per_s[name].append(rate)
            alarms[name] = '-'
        print(f'  round {round_no + 1}/{rounds}: ' + ', '.join(
            f'{k} {v[-1] / 1e6:.2f} M/s' for k, v in per_s.items()), flush=True)
    median = {k: statistics.median(v) for k, v in per_s.items()}
    ratio = {k: median[k] / median['ADWIN'] for k in median}
    # The first process on a machine compiles the kernels (numba cache); the second loads.
    rss_first, rss = _peak_rss_mb(), _peak_rss_mb()
    met = {'streaming_vs_adwin': ratio['ours streaming'] >= GOALS['streaming_vs_adwin'],
           'batch_vs_adwin': ratio['ours batch'] >= GOALS['batch_vs_adwin'],
           'peak_rss_mb': rss < GOALS['peak_rss_mb']}
    from rwa_monitor.core import llr_cstep
    return {'n': N, 'params': PARAMS, 'rounds': rounds,
            'c_call_armed': llr_cstep.step_address() is not None, 'per_s': per_s, 'median': median,
            'ratio_to_adwin': ratio, 'false_alarms': alarms, 'batch_equals_streaming': same,
            'peak_rss_mb': rss, 'peak_rss_first_mb': rss_first, 'goals': GOALS, 'met': met}


def markdown(res: dict[str, Any], load: tuple[tuple[float, ...], tuple[float, ...]]) -> str:
    """Return the docs/results.md section of a run."""
    rows = [[name, f'{res["median"][name] / 1e6:.2f}',
             f'{min(v) / 1e6:.2f}-{max(v) / 1e6:.2f}', f'{res["ratio_to_adwin"][name]:.2f}',
             res['false_alarms'][name]] for name, v in res['per_s'].items()]
    verdict = {True: 'met', False: 'NOT met'}
    met = res['met']
    ratio = res['ratio_to_adwin']
    return '\n'.join([
        '## LLR speed beside ADWIN and PageHinkley (`python -m bench llr_speed`, issue 25)',
        '',
        f'One fault-free stream of {res["n"]:,} samples (SI realistic profile, one wheel, '
        f'10 Hz, seed 7), {res["rounds"]} rounds in one process; ours with w = 400, r = '
        '1e-4, noise level and AR model estimated; ADWIN and PageHinkley (river 0.26.1, '
        'defaults) on the friction torque. Million samples per CPU second of the process '
        '(median, range over rounds); ratio to ADWIN in the same run; false alarms on the '
        'fault-free stream. Load average (1, 5, 15 min) before: '
        f'{", ".join(f"{x:.2f}" for x in load[0])}; after: '
        f'{", ".join(f"{x:.2f}" for x in load[1])} (2 cores shared).',
        '',
        report.table(['detector', 'M samples / CPU s', 'range', 'x ADWIN', 'false alarms'],
                     rows),
        '',
        f'C call armed in "ours streaming": {res["c_call_armed"]}. '
        f'Batch events == streaming events: {res["batch_equals_streaming"]}. Peak RSS of '
        f'one detector process (imports, the stream, streaming then batch on it): '
        f'{res["peak_rss_mb"]:.0f} MB with the compiled kernels cached '
        f'({res["peak_rss_first_mb"]:.0f} MB in the process before it).',
        '',
        f'Goals: streaming >= ADWIN: {verdict[met["streaming_vs_adwin"]]} '
        f'({ratio["ours streaming"]:.2f}x); batch >= 7x ADWIN: '
        f'{verdict[met["batch_vs_adwin"]]} ({ratio["ours batch"]:.2f}x); peak RSS < 250 MB: '
        f'{verdict[met["peak_rss_mb"]]}.',
        '',
        '"ours streaming" is `LLRDetector.update` as installed: a method implemented in C '
        '(core/_stepcall.c) calling the compiled step as a C function (core/llr_cstep.py); '
        '"ours streaming, Python path" the same detector with that C call never armed (the '
        'C method hands each call to the Python method, which calls the compiled step '
        "through numba's dispatcher; without the C module the Python method is called "
        'directly). '
        '"empty ... call": a function that does nothing, called per sample in the same '
        'loop, the floor of a per-sample update made that way: a Python function of three '
        "floats, a numba function of our step's arguments (two state arrays, three floats) "
        'through its dispatcher, a numba C function of two pointers, two lengths and three '
        'floats through ctypes, and that C function through our C method '
        f'({ratio["empty Python call"]:.2f}x, {ratio["empty compiled call"]:.2f}x, '
        f'{ratio["empty ctypes call"]:.2f}x, {ratio["empty C call"]:.2f}x ADWIN; docs/llr.md '
        '"Streaming call").',
    ])


def run(out_dir: pathlib.Path, quick: bool = False) -> dict[str, Any]:
    """Run the comparison; write bench/results/llr_speed.json and the results section."""
    before = os.getloadavg()
    res = measure(2 if quick else 7)
    load = (before, os.getloadavg())
    res['load_average'] = {'before': before, 'after': load[1]}
    report.write_json(out_dir, 'llr_speed', res)
    if not quick:
        report.update_section('llr_speed', markdown(res, load))
    print(markdown(res, load))
    return res
