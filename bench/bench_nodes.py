"""``python -m bench nodes``: the ROS 2 nodes in one process (replay -> llr_detector).

Sections: throughput in wheel messages/s (JointState with 4 wheels each; EventsExecutor
and the SingleThreadedExecutor fallback); latency from the replay publishing the row that
completes a declaration to a subscriber receiving the anomaly (p50/p99), saturated
(rate 0) and at 100x real time; peak memory over a 24-hour 10 Hz replay, sampled along
the run in a fresh process (must stay flat). Results: bench/results/nodes.json and the
``nodes`` section of docs/results.md.
"""

from __future__ import annotations

import multiprocessing
import os
import pathlib
import random
import time
from typing import Any

import numpy as np

from bench import nodes_chain, report

GOALS = {'throughput_per_s': 10_000}
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
# Reference from the environment notes (CONVENTIONS.md): JointState messages/s moved in
# one process by each executor, without a detector.
REFERENCE_PER_S = {'events': 11_500, 'single': 2_500}


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'throughput_hours': {'events': 0.5, 'single': 0.1},
                'latency_passes': {0.0: 3, 100.0: 2}, 'memory_hours': 2.0,
                'memory_samples': 5, 'repeats': 1}
    return {'throughput_hours': {'events': 3.0, 'single': 0.5},
            'latency_passes': {0.0: 25, 100.0: 10}, 'memory_hours': 24.0,
            'memory_samples': 12, 'repeats': 3}


def _telemetry(hours: float, seed: int = 7, anomalies: bool = True) -> Any:
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    duration = hours * 3600.0
    steps = [Anomaly('rw2', 'dry', round(duration / 3), delta_dry=2.0e-4),
             Anomaly('rw3', 'viscous', round(2 * duration / 3), delta_viscous=1.0e-6)]
    tele, _ = simulate_friction_with_truth(wheels=list(WHEELS), duration_s=duration,
                                           rate_hz=10.0, seed=seed,
                                           anomalies=steps if anomalies else ())
    return tele


class _System:
    """Replay + llr_detector (+ an anomaly listener) in one process on a private domain."""

    def __init__(self, tele: Any, executor: str, rate: float = 0.0, loop: bool = False,
                 burst: int = 50) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.logging import LoggingSeverity
        from rclpy.parameter import Parameter

        from rwa_monitor.nodes.llr_detector import LLRDetectorNode
        from rwa_monitor.nodes.replay import TelemetryReplay
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        self.context = Context()
        rclpy.init(context=self.context, domain_id=random.randint(201, 230))
        if executor == 'events':
            from rclpy.experimental import EventsExecutor
            self.executor = EventsExecutor(context=self.context)
        else:
            self.executor = SingleThreadedExecutor(context=self.context)
        self.detector = LLRDetectorNode(context=self.context, parameter_overrides=[
            Parameter('use_sim_time', value=True)])
        self.replay = TelemetryReplay(context=self.context, telemetry=tele, parameter_overrides=[
            Parameter('rate', value=rate), Parameter('loop', value=loop),
            Parameter('burst', value=burst if executor == 'events' else 1),
            Parameter('min_subscribers', value=1), Parameter('exit_when_done', value=False)])
        self.nodes = [self.detector, self.replay]
        for node in self.nodes:
            node.get_logger().set_level(LoggingSeverity.ERROR)
            self.executor.add_node(node)
        self.rows = len(tele)

    def add(self, node: Any) -> None:
        self.nodes.append(node)
        self.executor.add_node(node)

    def samples(self) -> int:
        return sum(w.samples for w in self.detector.wheels.values())

    def spin_until(self, predicate: Any, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.1)
        return True

    def close(self) -> None:
        import rclpy
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def throughput(hours: float, executor: str) -> dict[str, Any]:
    """Replay ``hours`` of 4-wheel telemetry as fast as the detector takes it."""
    tele = _telemetry(hours)
    system = _System(tele, executor)
    expected = len(tele) * len(WHEELS)
    try:
        system.spin_until(lambda: system.replay.published > 0, 30.0)
        start = time.perf_counter()
        done = system.spin_until(lambda: system.samples() >= expected, 1800.0)
        wall = time.perf_counter() - start
        lost = expected - system.samples()
    finally:
        system.close()
    return {'executor': executor, 'rows': len(tele), 'wall_s': wall, 'complete': done,
            'lost_samples': lost, 'wheel_messages_per_s': len(tele) / wall,
            'wheel_samples_per_s': expected / wall}


