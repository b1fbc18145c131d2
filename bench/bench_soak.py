"""``python -m bench soak``: every node under sustained load, with kills and bad input.

A recording with four wheels (a dry friction step on rw2) and gyro/star tracker (a bias
on gyro_y) is replayed at rate 0 (as fast as the subscribers take it, back-pressure, so
the highest sustained rate) and in a loop into the llr_detector, vsadc_detector and
fss_diagnoser nodes, each an OS process with an ``events_file`` journal; DDS stays on
this host. During the run each detector is killed once with SIGKILL and restarted, and
a burst of malformed messages is published on every input topic. A monitor (this
process) subscribes ``anomalies`` and ``/diagnostics`` from the start.

Reported (bench/results/soak.json, section ``soak`` of docs/results.md): sustained
rows/s of the whole system (wheel rows received by llr_detector per second of wall
time), messages lost per node (rows the replay published that a node did not receive;
includes the rows published while that node was killed), anomalies lost (declared in a
journal but never received by the monitor: must be 0), anomaly components of the file
never reported, crashes (a node that exited by itself, a non-zero exit code or a
traceback: must be 0), resident memory of each node at start and end (last
incarnation), and /diagnostics messages and statuses per second.
"""

from __future__ import annotations

import json
import math
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

from bench import report

NODES = {'llr': 'rwa-monitor-llr', 'vsadc': 'rwa-monitor-vsadc', 'fss': 'rwa-monitor-fss'}
NODE_NAMES = {'llr': 'llr_detector', 'vsadc': 'vsadc_detector', 'fss': 'fss_diagnoser'}
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
SEED = 1000  # fresh seed (development used 1-99)


def _settings(quick: bool) -> dict[str, Any]:
    if quick:
        return {'duration_s': 60.0, 'file_hours': 0.1, 'burst': 200, 'fss_window': 1000}
    return {'duration_s': 600.0, 'file_hours': 3.0, 'burst': 2000, 'fss_window': 20000}


def recording(hours: float, seed: int) -> Any:
    """Return four wheels at 10 Hz (dry step on rw2) with gyro/star tracker (bias on y)."""
    from rwa_monitor.sim.aocs import named_fault, simulate_aocs
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    n = int(hours * 3600 * 10)
    wheels, _ = simulate_friction_with_truth(
        wheels=list(WHEELS), n_samples=n, rate_hz=10.0, seed=seed,
        anomalies=[Anomaly('rw2', 'dry', hours * 3600 / 3, delta_dry=3e-4)])
    gyro = simulate_aocs(float(wheels.time[-1]), seed=seed, time=wheels.time,
                         fault=named_fault('bias', 'y', hours * 3600 / 2))
    wheels.gyro, wheels.attitude = gyro.gyro, gyro.attitude
    wheels.reference_rate = gyro.reference_rate
    return wheels


def _script(name: str) -> str:
    path = shutil.which(name, path=os.path.dirname(sys.executable))
    if path is None:
        raise RuntimeError(f'console script {name} not found next to {sys.executable}')
    return path


def _rss_mb(pid: int) -> float:
    try:
        for line in pathlib.Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


class _Proc:
    """One node process and its incarnations."""

    def __init__(self, key: str, args: list[str], env: dict[str, str], log_dir: pathlib.Path):
        self.key, self.args, self.env, self.log_dir = key, args, env, log_dir
        self.incarnation = 0
        self.proc: subprocess.Popen | None = None
        self.crashes: list[str] = []
        self.rss: list[tuple[float, float]] = []
        self.started = 0.0

    def start(self) -> None:
        self.incarnation += 1
        log = (self.log_dir / f'{self.key}.{self.incarnation}.log').open('w')
        self.proc = subprocess.Popen(self.args, env=self.env, stdout=log,
                                     stderr=subprocess.STDOUT)
        self.started = time.monotonic()
        self.rss = []

    def kill9(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)

    def check_alive(self) -> None:
        if self.proc is not None and self.proc.poll() is not None:
            self.crashes.append(f'{self.key} exited by itself with {self.proc.returncode}')
            self.start()

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.crashes.append(f'{self.key} did not stop on SIGTERM')
            return
        if code != 0:
            self.crashes.append(f'{self.key} exit code {code} on SIGTERM')

    def tracebacks(self) -> list[str]:
        out = []
        for log in sorted(self.log_dir.glob(f'{self.key}.*.log')):
            text = log.read_text(errors='replace')
            if 'Traceback' in text or 'RCLError' in text:
                out.append(f'{log.name}: traceback')
        return out


