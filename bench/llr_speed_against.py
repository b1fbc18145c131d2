"""Streaming and batch LLR speed of this tree against another checkout, on one machine.

``python -m bench.llr_speed_against OLD_CHECKOUT``: runs the throughput case of
bench_llr (SI realistic profile, 300k samples, w = 400, r = 1e-4, noise estimated) in two
interleaved rounds, in separate processes, for the other checkout and for this tree, and
prints the samples per CPU second of each (process time: a loaded shared machine changes
the wall clock, not the work). Absolute figures depend on the machine; the ratio is the
result (docs/results.md, "LLR speed of this round").
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
CASE = '''
import time
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
print(n / (time.process_time() - start), batch)
'''


def measure(tree: pathlib.Path) -> tuple[float, float]:
    """Return (streaming, batch) samples/s of the checkout at ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, '-c', CASE], env=env, cwd=tree, check=True,
                         capture_output=True, text=True).stdout.split()
    return float(out[0]), float(out[1])


def main(argv: list[str]) -> int:
    """Print the speeds of OLD_CHECKOUT and of this tree, two interleaved rounds."""
    if len(argv) != 1:
        print('usage: python -m bench.llr_speed_against OLD_CHECKOUT', file=sys.stderr)
        return 2
    old = pathlib.Path(argv[0]).resolve()
    for round_no in (1, 2):
        for name, tree in (('other', old), ('this', REPO)):
            stream, batch = measure(tree)
            print(f'round {round_no} {name}: streaming {stream:.0f}/s, batch {batch:.0f}/s',
                  flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