def latency(passes: int, rate: float) -> dict[str, Any]:
    """Seconds from publishing the declaring row to receiving its anomaly message.

    A 10-minute file with a dry step on each wheel (at 200, 300, 400 and 500 s, so that
    declarations do not coincide) is replayed in a loop (each pass restarts the
    detectors: a time jump backwards), so every pass gives new events. The delay is also
    split at the detector's ``publish`` of the anomaly: row -> detector (executor queue
    and the detector's work on that row) and detector -> subscriber (DDS delivery and
    the executor queue in front of the subscriber).
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import EVENTS_QOS
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    tele, _ = simulate_friction_with_truth(
        wheels=list(WHEELS), duration_s=600.0, rate_hz=10.0, seed=3,
        anomalies=[Anomaly(w, 'dry', 200.0 + 100.0 * i, delta_dry=3.0e-4)
                   for i, w in enumerate(WHEELS)])
    system = _System(tele, 'events', rate=rate, loop=True)
    published: dict[tuple[int, int], float] = {}
    detected: dict[tuple[int, int], float] = {}
    delays: list[tuple[float, float, float]] = []

    def wrap(publisher: Any, record: Any) -> None:
        plain = publisher.publish

        def timed(msg: Any) -> None:
            record(msg, time.perf_counter())
            plain(msg)
        publisher.publish = timed

    def row_published(msg: Any, now: float) -> None:
        published[messages.split_seconds(messages.decode_joint_state(msg)[0])] = now

    def declared(fields: dict[str, Any]) -> tuple[int, int]:
        return messages.split_seconds(fields['declaration_time_s'])

    def anomaly_published(msg: Any, now: float) -> None:
        for status in msg.status:
            detected[declared(messages.status_fields(status))] = now
    wrap(system.replay._wheels_pub, row_published)
    wrap(system.detector._anomaly_pub, anomaly_published)

    def received(msg: Any) -> None:
        now = time.perf_counter()
        for status in msg.status:
            key = declared(messages.status_fields(status))
            if key in published and key in detected:
                delays.append((now - published[key], detected[key] - published[key],
                               now - detected[key]))
    listener = Node('latency_listener', context=system.context)
    listener.create_subscription(DiagnosticArray, 'anomalies', received, EVENTS_QOS)
    system.add(listener)
    try:
        system.spin_until(lambda: system.replay.loops >= passes, 600.0)
    finally:
        system.close()
    arr = np.array(delays).reshape(-1, 3) * 1e3
    if not arr.size:
        return {'rate': rate, 'events': 0, 'passes': passes}
    return {'rate': rate, 'events': int(arr.shape[0]), 'passes': passes,
            'p50_ms': float(np.percentile(arr[:, 0], 50)),
            'p99_ms': float(np.percentile(arr[:, 0], 99)), 'max_ms': float(arr[:, 0].max()),
            'to_detector_p50_ms': float(np.percentile(arr[:, 1], 50)),
            'to_subscriber_p50_ms': float(np.percentile(arr[:, 2], 50))}


def _rss_mb(field: str = 'VmRSS') -> float:
    with open('/proc/self/status') as handle:
        for line in handle:
            if line.startswith(field + ':'):
                return int(line.split()[1]) / 1024.0
    return float('nan')


def _memory_child(hours: float, samples: int, queue: Any) -> None:
    tele = _telemetry(hours)
    loaded = _rss_mb()
    system = _System(tele, 'events')
    expected = len(tele) * len(WHEELS)
    trace = []
    start = time.perf_counter()
    try:
        for k in range(1, samples + 1):
            target = expected * k // samples
            system.spin_until(lambda: system.samples() >= target, 3600.0)
            trace.append({'fraction': k / samples, 'rss_mb': _rss_mb(),
                          'wall_s': time.perf_counter() - start})
    finally:
        system.close()
    queue.put({'hours': hours, 'rows': len(tele), 'rss_after_load_mb': loaded,
               'trace': trace, 'peak_mb': _rss_mb('VmHWM')})


def memory(hours: float, samples: int) -> dict[str, Any]:
    """Resident memory along a ``hours`` replay, in a fresh process."""
    ctx = multiprocessing.get_context('spawn')
    queue = ctx.Queue()
    proc = ctx.Process(target=_memory_child, args=(hours, samples, queue))
    proc.start()
    result = queue.get(timeout=7200)
    proc.join(timeout=60)
    trace = result['trace']
    first, last = trace[0]['rss_mb'], trace[-1]['rss_mb']
    result['growth_after_first_sample_mb'] = last - first
    result['flat'] = abs(last - first) < 0.05 * first
    return result


def _plot(out_dir: pathlib.Path, mem: dict[str, Any]) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5, 3))
    hours = mem['hours']
    ax.plot([p['fraction'] * hours for p in mem['trace']],
            [p['rss_mb'] for p in mem['trace']], 'o-')
    ax.set_xlabel('telemetry replayed (h)')
    ax.set_ylabel('resident memory (MB)')
    ax.set_ylim(0, 1.2 * max(p['rss_mb'] for p in mem['trace']))
    ax.set_title('replay -> llr_detector, 4 wheels, 10 Hz')
    fig.tight_layout()
    fig.savefig(out_dir / 'nodes_memory.png', dpi=120)
    plt.close(fig)


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run every section; write JSON, plot and the docs/results.md section."""
    settings = _settings(quick)
    load_before = os.getloadavg()[0]
    results: dict[str, Any] = {'quick': quick, 'goals': GOALS}
    results['throughput'] = []
    for executor, repeats in (('events', settings['repeats']), ('single', 1)):
        runs = [throughput(settings['throughput_hours'][executor], executor)
                for _ in range(repeats)]
        rates = [r['wheel_messages_per_s'] for r in runs]
        best = runs[int(np.argmax(rates))]
        results['throughput'].append({**best, 'runs': rates,
                                      'median_per_s': float(np.median(rates))})
        print(f'  throughput {executor}: {[round(x) for x in rates]}', flush=True)
    results['latency'] = [latency(passes, rate)
                          for rate, passes in settings['latency_passes'].items()]
    print('  latency:', results['latency'], flush=True)
    results['memory'] = memory(settings['memory_hours'], settings['memory_samples'])
    print('  memory:', results['memory']['trace'][-1], flush=True)
    results['chain'] = nodes_chain.section(quick, os.environ.get('RWA_BENCH_NODES_BASE'))
    results['load_average'] = {'before': load_before, 'after': os.getloadavg()[0]}
    report.write_json(out_dir, 'nodes', results)
    _plot(out_dir, results['memory'])
    report.update_section('nodes', markdown(results))
    return results


