"""``python -m bench bus_ramps`` (``make bench-bus``): ramp kinds on the bus, with intervals.

The bus acceptance (bench/bus_acceptance.py) has 10 runs per fault, so a rate of 90 % is
read there within about +-20 %. This bench runs more ramps of each kind on fresh seeds
(:data:`SEEDS`, fixed before any result was seen), with the acceptance's calibration
(seed 7020), fault size, start and duration, one wheel per run in turn, and scores them
as the acceptance does (the final kind of the first declaration on the faulty wheel after
the fault starts). Per kind: right / detected / runs, with a two-sided 95 %
Clopper-Pearson interval of the right-kind rate and the one-sided binomial p-value of the
count under a true rate of 90 % (the acceptance's goal). Needs the ``bsk`` extra.
"""

from __future__ import annotations

import json
import multiprocessing
import pathlib
import time
from typing import Any

from bench.bus_config import llr_config
from bench.report import table, update_section, write_json
from rwa_monitor.sim.basilisk_config import available, INSTALL_HINT

NAME = 'bus_ramps'
SEEDS = tuple(range(7700, 7740))
# Spent: 7300-7339 (the rule of llr_kinds.stands_beside_growth was made on them),
# 7400-7439 (scored with a version of it that could name the other kind), 7500-7539 (the
# continuation rule of llr_changes.growth_kind was found on them) and 7600-7639 (scored
# with a first version of that rule).
GOAL = 0.9
RAMPS = ('dry ramp', 'viscous ramp')


def plan(seeds: tuple[int, ...]) -> list[dict[str, Any]]:
    """Return the runs: each seed one ramp of each kind, wheels in turn."""
    from bench import bus_acceptance as acc
    faults = {name: (kind, spec) for name, kind, spec in acc.FAULTS}
    runs = []
    for i, seed in enumerate(seeds):
        name = RAMPS[i % len(RAMPS)]
        kind, spec = faults[name]
        wheel = acc.WHEELS[(i // len(RAMPS)) % len(acc.WHEELS)]
        runs.append({'seed': seed, 'fault': name, 'expected': kind, 'wheel': wheel,
                     'spec': f'friction:{wheel}:{acc.FAULT_TIME_S:g}:{spec}'})
    return runs


def interval(right: int, runs: int) -> dict[str, float]:
    """Return the Clopper-Pearson 95 % interval and ``P(X <= right | GOAL)``."""
    from scipy import stats
    low = float(stats.beta.ppf(0.025, right, runs - right + 1)) if right > 0 else 0.0
    high = float(stats.beta.ppf(0.975, right + 1, runs - right)) if right < runs else 1.0
    return {'low': low, 'high': high,
            'p_at_goal': float(stats.binom.cdf(right, runs, GOAL))}


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run the ramps; write bus_ramps.json and the docs/results.md section."""
    if not available():
        print(f'bench {NAME}: skipped: {INSTALL_HINT}')
        return {'skipped': INSTALL_HINT}
    from bench import bus_acceptance as acc

    start = time.perf_counter()
    calibration = acc.calibrate(out_dir)
    runs = plan(SEEDS[:2] if quick else SEEDS)
    jobs = [(r, calibration['path'], llr_config()) for r in runs]
    results: dict[str, Any] = {'quick': quick, 'calibration_seed': calibration['seed'],
                               'seeds': [runs[0]['seed'], runs[-1]['seed']], 'runs': []}
    with multiprocessing.get_context('spawn').Pool(2) as pool:
        for result in pool.imap(acc._worker, jobs):
            result.pop('fss', None)
            result.pop('uncalibrated', None)
            results['runs'].append(result)
            print(f'  seed {result["seed"]} {result["fault"]} on {result["wheel"]}', flush=True)
    per_fault = acc.score(results['runs'], 'calibrated')['per_fault']
    keys = ('runs', 'detected', 'right_kind', 'confirmed', 'right_confirmed', 'delay_median_s',
            'extra_declarations')
    results['score'] = {name: {**{k: entry[k] for k in keys},
                               **interval(entry['right_kind'], entry['runs'])}
                        for name, entry in per_fault.items()}
    results['elapsed_s'] = time.perf_counter() - start
    write_json(out_dir, NAME, results)
    if not quick:
        update_section(NAME, markdown(results))
    print(json.dumps(results['score'], indent=1))
    return results


def markdown(results: dict[str, Any]) -> str:
    """Return the docs/results.md section."""
    rows = [[name, s['runs'], s['detected'], s['right_kind'], s['right_confirmed'],
             f'{s["right_kind"] / s["runs"]:.0%}', f'{s["low"]:.0%}-{s["high"]:.0%}',
             f'{s["p_at_goal"]:.2f}', s['extra_declarations']]
            for name, s in sorted(results['score'].items())]
    lo, hi = results['seeds']
    return '\n'.join([
        f'`python -m bench bus_ramps`: ramps of the bus acceptance on fresh seeds {lo}-{hi} '
        f'(fixed before any result was seen), calibration seed '
        f'{results["calibration_seed"]}, LLR parameters of config/rwa_monitor.yaml; '
        f'{results["elapsed_s"]:.0f} s.', '',
        table(['ramp', 'runs', 'detected', 'right kind', 'right and confirmed', 'rate',
               '95 % interval', f'P(<= right at {GOAL:.0%})',
               'more declarations of the same ramp'], rows)])