def _malformed(node: Any, count: int) -> dict[str, int]:
    """Publish ``count`` bad messages on each input topic; return how many per topic."""
    from geometry_msgs.msg import QuaternionStamped
    from sensor_msgs.msg import Imu, JointState

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import telemetry_qos
    rng = random.Random(SEED)
    wheels = node.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
    gyro = node.create_publisher(Imu, 'telemetry/gyro', telemetry_qos())
    star = node.create_publisher(QuaternionStamped, 'telemetry/star_tracker', telemetry_qos())
    time.sleep(1.0)
    for i in range(count):
        msg = JointState()
        msg.header.stamp = messages.to_stamp(rng.uniform(0.0, 1e4))
        case = i % 4
        msg.name = [['rw1', 'rw2'], ['', 'rw1'], ['rw1', 'rw1'], ['rw1']][case]
        msg.velocity = [[1.0], [float('nan'), 1.0], [1.0, 2.0], [float('inf')]][case]
        msg.effort = [[1e-3, 2e-3], [1e-3, 1e-3], [1e-3, 1e-3], [1e5]][case]
        wheels.publish(msg)
        g = messages.imu(rng.uniform(0.0, 1e4), [float('nan'), 1e30, -0.0])
        gyro.publish(g)
        star.publish(messages.quaternion(rng.uniform(0.0, 1e4), [0.0, 0.0, 0.0, 0.0]))
    return {'telemetry/wheels': count, 'telemetry/gyro': count,
            'telemetry/star_tracker': count}


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run the soak; write soak.json and the ``soak`` section; return the results."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS
    from rwa_monitor.pipelines import llr, vsadc
    from rwa_monitor.telemetry import write_telemetry

    cfg = _settings(quick)
    work = pathlib.Path(tempfile.mkdtemp(prefix='rwa_soak_'))
    tele = recording(cfg['file_hours'], SEED)
    path = work / 'soak.csv'
    write_telemetry(path, tele)
    expected = {e.component for e in llr.run(tele, {})} | \
        {e.component for e in vsadc.run(tele, {}) if e.kind != 'healthy'}
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(random.SystemRandom().randint(150, 200)))
    journals = {k: work / f'{k}.jsonl' for k in NODES}
    extra = {'llr': [], 'vsadc': [],
             'fss': ['-p', f'window_length:={cfg["fss_window"]}',
                     '-p', f'window_period:={cfg["fss_window"] // 2}']}
    procs = {k: _Proc(k, [_script(NODES[k]), '--ros-args', '-p',
                          f'events_file:={journals[k]}', '-p', 'stale_timeout:=30.0',
                          *extra[k]], env, work) for k in NODES}
    replay = _Proc('replay', [_script('rwa-monitor-replay'), '--ros-args',
                              '-p', f'file:={path}', '-p', 'rate:=0.0', '-p', 'loop:=true',
                              '-p', 'burst:=20', '-p', 'min_subscribers:=2'], env, work)

    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    context = Context()
    rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']))
    monitor = Node('soak_monitor', context=context)
    received: set[tuple] = set()
    diag = {'messages': 0, 'statuses': 0}
    counters: dict[tuple[str, int], dict[str, Any]] = {}
    incarnation = {}

    def on_anomalies(msg: Any) -> None:
        for status in msg.status:
            e = messages.status_event(status)
            received.add((e.detector, e.component, e.index, e.kind))

    def on_diagnostics(msg: Any) -> None:
        diag['messages'] += 1
        diag['statuses'] += len(msg.status)
        for status in msg.status:
            node = status.name.split(':', 1)[0]
            key = {**{v: k for k, v in NODE_NAMES.items()}, 'telemetry_replay': 'replay'}.get(
                node, node)
            if status.hardware_id in ('telemetry/wheels', 'gyro_star_tracker', 'replay'):
                counters[(key, incarnation.get(key, 1))] = messages.status_fields(status)

    monitor.create_subscription(DiagnosticArray, 'anomalies', on_anomalies, EVENTS_QOS)
    monitor.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics,
                                DIAGNOSTICS_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(monitor)

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
            for p in procs.values():
                p.check_alive()
                incarnation[p.key] = p.incarnation
                if p.proc and time.monotonic() - p.started > 15.0 and (
                        not p.rss or time.monotonic() - p.rss[-1][0] > 5.0):
                    p.rss.append((time.monotonic(), _rss_mb(p.proc.pid)))

    seen_nodes: set[str] = set()

    def note_nodes(msg: Any) -> None:
        seen_nodes.update(status.name.split(':', 1)[0] for status in msg.status)

    monitor.create_subscription(DiagnosticArray, '/diagnostics', note_nodes, DIAGNOSTICS_QOS)
    for p in procs.values():
        p.start()
    ready_by = time.monotonic() + 180.0      # start-up can be slow on a loaded machine
    while not set(NODE_NAMES.values()) <= seen_nodes and time.monotonic() < ready_by:
        spin(0.5)
    results_startup = sorted(seen_nodes)
    replay.start()
    start = time.monotonic()
    duration = cfg['duration_s']
    schedule = [(0.3, 'kill', 'llr'), (0.4, 'burst', None), (0.5, 'kill', 'vsadc'),
                (0.7, 'kill', 'fss')]
    burst: dict[str, int] = {}
    for fraction, action, key in schedule:
        spin(max(0.0, start + fraction * duration - time.monotonic()))
        if action == 'kill':
            procs[key].kill9()
            procs[key].start()
        else:
            burst = _malformed(monitor, cfg['burst'])
    spin(max(0.0, start + duration - time.monotonic()))
    wall = time.monotonic() - start
    end_rss = {k: (p.rss[0][1] if p.rss else math.nan, _rss_mb(p.proc.pid))
               for k, p in procs.items()}
    replay.stop()
    spin(5.0)
    for p in procs.values():
        p.stop()
    executor.shutdown()
    monitor.destroy_node()
    rclpy.try_shutdown(context=context)

    journalled = set()
    for journal in journals.values():
        for line in journal.read_text().splitlines() if journal.exists() else []:
            try:
                e = json.loads(line)['event']
            except (ValueError, KeyError):
                continue
            if e.get('kind') != 'healthy':
                journalled.add((e['detector'], e['component'], e['change_index'], e['kind']))
    received_anomalies = {r for r in received if r[3] != 'healthy'}
    published = max((c.get('rows_published', 0) for (k, _), c in counters.items()
                     if k == 'replay'), default=0)

    def got(key: str, field: str) -> int:
        return sum(int(c.get(field, 0)) for (k, _), c in counters.items() if k == key)

    llr_rows = got('llr', 'messages') - burst.get('telemetry/wheels', 0)
    results = {
        'settings': cfg, 'seed': SEED, 'wall_s': wall, 'rows_in_file': len(tele),
        'nodes_up_before_replay': results_startup,
        'load_average_1min_at_end': os.getloadavg()[0],
        'rows_published': published,
        'sustained_rows_per_s': llr_rows / wall,
        'messages_lost': {
            'llr': published - llr_rows,
            'fss': published - (got('fss', 'messages') - burst.get('telemetry/wheels', 0)),
            'vsadc': published - (got('vsadc', 'gyro_messages')
                                  - burst.get('telemetry/gyro', 0))},
        'malformed_sent': burst,
        'anomalies_journalled': len(journalled),
        'anomalies_received': len(received_anomalies),
        'anomalies_lost': len(journalled - received_anomalies),
        'expected_components': sorted(expected),
        'expected_components_missed': sorted(expected - {r[1] for r in received_anomalies}),
        'crashes': [c for p in (*procs.values(), replay) for c in p.crashes + p.tracebacks()],
        'memory_mb': {k: {'start': v[0], 'end': v[1]} for k, v in end_rss.items()},
        'diagnostics_messages_per_s': diag['messages'] / wall,
        'diagnostics_statuses_per_s': diag['statuses'] / wall,
        'machine': report.machine(),
    }
    report.write_json(out_dir, 'soak', results)
    _section(results, quick)
    if not os.environ.get('RWA_SOAK_KEEP'):
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps({k: v for k, v in results.items() if k != 'machine'}, indent=1,
                     default=str))
    return results