def markdown(results: dict[str, Any]) -> str:
    """Return the ``nodes`` section of docs/results.md."""
    lines = ['## ROS 2 nodes (replay -> llr_detector, one process)', '',
             f'`python -m bench nodes`{" --quick" if results["quick"] else ""}; 4 wheels '
             'per JointState, 10 Hz seeded telemetry (dry step on rw2, viscous on rw3), '
             'replay at rate 0 (as fast as the detector takes it). Load average of the '
             f'2-core machine: {results["load_average"]["before"]:.1f} before, '
             f'{results["load_average"]["after"]:.1f} after'
             f'{" (other jobs were running)" if results["load_average"]["before"] > 1.5 else ""}'
             '.', '']
    rows = []
    for r in results['throughput']:
        runs = ', '.join(str(round(x)) for x in r['runs'])
        rows.append([f'throughput, {r["executor"]} executor (wheel messages/s, best of '
                     f'{len(r["runs"])})',
                     f'>= {GOALS["throughput_per_s"]}' if r['executor'] == 'events' else '-',
                     round(r['wheel_messages_per_s']),
                     f'{REFERENCE_PER_S[r["executor"]]} (no detector)',
                     f'runs: {runs}; {r["rows"]} msgs, {r["lost_samples"]} samples lost'])
    for r in results['latency']:
        label = 'rate 0 (saturated)' if r['rate'] == 0 else f'rate {r["rate"]:g}x real time'
        split = (f'; p50 split: {r["to_detector_p50_ms"]:.1f} row -> detector publish, '
                 f'{r["to_subscriber_p50_ms"]:.1f} -> subscriber'
                 if 'to_detector_p50_ms' in r else '')
        rows.append([f'publish -> anomaly latency p50 / p99 / max (ms), {label}', '-',
                     f'{r["p50_ms"]:.1f} / {r["p99_ms"]:.1f} / {r["max_ms"]:.1f}'
                     if r['events'] else 'n/a', '-', f'{r["events"]} events{split}'])
    mem = results['memory']
    trace = mem['trace']
    rows.append([f'resident memory over a {mem["hours"]:g} h replay (MB)', 'flat',
                 f'{trace[0]["rss_mb"]:.0f} at {100 * trace[0]["fraction"]:.0f}% -> '
                 f'{trace[-1]["rss_mb"]:.0f} at 100%', '-',
                 f'peak {mem["peak_mb"]:.0f} MB; {mem["rows"]} rows; '
                 f'{"flat" if mem["flat"] else "GROWS"}'])
    lines.append(report.table(['measure', 'goal', 'measured', 'reference', 'notes'], rows))
    lines += ['', 'The reference rates (CONVENTIONS.md) are rclpy moving generated JointState '
              'messages without a detector; the nodes exchange hand-encoded CDR bytes '
              '(docs/nodes.md, "Hot path"), which is why the events executor with the LLR '
              'detector runs faster than that reference. The single-threaded fallback needs '
              'replay burst 1 (one row per executor turn) and rebuilds its wait set for each '
              'callback. Latency is measured from the replay publishing the row that completes '
              'a declaration to a subscriber in the same process receiving the anomaly: it '
              'includes the queue of telemetry ahead of it in the executor and DDS delivery.',
              '', 'Memory trace: `bench/results/nodes_memory.png`; the telemetry itself '
              f'({mem["rss_after_load_mb"]:.0f} MB resident after generating it) is '
              'held by the replay.']
    verdict = results['throughput'][0]['wheel_messages_per_s'] >= GOALS['throughput_per_s']
    lines.append(f'Throughput goal {"met" if verdict else "NOT met"} on this run.')
    if results.get('chain'):
        lines += ['', '### Process chain over DDS (issue 27, item 3)', '',
                  'The documented commands (docs/usage.md): replay at rate 0 into '
                  'llr_detector, vsadc_detector and fss_diagnoser, each its own process, with '
                  'the shipped parameters file; a 4-wheel bus-like recording (four wheels at '
                  '10 Hz with gyro, star tracker and reference rate on every row, '
                  f'{results["chain"]["rows"]} rows). Rows/s: the slope of each node\'s own '
                  'counter of rows received on /diagnostics (every 0.2 s), the slowest node; '
                  'CPU per row: each process over the run (bench/nodes_chain.py). "Before" is '
                  'the code of `RWA_BENCH_NODES_BASE` (main 09648a8), run alternately with '
                  'the new code on the same shared machine.', '']
        lines += nodes_chain.markdown(results['chain'])
    return '\n'.join(lines)
