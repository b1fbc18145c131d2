"""``python -m bench second_change``: the price of the continuation test, measured.

A declaration made while the last declared change is still followed is first tested as
that change's continuation (docs/llr.md "One declaration per ramp"): a weak second change
soon after a first one can be taken for the first one's growth. Per run: a realistic SI
profile, one wheel, 6000 s at 10 Hz, noise 5e-5 N m; a dry step of 1.5e-4 N m (3 noise
std) at 1000 s, then a second step at 1300 s (the first change's re-checks still due) or
4000 s (they are over) of dry 1e-5 or 2e-5 N m, or viscous 1e-7 or 2e-7 N m s/rad
(0.2-0.4 noise std at the profile's speeds); `detect`'s code with the shipped LLR
parameters. Per case, :data:`RUNS` seeds from :data:`FIRST_SEED`: the second change
*declared* (a first declaration whose change time is within :data:`TOLERANCE_S` of the
second step or later), *taken as the first's growth* (no such declaration, and a
revision of the first change declared after the second step), or *no event* after it.
Writes bench/results/second_change.json and the docs/results.md section.
"""

from __future__ import annotations

import json
import pathlib
import time
from typing import Any

from bench.report import table, update_section, write_json

NAME = 'second_change'
RUNS = 40
FIRST_SEED = 64_000   # not used by any other bench or test
FIRST = 'rw1:dry:1000:+1.5e-4'
SECOND_AT_S = (1300.0, 4000.0)
TOLERANCE_S = 50.0    # one window of the shipped 500 samples at 10 Hz
SECOND = ('dry:+1e-5', 'dry:+2e-5', 'viscous:+1e-7', 'viscous:+2e-7')


def one_run(seed: int, second: str, at_s: float) -> str:
    """Return what became of the second change (at ``at_s``) in one seeded run."""
    from bench.bus_config import llr_config
    from rwa_monitor.pipelines import llr
    from rwa_monitor.sim.friction import parse_anomaly, simulate_friction_with_truth

    kind, size = second.split(':')
    anomalies = [parse_anomaly(FIRST), parse_anomaly(f'rw1:{kind}:{at_s:g}:{size}')]
    tele, _ = simulate_friction_with_truth(wheels=('rw1',), duration_s=6000.0, rate_hz=10.0,
                                           profile='realistic', anomalies=anomalies,
                                           seed=seed)
    events = llr.run(tele, llr_config())
    late = at_s - TOLERANCE_S
    if any(e.revision == 0 and e.time >= late for e in events):
        return 'declared'
    if any(e.revision > 0 and e.time < late and e.declared_time >= at_s for e in events):
        return 'growth'
    return 'none'


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run every size on its seeds; write second_change.json and the results section."""
    start = time.perf_counter()
    runs = 2 if quick else RUNS
    seeds = list(range(FIRST_SEED, FIRST_SEED + runs))
    counts: dict[str, dict[str, int]] = {}
    for at_s in SECOND_AT_S:
        for second in SECOND:
            case = f'{second} at {at_s:g} s'
            outcomes = [one_run(seed, second, at_s) for seed in seeds]
            counts[case] = {k: outcomes.count(k) for k in ('declared', 'growth', 'none')}
            print(f'  {case}: {counts[case]}', flush=True)
    results = {'quick': quick, 'seeds': [seeds[0], seeds[-1]], 'first': FIRST,
               'counts': counts,
               'elapsed_s': time.perf_counter() - start}
    write_json(out_dir, NAME, results)
    if not quick:
        update_section(NAME, markdown(results))
    print(json.dumps(counts, indent=1))
    return results


def markdown(results: dict[str, Any]) -> str:
    """Return the docs/results.md section."""
    lo, hi = results['seeds']
    rows = [[second, c['declared'], c['growth'], c['none'], sum(c.values())]
            for second, c in results['counts'].items()]
    return '\n'.join([
        f'`python -m bench second_change`: a dry step of 1.5e-4 N m at 1000 s, then a '
        f'second step; realistic profile, 6000 s at 10 Hz, '
        f'noise 5e-5 N m, seeds {lo}-{hi}, shipped LLR parameters; '
        f'{results["elapsed_s"]:.0f} s.', '',
        table(['second step', 'declared', "taken as the first's growth", 'no event after it',
               'runs'], rows)])
