"""The process chain of docs/usage.md over DDS: replay -> llr, vsadc, fss (one process each).

A 4-wheel bus-like recording (four wheels at 10 Hz with gyro, star tracker and reference
rate on every row) is written to a CSV file; each detector is started as its own OS
process with the documented command (console script, ``--params-file`` of the shipped
configuration), then the replay at rate 0. This process listens to ``/diagnostics`` on the
same (private) domain and reads each node's own counter of rows received (llr_detector
and fss_diagnoser: ``messages`` of ``telemetry/wheels``; vsadc_detector: ``gyro_messages``)
until every node has counted every row the replay published.

Throughput (rows/s) of a node is the slope of its counter between the first status that
shows at least 5 % of the rows and the status that shows them all; the system's is the
lowest of the nodes (every row must be processed by every detector). The CPU time of
each process between the replay's start and the end gives the CPU per row.
"""

from __future__ import annotations

import os
import pathlib
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any

WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
RATE_HZ = 10.0
# The console script of each node, and the status (hardware_id, key) with its row count.
SEPARATE = {'llr_detector': 'rwa-monitor-llr', 'vsadc_detector': 'rwa-monitor-vsadc',
            'fss_diagnoser': 'rwa-monitor-fss'}
COUNTERS = {'llr_detector': ('telemetry/wheels', 'messages'),
            'fss_diagnoser': ('telemetry/wheels', 'messages'),
            'vsadc_detector': ('gyro_star_tracker', 'gyro_messages')}
DIAGNOSTIC_PERIOD = 0.2   # s, so that the counters' slope is read finely


def recording(rows: int, seed: int = 7) -> Any:
    """Return four wheels at 10 Hz (dry step on rw2) with gyro, star tracker, reference."""
    from rwa_monitor.sim.aocs import named_fault, simulate_aocs
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    seconds = rows / RATE_HZ
    tele, _ = simulate_friction_with_truth(
        wheels=list(WHEELS), n_samples=rows, rate_hz=RATE_HZ, seed=seed,
        anomalies=[Anomaly('rw2', 'dry', seconds / 4, delta_dry=3e-4)])
    gyro = simulate_aocs(float(tele.time[-1]), seed=seed, time=tele.time,
                         fault=named_fault('bias', 'y', seconds / 2))
    tele.gyro, tele.attitude = gyro.gyro, gyro.attitude
    tele.reference_rate = gyro.reference_rate
    return tele


def _script(name: str) -> str:
    path = shutil.which(name, path=os.path.dirname(sys.executable))
    if path is None:
        raise RuntimeError(f'console script {name} is not installed next to {sys.executable}')
    return path


def _cpu_s(pid: int) -> float:
    """Return the user + system CPU seconds of process ``pid`` and its waited children."""
    try:
        fields = pathlib.Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return float('nan')
    return sum(int(v) for v in fields[11:15]) / os.sysconf('SC_CLK_TCK')


