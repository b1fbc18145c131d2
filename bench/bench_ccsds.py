"""``python -m bench ccsds``: CCSDS space packets (issue 33), decoder rate and detect time.

1. Decoder: a file of fixed-layout containers written by the package's writer (a wheel
   container of 8 float64 values and a gyro container of 3, both with the CUC-style time,
   interleaved at 10 Hz each), decoded by the vectorised path (walk, gather, record-type
   views; ``ccsds.decode_file``) and by the whole reader (plus the join onto one time
   base; ``ccsds.read_packets``): packets per second, median of repeated runs with the file
   in the page cache. space-packet-parser's rate beside it: its generator and
   ``parse_bytes`` on the first packets of the same file. Goal: >= 5 M packets/s.
2. ``rwa-monitor detect`` wall time on packets against the same data as CSV (a 3 h, 10 Hz
   run of 4 wheels with gyro and star tracker: the CSV read back, then written as
   packets, so both hold the same values), each a fresh process, in turn, median of the
   runs and median of the per-pair ratios. Goal: packets <= 1.5 x CSV.

Writes bench/results/ccsds.json, ccsds.png and section ``ccsds`` of docs/results.md.
"""

from __future__ import annotations

import os
import pathlib
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any, Callable

import numpy as np

from bench import report
from rwa_monitor.telemetry import ccsds, read_telemetry, Telemetry, telemetry_map, Wheel
from rwa_monitor.telemetry import write_telemetry, xtce
from rwa_monitor.telemetry.ccsds_write import sibling_paths

GOALS = {'decoder_packets_per_s': 5e6, 'detect_ratio_packets_over_csv': 1.5}


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'rows': 100_000, 'repeats': 3, 'reference_packets': 3_000,
                'detect_hours': 0.25, 'detect_runs': 2}
    return {'rows': 1_000_000, 'repeats': 7, 'reference_packets': 20_000,
            'detect_hours': 3.0, 'detect_runs': 5}


def decoder_file(path: pathlib.Path, rows: int, seed: int = 0) -> int:
    """Write ``rows`` wheel and gyro packets (fixed layouts); return the packet count."""
    rng = np.random.default_rng(seed)
    tele = Telemetry(time=np.arange(rows) / 10.0, wheels={
        f'rw{k}': Wheel(rng.normal(size=rows), rng.normal(size=rows)) for k in range(1, 5)},
        gyro=rng.normal(size=(rows, 3)))
    write_telemetry(path, tele)
    return 2 * rows


def _timed(call: Callable[[], Any], repeats: int) -> dict[str, Any]:
    """Return wall and CPU seconds (this process) of ``repeats`` calls, with medians."""
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        call()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return {'wall_s': wall, 'cpu_s': cpu, 'wall_median_s': statistics.median(wall),
            'cpu_median_s': statistics.median(cpu), 'wall_min_s': min(wall)}


def decoder(folder: pathlib.Path, settings: dict[str, Any]) -> dict[str, Any]:
    """Return the decoder rates (vectorised, whole reader, space-packet-parser)."""
    import space_packet_parser as spp
    path = folder / 'decoder.bin'
    packets = decoder_file(path, settings['rows'])
    xml, yml = sibling_paths(path)
    definition, tmap = xtce.load(xml), telemetry_map.read_map(yml)
    columns_of = telemetry_map.check(tmap, definition)
    decoded, report_ = ccsds.decode_file(path, definition, tmap, columns_of)   # warm-up
    assert sum(report_.decoded.values()) == packets
    vector = _timed(lambda: ccsds.decode_file(path, definition, tmap, columns_of),
                    settings['repeats'])
    reader = _timed(lambda: ccsds.read_packets(path, xml, yml), settings['repeats'])
    n_ref = settings['reference_packets']

    def reference() -> None:
        with open(path, 'rb') as handle:
            for k, raw in enumerate(spp.ccsds_generator(handle)):
                definition.spp.parse_bytes(raw)
                if k + 1 == n_ref:
                    break

    ref = _timed(reference, 3)
    out: dict[str, Any] = {'packets': packets, 'file_bytes': path.stat().st_size,
                           'reference_packets': n_ref}
    for name, timing, n in (('vectorised', vector, packets), ('reader', reader, packets),
                            ('reference', ref, n_ref)):
        out[name] = timing
        out[f'{name}_packets_per_s'] = n / timing['wall_median_s']
        out[f'{name}_packets_per_cpu_s'] = n / timing['cpu_median_s']
    return out