def _section(r: dict[str, Any], quick: bool) -> None:
    rows = [['sustained rows/s (4 wheels + gyro, whole system)',
             f'{r["sustained_rows_per_s"]:.0f}'],
            ['rows published', r['rows_published']],
            ['messages lost (llr / vsadc / fss; includes rows sent while killed)',
             ' / '.join(str(r['messages_lost'][k]) for k in ('llr', 'vsadc', 'fss'))],
            ['anomalies journalled / received / lost (must be 0)',
             f'{r["anomalies_journalled"]} / {r["anomalies_received"]} / '
             f'{r["anomalies_lost"]}'],
            ['anomaly components of the file never reported',
             ', '.join(r['expected_components_missed']) or 'none'],
            ['crashes (must be 0)', len(r['crashes'])],
            *[[f'memory {k} start / end (MB)', f'{v["start"]:.0f} / {v["end"]:.0f}']
              for k, v in r['memory_mb'].items()],
            ['load average (1 min) at the end, 2 cores', f'{r["load_average_1min_at_end"]:.1f}'],
            ['/diagnostics messages/s (statuses/s)',
             f'{r["diagnostics_messages_per_s"]:.2f} ({r["diagnostics_statuses_per_s"]:.1f})']]
    kind = 'quick smoke run, not a result' if quick else 'full run'
    text = (f'Soak and faults ({kind}): {r["wall_s"]:.0f} s of replay at rate 0 in a loop '
            f'into llr_detector, vsadc_detector and fss_diagnoser (separate processes, DDS '
            f'on localhost), each killed with SIGKILL once and restarted, one burst of '
            f'{r["malformed_sent"].get("telemetry/wheels", 0)} malformed messages per input '
            f'topic; recording seed {r["seed"]} ({r["settings"]["file_hours"]} h, 4 wheels '
            f'at 10 Hz, dry step on rw2, gyro_y bias). `python -m bench soak'
            f'{" --quick" if quick else ""}`.\n\n'
            + report.table(['measure', 'value'], rows))
    report.update_section('soak', text)


if __name__ == '__main__':
    run(report.RESULTS_DIR, '--quick' in sys.argv)