class _Listener:
    """A node of this process reading the counters on /diagnostics."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from diagnostic_msgs.msg import DiagnosticArray
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node('chain_bench_listener', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.counts: dict[str, list[tuple[float, int]]] = {}
        self.published = 0
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_status, 50)

    def _on_status(self, msg: Any) -> None:
        now = time.monotonic()
        for status in msg.status:
            node = status.name.split(':', 1)[0]
            values = {kv.key: kv.value for kv in status.values}
            if status.hardware_id == 'replay' and 'rows_published' in values:
                self.published = int(values['rows_published'])
            for name, (hardware_id, key) in COUNTERS.items():
                if node.endswith(name) and status.hardware_id == hardware_id and key in values:
                    self.counts.setdefault(name, []).append((now, int(values[key])))

    def last(self, name: str) -> int:
        samples = self.counts.get(name)
        return samples[-1][1] if samples else -1

    def spin_until(self, predicate: Any, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def close(self) -> None:
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _slope(samples: list[tuple[float, int]], rows: int) -> float:
    """Return rows/s between the first sample >= 5 % of ``rows`` and the final count."""
    if not samples:
        return float('nan')
    final = samples[-1][1]
    start = next((s for s in samples if s[1] >= 0.05 * rows), None)
    end = next(s for s in samples if s[1] >= final)
    if start is None or end is None or end[0] <= start[0]:
        return float('nan')
    return (end[1] - start[1]) / (end[0] - start[0])


def _settled(listener: _Listener, replay: subprocess.Popen, quiet_s: float = 5.0) -> bool:
    """Return True when the replay has exited and no counter moved for ``quiet_s`` s."""
    if replay.poll() is None:
        return False
    now = time.monotonic()
    for name in COUNTERS:
        samples = listener.counts.get(name, [])
        last_change = next((t for t, n in samples if n == samples[-1][1]), now)
        if now - last_change < quiet_s:
            return False
    return True


PROFILE_S = 8


def _profile(procs: dict[str, subprocess.Popen], out: pathlib.Path | None) -> list:
    """Start py-spy on every process (``--native``: time in rclpy's C layer shows too)."""
    if out is None:
        return []
    out.mkdir(parents=True, exist_ok=True)
    spy = _script('py-spy')
    return [subprocess.Popen([spy, 'record', '--native', '--format', 'raw', '-r', '200',
                              '-d', str(int(PROFILE_S)), '-p', str(p.pid),
                              '-o', str(out / f'{name}.txt')],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for name, p in procs.items()]


def _stop(proc: subprocess.Popen) -> str:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=15)
    return proc.stdout.read().decode(errors='replace') if proc.stdout else ''


def run_chain(rows: int, composed: bool = False, pythonpath: str | None = None,
              timeout_s: float = 600.0, replay_args: tuple[str, ...] = (),
              profile_dir: pathlib.Path | None = None) -> dict[str, Any]:
    """Run the chain once on ``rows`` rows; return rates, counts, CPU per row, load.

    ``composed``: the three detectors in one process (``rwa-monitor-monitor``) instead of
    one process each. ``pythonpath`` runs the nodes of another checkout (the before/after
    comparison of docs/results.md). ``replay_args``: extra ``-p`` settings of the replay.
    ``profile_dir``: sample every process with py-spy for ``PROFILE_S`` seconds from the
    replay's start (collapsed stacks, one file per process).
    """
    from rwa_monitor.telemetry import write_telemetry
    repo = pathlib.Path(__file__).resolve().parent.parent
    code = pathlib.Path(pythonpath or repo)
    config = code / 'config' / 'rwa_monitor.yaml'
    domain_id = random.randint(201, 232)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONPATH=str(code),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
    workdir = pathlib.Path(tempfile.mkdtemp(prefix='rwa_chain_'))
    path = workdir / 'bus.csv'
    write_telemetry(path, recording(rows))
    if composed:
        commands = {'monitor': [sys.executable, '-m', 'rwa_monitor.nodes.monitor']}
    else:
        commands = {name: [_script(script)] for name, script in SEPARATE.items()}
    procs: dict[str, subprocess.Popen] = {}
    listener = _Listener(domain_id)
    result: dict[str, Any] = {'rows': rows, 'composed': composed,
                              'load_before': os.getloadavg()[0]}
    try:
        for name, command in commands.items():
            args = [*command, '--ros-args', '--params-file', str(config)]
            for node in SEPARATE:
                args += ['-p', f'{node}:diagnostic_period:={DIAGNOSTIC_PERIOD}',
                         '-p', f'{node}:stale_timeout:=60.0']
            procs[name] = subprocess.Popen(args, env=env, stdout=subprocess.PIPE,
                                           stderr=subprocess.STDOUT, cwd=workdir)
        if not listener.spin_until(lambda: all(listener.last(n) >= 0 for n in COUNTERS),
                                   300.0):
            raise RuntimeError('a detector did not start: '
                               + ', '.join(n for n in COUNTERS if listener.last(n) < 0))
        cpu0 = {name: _cpu_s(p.pid) for name, p in procs.items()}
        start = time.monotonic()
        procs['replay'] = subprocess.Popen(
            [_script('rwa-monitor-replay'), '--ros-args', '-p', f'file:={path}',
             '-p', 'rate:=0.0', *replay_args],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=workdir)
        profilers = _profile(procs, profile_dir)
        replay_cpu = [0.0]

        def finished() -> bool:
            if procs['replay'].poll() is None:   # its CPU time, while /proc still has it
                replay_cpu[0] = max(replay_cpu[0], _cpu_s(procs['replay'].pid))
            return (all(listener.last(n) >= rows for n in COUNTERS)
                    or _settled(listener, procs['replay']))
        done = listener.spin_until(finished, timeout_s)
        listener.spin_until(lambda: False, 3 * DIAGNOSTIC_PERIOD)  # the last counts
        done = all(listener.last(n) >= rows for n in COUNTERS)
        for profiler in profilers:
            profiler.wait(timeout=120)
        cpu = {name: _cpu_s(p.pid) - cpu0.get(name, 0.0) for name, p in procs.items()}
        if procs['replay'].poll() is not None:
            cpu['replay'] = replay_cpu[0]   # up to the last poll before it exited
        result.update({
            'complete': done, 'wall_s': time.monotonic() - start,
            'published': listener.published,
            'counted': {n: listener.last(n) for n in COUNTERS},
            'rows_per_s_by_node': {n: _slope(listener.counts[n], rows) for n in COUNTERS},
            'cpu_ms_per_row': {n: 1e3 * c / rows for n, c in cpu.items()}})
        result['rows_per_s'] = min(result['rows_per_s_by_node'].values())
    finally:
        logs = {name: _stop(p) for name, p in procs.items()}
        listener.close()
        shutil.rmtree(workdir, ignore_errors=True)
    result['load_after'] = os.getloadavg()[0]
    result['tracebacks'] = [n for n, log in logs.items() if 'Traceback' in log]
    if result['tracebacks'] or not result.get('complete'):
        result['logs'] = {n: log[-3000:] for n, log in logs.items()}
    return result


GOAL_ROWS_PER_S = 3000


def section(quick: bool, base: str | None) -> dict[str, Any]:
    """Run the chain before (``base`` checkout, if given) and after, interleaved; composed.

    Before and after alternate so that both see the same load of the shared machine; the
    ratio of each pair is reported beside the medians. The code before has no subscriber
    wait at rate > 0 and counts only ``telemetry/wheels`` subscribers, so its replay gets
    ``min_subscribers`` 2 (llr and fss), as close to "started after the detectors" as it
    can be told.
    """
    rows = 10_000 if quick else 36_000
    repeats = 1 if quick else 3
    out: dict[str, Any] = {'rows': rows, 'base': base, 'before': [], 'after': [],
                           'composed': []}
    for _ in range(repeats):
        if base:
            out['before'].append(run_chain(rows, pythonpath=base,
                                           replay_args=('-p', 'min_subscribers:=2')))
            print(f'  chain before: {out["before"][-1]["rows_per_s"]:.0f}', flush=True)
        out['after'].append(run_chain(rows))
        print(f'  chain after: {out["after"][-1]["rows_per_s"]:.0f}', flush=True)
    for _ in range(max(1, repeats - 1)):
        out['composed'].append(run_chain(rows, composed=True))
        print(f'  chain composed: {out["composed"][-1]["rows_per_s"]:.0f}', flush=True)
    return out


def _median(runs: list[dict[str, Any]], key: str = 'rows_per_s') -> float:
    values = sorted(r[key] for r in runs)
    return values[len(values) // 2] if values else float('nan')


def markdown(chain: dict[str, Any]) -> list[str]:
    """Return the lines of the process-chain table of docs/results.md."""
    from bench import report
    rows = []
    labels = {'before': 'separate processes, code before (SingleThreadedExecutor)',
              'after': 'separate processes (docs/usage.md commands)',
              'composed': 'rwa-monitor-monitor (3 detectors in 1 process) + replay'}
    for key, label in labels.items():
        runs = chain[key]
        if not runs:
            continue
        lost = {n: chain['rows'] - c for r in runs for n, c in r['counted'].items()
                if c < chain['rows']}
        cpu = {n: sum(r['cpu_ms_per_row'][n] for r in runs) / len(runs)
               for n in runs[0]['cpu_ms_per_row']}
        loads = ', '.join(f'{r["load_before"]:.1f}' for r in runs)
        rows.append([label, f'>= {GOAL_ROWS_PER_S}' if key != 'before' else '-',
                     f'{_median(runs):.0f}',
                     ', '.join(f'{r["rows_per_s"]:.0f}' for r in runs),
                     ' / '.join(f'{n} {v:.3f}' for n, v in cpu.items()),
                     f'{sum(r["complete"] for r in runs)}/{len(runs)}'
                     + (f'; short: {lost}' if lost else ''), loads])
    lines = [report.table(['chain', 'goal', 'rows/s (median)', 'runs', 'CPU ms per row',
                           'every row counted by every node', 'load at start'], rows)]
    pairs = list(zip(chain['before'], chain['after']))
    if pairs:
        ratios = [a['rows_per_s'] / b['rows_per_s'] for b, a in pairs]
        lines += ['', 'After / before, run by run (interleaved, same load): '
                  + ', '.join(f'x{r:.2f}' for r in ratios) + '.']
    lines += ['', 'Load: the 1-minute load average of the 2-core machine when each run started '
              '(other sessions share it, and it includes the previous run of this bench). The '
              'CPU of the replay includes its start (imports, reading the file). The composed '
              'monitor needs about half the CPU per row of the three processes but runs its '
              'three nodes on one core, so its rate depends more on what else runs.']
    return lines


if __name__ == '__main__':
    import json
    print(json.dumps(run_chain(
        int(sys.argv[1]) if len(sys.argv) > 1 else 36_000,
        pythonpath=os.environ.get('CHAIN_CODE'),
        replay_args=tuple(os.environ.get('CHAIN_REPLAY_ARGS', '').split()),
        profile_dir=pathlib.Path(os.environ['CHAIN_PROFILE'])
        if os.environ.get('CHAIN_PROFILE') else None), indent=1))
