"""Streaming and batch LLR speed of this tree against another checkout, on one machine.

``python -m bench.llr_speed_against OLD_CHECKOUT [--rounds N] [--bus FILE --calibration
YAML]``: runs, in N interleaved rounds (default 2), each in its own process, for the other
checkout and for this tree:

- the throughput case of bench_llr (SI realistic profile, 300k samples, w = 400, r = 1e-4,
  noise estimated; white noise);
- with ``--bus``: the calibrated bus case of bench/bus_acceptance.py ``throughput`` (every
  wheel of FILE, LLR parameters of config/rwa_monitor.yaml): streaming = the per-sample
  calibrated residual ``NominalWheel.residual_one`` then ``LLRDetector.update``, batch =
  ``NominalWheel.residual`` then ``detect_batch``, and where the tree has it the one-call
  streaming path ``LLRDetector.update_nominal(NominalWheel.table, ...)`` (its events
  compared with the two-call ones);

and prints the samples per CPU second of each (process time: a loaded shared machine
changes the wall clock, not the work), then the medians over the rounds and their ratio
this / other. Absolute figures depend on the machine; the ratio is the result
(docs/results.md, "LLR speed of this round" and "LLR speed (issue 12 throughput)").
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
WHITE = '''
import json, time
from rwa_monitor.core.llr import detect_batch, LLRDetector
from rwa_monitor.sim.friction import simulate_friction
params = {'window': 400, 'k_verif': 200, 'false_alarm_rate': 1e-4, 'noise_std': None}
n = 300000
tele = simulate_friction(wheels=('rw1',), n_samples=n, rate_hz=10.0, seed=7)
w = tele.wheels['rw1']
start = time.process_time()
detect_batch(tele.time, w.speed, w.friction, component='rw1', **params)
batch = n / (time.process_time() - start)
det = LLRDetector('rw1', **params)
rows = list(zip(tele.time.tolist(), w.speed.tolist(), w.friction.tolist()))
start = time.process_time()
for t, s, f in rows:
    det.update(t, s, f)
print(json.dumps({'streaming': n / (time.process_time() - start), 'batch': batch}))
'''
BUS = '''
import json, sys, time
import numpy as np
from rwa_monitor.core.calibrate import NominalWheel
from rwa_monitor.core.llr import detect_batch, LLRDetector
from rwa_monitor.core.schema import llr_kwargs
from rwa_monitor.pipelines import calibrated, llr
from rwa_monitor.telemetry import read_telemetry
from rwa_monitor.telemetry.parameters_file import load_block
params = load_block(None, llr.SCHEMA)
kwargs = llr_kwargs({k: v for k, v in params.items() if k in llr.DEFAULTS})
tele = read_telemetry(sys.argv[1])
cal = calibrated.load(sys.argv[2])
n = len(tele)
t, rates, same = tele.time.tolist(), {'streaming': [], 'batch': []}, True
for wheel, ch in tele.wheels.items():
    nominal = NominalWheel(cal['wheels'][wheel])
    w, f = ch.speed.tolist(), ch.friction.tolist()
    start = time.process_time()
    residual, _ = nominal.residual(tele.time, ch.speed, ch.friction)
    batch = detect_batch(tele.time, ch.speed, residual, component=wheel, **kwargs)
    rates['batch'].append(n / (time.process_time() - start))
    detector = LLRDetector(wheel, **kwargs)
    found = []
    start = time.process_time()
    for t_k, w_k, f_k in zip(t, w, f):
        out = detector.update(t_k, w_k, nominal.residual_one(t_k, w_k, f_k)[0])
        if out:
            found.extend(out)
    rates['streaming'].append(n / (time.process_time() - start))
    same &= [e.to_json() for e in batch] == [e.to_json() for e in found]
    if hasattr(LLRDetector, 'update_nominal'):
        detector = LLRDetector(wheel, **kwargs)
        table = NominalWheel(cal['wheels'][wheel]).table
        one = []
        start = time.process_time()
        for t_k, w_k, f_k in zip(t, w, f):
            out = detector.update_nominal(table, t_k, w_k, f_k)
            if out:
                one.extend(out)
        rates.setdefault('one call', []).append(n / (time.process_time() - start))
        same &= [e.to_json() for e in one] == [e.to_json() for e in found]
out = {k: float(np.median(v)) for k, v in rates.items()}
print(json.dumps(dict(out, batch_equals_streaming=same)))
'''


def measure(tree: pathlib.Path, case: str, args: tuple[str, ...] = ()) -> dict:
    """Return the samples/s of ``case`` (WHITE or BUS source) in the checkout at ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, '-c', case, *args], env=env, cwd=tree,
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    """Print the speeds of OLD_CHECKOUT and of this tree, interleaved, then medians."""
    parser = argparse.ArgumentParser(prog='python -m bench.llr_speed_against')
    parser.add_argument('old')
    parser.add_argument('--rounds', type=int, default=2)
    parser.add_argument('--bus', help='bus telemetry file (calibrated case)')
    parser.add_argument('--calibration', help='calibration.yaml of the bus case')
    args = parser.parse_args(argv)
    if bool(args.bus) != bool(args.calibration):
        parser.error('--bus and --calibration go together')
    old = pathlib.Path(args.old).resolve()
    cases = [('white', WHITE, ())]
    if args.bus:
        cases.append(('bus calibrated', BUS, (str(pathlib.Path(args.bus).resolve()),
                                              str(pathlib.Path(args.calibration).resolve()))))
    got: dict[tuple[str, str], list[dict]] = {}
    for round_no in range(1, args.rounds + 1):
        for label, case, extra in cases:
            for name, tree in (('other', old), ('this', REPO)):
                rates = measure(tree, case, extra)
                got.setdefault((label, name), []).append(rates)
                print(f'round {round_no} {label} {name}: streaming {rates["streaming"]:.0f}/s, '
                      f'batch {rates["batch"]:.0f}/s'
                      + (f', streaming in one call {rates["one call"]:.0f}/s'
                         if 'one call' in rates else '')
                      + (f', batch events == streaming: {rates["batch_equals_streaming"]}'
                         if 'batch_equals_streaming' in rates else ''), flush=True)
    for label, _, _ in cases:
        for mode in ('streaming', 'batch', 'one call'):
            now = [r[mode] for r in got[(label, 'this')] if mode in r]
            if not now:
                continue
            before = [r[mode] for r in got[(label, 'other')] if mode in r]
            print(f'median {label} {mode}: this {statistics.median(now):.0f}/s'
                  + (f', other {statistics.median(before):.0f}/s, ratio '
                     f'{statistics.median(now) / statistics.median(before):.2f}'
                     if before else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