def detect_files(folder: pathlib.Path, hours: float) -> tuple[pathlib.Path, pathlib.Path]:
    """Write the detect input as CSV and, from the CSV as read, as packets."""
    from rwa_monitor.sim.aocs import add_gyro_channels
    from rwa_monitor.sim.friction import parse_anomaly, simulate_friction
    tele = simulate_friction(duration_s=3600 * hours, rate_hz=10.0, seed=330,
                             wheels=('rw1', 'rw2', 'rw3', 'rw4'),
                             anomalies=[parse_anomaly(f'rw2:dry:{1800 * hours:g}:3e-4')])
    tele = add_gyro_channels(tele, seed=331)
    csv, packets = folder / 'run.csv', folder / 'run.bin'
    write_telemetry(csv, tele)
    write_telemetry(packets, read_telemetry(csv))
    return csv, packets


def detect_times(csv: pathlib.Path, packets: pathlib.Path, runs: int) -> dict[str, Any]:
    """Time ``rwa-monitor detect`` on both files in turn (fresh processes), after a warm-up."""
    def once(path: pathlib.Path) -> tuple[float, float]:
        """Return (wall s, CPU s of the child: user + system)."""
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', 'detect',
                               str(path), '-o', str(path.with_suffix('.events.json'))],
                              capture_output=True, text=True, timeout=1800)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode not in (0, 1, 3):
            raise RuntimeError(f'detect {path.name}: {done.stderr.strip()[-300:]}')
        return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)

    once(csv), once(packets)                          # warm-up: caches, compiled kernels
    timed = [(once(csv), once(packets)) for _ in range(runs)]
    pairs = [(a[0], b[0]) for a, b in timed]
    cpu = [(a[1], b[1]) for a, b in timed]
    same = (csv.with_suffix('.events.json').read_text().split('"summary"')[0]
            == packets.with_suffix('.events.json').read_text().split('"summary"')[0])
    return {'runs': runs, 'csv_s': [a for a, _ in pairs], 'packets_s': [b for _, b in pairs],
            'csv_median_s': statistics.median(a for a, _ in pairs),
            'packets_median_s': statistics.median(b for _, b in pairs),
            'ratio_median': statistics.median(b / a for a, b in pairs),
            'csv_cpu_s': [a for a, _ in cpu], 'packets_cpu_s': [b for _, b in cpu],
            'csv_cpu_median_s': statistics.median(a for a, _ in cpu),
            'packets_cpu_median_s': statistics.median(b for _, b in cpu),
            'cpu_ratio_median': statistics.median(b / a for a, b in cpu),
            'csv_bytes': csv.stat().st_size, 'packets_bytes': packets.stat().st_size,
            'same_events': same}


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run both parts; write JSON, plot and the docs/results.md section."""
    settings = _settings(quick)
    results: dict[str, Any] = {'quick': quick, 'goals': GOALS, 'settings': settings,
                               'load_average_before': list(os.getloadavg())}
    with tempfile.TemporaryDirectory(prefix='bench-ccsds-') as scratch:
        folder = pathlib.Path(scratch)
        results['decoder'] = decoder(folder, settings)
        print(f'  decoder: {results["decoder"]["vectorised_packets_per_s"]:.3g} packets/s '
              f'(reference {results["decoder"]["reference_packets_per_s"]:.3g})', flush=True)
        csv, packets = detect_files(folder, settings['detect_hours'])
        results['detect'] = detect_times(csv, packets, settings['detect_runs'])
        print(f'  detect: csv {results["detect"]["csv_median_s"]:.2f} s, packets '
              f'{results["detect"]["packets_median_s"]:.2f} s', flush=True)
    results['load_average_after'] = list(os.getloadavg())
    report.write_json(out_dir, 'ccsds', results)
    _plot(out_dir, results)
    report.update_section('ccsds', markdown(results))
    return results


def markdown(results: dict[str, Any]) -> str:
    """Return the docs/results.md section."""
    d, t = results['decoder'], results['detect']
    goal = GOALS['decoder_packets_per_s']

    def verdict(rate: float) -> str:
        return 'met' if rate >= goal else 'NOT met'

    rows = []
    for name, label, measured_on in (
            ('vectorised', 'vectorised decoder (walk + decode)', f'{d["packets"]:,} packets'),
            ('reader', 'whole reader (+ join on one time base)', f'{d["packets"]:,} packets'),
            ('reference', 'space-packet-parser (generator + parse_bytes)',
             f'first {d["reference_packets"]:,} packets')):
        wall, cpu = d[f'{name}_packets_per_s'], d[f'{name}_packets_per_cpu_s']
        rows.append([label, f'{wall:.3g}', f'{cpu:.3g}',
                     f'{measured_on}, median of {len(d[name]["wall_s"])}',
                     'reference' if name == 'reference' else
                     f'{verdict(wall)} (wall), {verdict(cpu)} (CPU)'])
    lines = [
        f'CCSDS space packets (issue 33). `python -m bench ccsds`'
        f'{" --quick (a smoke test, not a result)" if results["quick"] else ""}; load '
        f'average {results["load_average_before"][0]:.1f} before, '
        f'{results["load_average_after"][0]:.1f} after, on 2 shared cores: wall times '
        'include the waits for a core, CPU times (this process) do not.', '',
        report.table(['decoding fixed-layout containers', 'packets/s (wall)',
                      'packets/s (CPU)', 'measured on', 'goal >= 5 M/s'], rows), '',
        f'Vectorised over space-packet-parser: '
        f'{d["vectorised_packets_per_s"] / d["reference_packets_per_s"]:.0f}x (wall), '
        f'{d["vectorised_packets_per_cpu_s"] / d["reference_packets_per_cpu_s"]:.0f}x '
        '(CPU).', '',
        report.table(['`rwa-monitor detect`, same data', 'median wall (s)',
                      'median CPU (s)', 'file (MB)'], [
            ['CSV', f'{t["csv_median_s"]:.2f}', f'{t["csv_cpu_median_s"]:.2f}',
             f'{t["csv_bytes"] / 1e6:.1f}'],
            ['packets (.bin + XTCE + map)', f'{t["packets_median_s"]:.2f}',
             f'{t["packets_cpu_median_s"]:.2f}', f'{t["packets_bytes"] / 1e6:.1f}']]), '',
        f'Packets over CSV, median of {t["runs"]} per-pair ratios: wall '
        f'{t["ratio_median"]:.2f}, CPU {t["cpu_ratio_median"]:.2f} (goal <= '
        f'{GOALS["detect_ratio_packets_over_csv"]}: '
        f'{"met" if t["ratio_median"] <= GOALS["detect_ratio_packets_over_csv"] else "NOT met"}'
        f' on wall time); same events: {t["same_events"]}. Each run a fresh process '
        '(imports, read, detectors), the two commands in turn; the CSV and the packets hold '
        'the same values '
        '(the CSV read back, then written as packets). Plot: bench/results/ccsds.png.']
    return '\n'.join(lines)


def _plot(out_dir: pathlib.Path, results: dict[str, Any]) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    d, t = results['decoder'], results['detect']
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    names = ['vectorised', 'whole reader', 'space-packet-parser']
    x = np.arange(len(names))
    for shift, key, label in ((-0.2, 'packets_per_s', 'wall'), (0.2, 'packets_per_cpu_s', 'CPU')):
        left.bar(x + shift, [d[f'{n}_{key}'] for n in ('vectorised', 'reader', 'reference')],
                 width=0.4, label=label)
    left.set_xticks(x, names)
    left.axhline(GOALS['decoder_packets_per_s'], color='k', ls='--', label='goal 5 M/s')
    left.set_yscale('log')
    left.set_ylabel('packets / s')
    left.set_title('decoding fixed-layout packets')
    left.legend()
    right.plot(t['csv_s'], 'o-', label='CSV')
    right.plot(t['packets_s'], 's-', label='packets')
    right.set_xlabel('run (in turn)')
    right.set_ylabel('wall s')
    right.set_title('rwa-monitor detect, same data')
    right.legend()
    fig.tight_layout()
    out_dir.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_dir / 'ccsds.png', dpi=110)
    plt.close(fig)
