"""``python -m bench [NAME ...]`` (``make bench``): run benchmarks, refresh docs/results.md.

Benchmarks live outside the installed package: results and docs are found relative to
this repository, whatever the working directory.
"""

from __future__ import annotations

import argparse
import importlib
import pathlib
import pkgutil
import sys
import time

import bench
from bench.report import RESULTS_DIR


def available() -> list[str]:
    """Return the names of the benchmark modules (``bench_<name>``)."""
    return sorted(m.name[len('bench_'):] for m in pkgutil.iter_modules(bench.__path__)
                  if m.name.startswith('bench_'))


def main(argv: list[str] | None = None) -> int:
    """Run the selected benchmarks in turn; return the exit code."""
    parser = argparse.ArgumentParser(
        prog='python -m bench',
        description='Run benchmarks; write bench/results/*.json, PNG plots and the '
                    'tables of docs/results.md.')
    parser.add_argument('names', nargs='*', metavar='NAME',
                        help=f'benchmarks to run (default all: {", ".join(available())})')
    parser.add_argument('--out', type=pathlib.Path, default=RESULTS_DIR,
                        help='directory for JSON and plots (default bench/results)')
    parser.add_argument('--quick', action='store_true',
                        help='fewer runs: a smoke test of the benchmark, not a result')
    args = parser.parse_args(argv)
    names = args.names or available()
    unknown = sorted(set(names) - set(available()))
    if unknown:
        parser.error(f'unknown benchmark(s): {", ".join(unknown)}; '
                     f'available: {", ".join(available())}')
    for name in names:
        start = time.perf_counter()
        print(f'== bench {name}', flush=True)
        importlib.import_module(f'bench.bench_{name}').run(args.out, args.quick)
        print(f'== bench {name}: {time.perf_counter() - start:.1f} s', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
