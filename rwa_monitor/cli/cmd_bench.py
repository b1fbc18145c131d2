"""``rwa-monitor bench [NAME ...]``: run the benchmarks and refresh docs/results.md."""

from __future__ import annotations

import argparse
import importlib
import pathlib
import pkgutil
import time

from rwa_monitor import bench


def available() -> list[str]:
    """Return the names of the benchmark modules (``bench_<name>``)."""
    return sorted(m.name[len('bench_'):] for m in pkgutil.iter_modules(bench.__path__)
                  if m.name.startswith('bench_'))


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bench`` sub-command."""
    parser = subparsers.add_parser(
        'bench', help='run benchmarks (results JSON, plots, docs/results.md)',
        description='Run benchmarks; write bench/results/*.json, PNG plots and the '
                    'tables of docs/results.md. Run from the repository root.')
    parser.add_argument('names', nargs='*', metavar='NAME',
                        help=f'benchmarks to run (default all: {", ".join(available())})')
    parser.add_argument('--out', type=pathlib.Path, default=pathlib.Path('bench/results'),
                        help='directory for JSON and plots (default bench/results)')
    parser.add_argument('--quick', action='store_true',
                        help='fewer runs: a smoke test of the benchmark, not a result')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the selected benchmarks in turn."""
    names = args.names or available()
    unknown = sorted(set(names) - set(available()))
    if unknown:
        raise SystemExit(f'unknown benchmark(s): {", ".join(unknown)}; '
                         f'available: {", ".join(available())}')
    for name in names:
        start = time.perf_counter()
        print(f'== bench {name}', flush=True)
        importlib.import_module(f'rwa_monitor.bench.bench_{name}').run(args.out, args.quick)
        print(f'== bench {name}: {time.perf_counter() - start:.1f} s', flush=True)
    return 0
