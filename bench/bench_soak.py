"""``python -m bench soak``: every node under sustained load, with kills and bad input.

A short recording (15 min of data: four wheels at 10 Hz with a dry friction step on rw2
at a quarter, gyro/star tracker with a bias on gyro_y at half) is replayed in a loop into
the llr_detector, vsadc_detector and fss_diagnoser nodes, each an OS process with an
``events_file`` journal; DDS stays on this host. Every pass of the loop holds the
faults, so the anomaly checks are never empty, whatever the machine's load: the run lasts
at least ``duration_s`` of wall time and at least ``min_passes`` complete passes (up to
``max_duration_s``; fewer passes is a failed run, not an empty one).

Rate: the highest the whole system sustains. Rate 0 (as fast as the readers take it)
fills the slowest reader's keep-all history (about 10,000 rows) and a kill then throws
that backlog away (docs/nodes.md "vsadc_detector input"), so the replay runs paced and
this process steers its ``rate`` parameter: every ``control_period_s`` it estimates by how
many rows each node fell behind the replay within the last 30 s (from the /diagnostics
counters; :class:`Incarnation`) and multiplies the rate by 1.25 while every backlog is below a
third of the limit (``backlog_s`` seconds of data, at least ``backlog_min_rows``) and by
0.6 when one is above it (:func:`next_rate`).

Faults: each detector is killed once with SIGKILL after it has declared an anomaly
(FSS: at the latest at 60 % of the run, declared or not) and restarted; its latched
anomalies must reach this monitor again from the new process. One burst of malformed
messages goes to every input topic.

Reported (bench/results/soak.json, section ``soak`` of docs/results.md): sustained rows/s
(rows published by the replay per second of wall time; every node kept up within the
backlog limit), messages lost per node with their explanation (rows sent while the node
was down, its backlog at the kill, and the rest), anomalies lost (journalled, never
received: must be 0), anomalies of the file never reported (the file pipelines' events
of one pass, by detector, component, kind and change index: must be none), latched
anomalies re-published after each restart, crashes (a node that exited by itself, a
non-zero exit on SIGTERM or a traceback: must be 0), resident memory at start and end,
/diagnostics messages/s and the 1-minute load average. :func:`verdict` lists what failed.
"""

from __future__ import annotations

from collections import deque
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
# The per-node counter of rows received, and the hardware_id of the status holding it.
RECEIVED = {'llr': ('telemetry/wheels', 'messages'), 'fss': ('telemetry/wheels', 'messages'),
            'vsadc': ('gyro_star_tracker', 'gyro_messages')}
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
SEED = 1000  # fresh seed (development used 1-99)
RATE_HZ = 10.0


def run_settings(quick: bool) -> dict[str, Any]:
    """Return the run's settings (``quick``: a smoke run, not a result)."""
    base = {'file_s': 900.0, 'burst': 2000, 'fss_window': 3000, 'min_passes': 3,
            'control_period_s': 3.0, 'backlog_s': 3.0, 'backlog_min_rows': 300,
            'start_rate': 5.0, 'max_rate': 2000.0, 'fss_kill_by': 0.6}
    if quick:
        return {**base, 'duration_s': 120.0, 'max_duration_s': 300.0, 'min_passes': 2,
                'burst': 200}
    return {**base, 'duration_s': 600.0, 'max_duration_s': 1800.0}


def recording(seconds: float, seed: int) -> Any:
    """Return four wheels at 10 Hz (dry step on rw2) with gyro/star tracker (bias on y)."""
    from rwa_monitor.sim.aocs import named_fault, simulate_aocs
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    wheels, _ = simulate_friction_with_truth(
        wheels=list(WHEELS), n_samples=int(seconds * RATE_HZ), rate_hz=RATE_HZ, seed=seed,
        anomalies=[Anomaly('rw2', 'dry', seconds / 4, delta_dry=3e-4)])
    gyro = simulate_aocs(float(wheels.time[-1]), seed=seed, time=wheels.time,
                         fault=named_fault('bias', 'y', seconds / 2))
    wheels.gyro, wheels.attitude = gyro.gyro, gyro.attitude
    wheels.reference_rate = gyro.reference_rate
    return wheels


def next_rate(rate: float, backlogs: dict[str, float], limit: float,
              max_rate: float) -> float:
    """Return the replay rate of the next control period (multiplicative steps).

    Down by 0.6 when a node's backlog is above ``limit`` rows, up by 1.25 when every
    backlog is below a third of it, else unchanged; within [0.5, ``max_rate``].
    """
    worst = max(backlogs.values(), default=0.0)
    if worst > limit:
        rate *= 0.6
    elif worst < limit / 3:
        rate *= 1.25
    return min(max(rate, 0.5), max_rate)


class Incarnation:
    """One process of a node: its counters, for the backlog estimate.

    The raw estimate is what the replay published since the node's first status minus
    what the node counted since (plus ``sent_extra``, the malformed burst). It carries
    a constant offset: the two counters arrive in different statuses up to a second
    apart, and a process counts nothing until discovery has matched it with the replay
    (rows published meanwhile never reach it). The backlog is therefore the raw estimate
    above its lowest value of the last ``window_s`` seconds: the rows by which the node
    fell behind within that window.
    """

    def __init__(self, window_s: float = 30.0) -> None:
        self.base: tuple[float, float] | None = None
        self.received = 0.0
        self.sent_extra = 0.0
        self.window_s = window_s
        self._history: deque[tuple[float, float]] = deque()

    def raw(self, published: float) -> float:
        """Return published minus received since the first status (0 before it)."""
        if self.base is None:
            return 0.0
        return (published - self.base[0]) + self.sent_extra - (self.received - self.base[1])

    def update(self, published: float, received: float, now: float | None = None) -> None:
        """Record the node's latest counter (and the base at its first status)."""
        now = time.monotonic() if now is None else now
        if self.base is None:
            self.base = (published, received)
        self.received = received
        self._history.append((now, self.raw(published)))
        while self._history[0][0] < now - self.window_s:
            self._history.popleft()

    def backlog(self, published: float) -> float:
        """Return the estimated rows waiting in the node (0 before its first status)."""
        if self.base is None:
            return 0.0
        return self.raw(published) - min(r for _, r in self._history)


def verdict(r: dict[str, Any]) -> list[str]:
    """Return the failed checks of a soak result (empty: passed)."""
    failed = []
    if r['passes_completed'] < r['settings']['min_passes']:
        failed.append(f'only {r["passes_completed"]} complete passes of the file '
                      f'(need {r["settings"]["min_passes"]})')
    if not r['expected_anomalies']:
        failed.append('the file pipelines found no anomaly: nothing to check')
    if r['expected_missed']:
        failed.append(f'anomalies of the file never reported: {r["expected_missed"]}')
    if r['anomalies_lost']:
        failed.append(f'{r["anomalies_lost"]} journalled anomalies never received')
    if r['crashes']:
        failed.append(f'crashes: {r["crashes"]}')
    for key, kill in r['kills'].items():
        if kill.get('latched_before_kill', 0) and \
                kill.get('republished_after_restart', 0) < kill['latched_before_kill']:
            failed.append(f'{key}: {kill["latched_before_kill"]} latched anomalies before '
                          f'the kill, {kill.get("republished_after_restart", 0)} shown again')
        if 'killed_at_s' not in kill:
            failed.append(f'{key} was never killed')
    return failed


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
        self.rss: list[float] = []
        self.first_rss = math.nan
        self.started = 0.0

    def start(self) -> None:
        self.incarnation += 1
        log = (self.log_dir / f'{self.key}.{self.incarnation}.log').open('w')
        self.proc = subprocess.Popen(self.args, env=self.env, stdout=log,
                                     stderr=subprocess.STDOUT)
        self.started = time.monotonic()
        self.rss = []

    def sample_rss(self) -> None:
        if self.proc is not None and time.monotonic() - self.started > 15.0:
            self.rss.append(_rss_mb(self.proc.pid))
            if self.incarnation == 1 and math.isnan(self.first_rss):
                self.first_rss = self.rss[-1]

    def kill9(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        self.proc = None            # an expected death, not a crash

    def check_alive(self) -> bool:
        if self.proc is not None and self.proc.poll() is not None:
            self.crashes.append(f'{self.key} exited by itself with {self.proc.returncode}')
            self.start()
            return False
        return True

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout=30)
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
        gyro.publish(messages.imu(rng.uniform(0.0, 1e4), [float('nan'), 1e30, -0.0]))
        star.publish(messages.quaternion(rng.uniform(0.0, 1e4), [0.0, 0.0, 0.0, 0.0]))
    return {'telemetry/wheels': count, 'telemetry/gyro': count,
            'telemetry/star_tracker': count}


def _domain_lease() -> tuple[int, Any]:
    """Hold a ROS domain id no test harness on this machine uses meanwhile.

    The same lock files as test/ros_harness.py's DomainLease (one per id, flock), so a
    test run beside the soak never shares its domain; released when the process ends.
    """
    import fcntl
    lock_dir = pathlib.Path(tempfile.gettempdir()) / 'rwa_monitor_ros_domains'
    lock_dir.mkdir(exist_ok=True)
    ids = list(range(1, 201))
    random.SystemRandom().shuffle(ids)
    for domain_id in ids:
        handle = (lock_dir / f'{domain_id}.lock').open('w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        return domain_id, handle
    raise RuntimeError('no free ROS domain id in 1-200')


def _expected(tele: Any) -> list[tuple]:
    """Return the file pipelines' anomalies of one pass: (detector, component, kind, index)."""
    from rwa_monitor.pipelines import llr, vsadc
    return sorted({(e.detector, e.component, e.kind, e.index)
                   for e in [*llr.run(tele, {}), *vsadc.run(tele, {})] if e.kind != 'healthy'})


def _latched(journal: pathlib.Path, copy: pathlib.Path, key: str) -> list[tuple]:
    """Return the records a node restarted on ``journal`` reloads (read from a copy)."""
    from rwa_monitor.telemetry.alarms import AlarmStore, event_key, kind_key
    if not journal.exists():
        return []
    shutil.copyfile(journal, copy)
    store = AlarmStore(copy, key=kind_key if key == 'fss' else event_key)
    return sorted({(a.event.detector, a.event.component, a.event.kind, a.event.index)
                   for a in store.load()})


def _journalled(path: pathlib.Path) -> list[tuple]:
    out = []
    for line in path.read_text().splitlines() if path.exists() else []:
        try:
            e = json.loads(line)['event']
        except (ValueError, KeyError, TypeError):
            continue
        if e.get('kind') != 'healthy':
            out.append((e['detector'], e['component'], e['kind'], e['change_index']))
    return out


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run the soak; write soak.json and the ``soak`` section; return the results."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS
    from rwa_monitor.telemetry import write_telemetry

    cfg = run_settings(quick)
    work = pathlib.Path(tempfile.mkdtemp(prefix='rwa_soak_'))
    tele = recording(cfg['file_s'], SEED)
    path = work / 'soak.csv'
    write_telemetry(path, tele)
    expected = _expected(tele)
    lease = _domain_lease()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(lease[0]))
    journals = {k: work / f'{k}.jsonl' for k in NODES}
    extra = {'llr': [], 'vsadc': [],
             'fss': ['-p', f'window_length:={cfg["fss_window"]}',
                     '-p', f'window_period:={cfg["fss_window"] // 2}']}
    procs = {k: _Proc(k, [_script(NODES[k]), '--ros-args', '-p',
                          f'events_file:={journals[k]}', '-p', 'stale_timeout:=30.0',
                          *extra[k]], env, work) for k in NODES}
    replay = _Proc('replay', [_script('rwa-monitor-replay'), '--ros-args',
                              '-p', f'file:={path}', '-p', f'rate:={cfg["start_rate"]}',
                              '-p', 'loop:=true', '-p', 'min_subscribers:=2'], env, work)

    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    context = Context()
    rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']))
    monitor = Node('soak_monitor', context=context)
    received: list[tuple[float, str, tuple]] = []       # (time, node, key)
    diag = {'messages': 0, 'statuses': 0}
    replay_state: dict[str, float] = {'rows_published': 0.0, 'loops': 0.0}
    incarnations: dict[str, list[Incarnation]] = {k: [] for k in NODES}
    last_counters: dict[str, dict[str, Any]] = {}
    seen_nodes: set[str] = set()
    by_name = {v: k for k, v in NODE_NAMES.items()}

    def on_anomalies(msg: Any) -> None:
        now = time.monotonic()
        for status in msg.status:
            e = messages.status_event(status)
            node = by_name.get(status.name.split(':', 1)[0], e.detector)
            received.append((now, node, (e.detector, e.component, e.kind, e.index)))

    def on_diagnostics(msg: Any) -> None:
        diag['messages'] += 1
        diag['statuses'] += len(msg.status)
        for status in msg.status:
            name = status.name.split(':', 1)[0]
            seen_nodes.add(name)
            if name == 'telemetry_replay' and status.hardware_id == 'replay':
                fields = messages.status_fields(status)
                replay_state.update({k: float(fields.get(k, 0)) for k in replay_state})
            key = by_name.get(name)
            if key and status.hardware_id == RECEIVED[key][0] and incarnations[key]:
                fields = messages.status_fields(status)
                last_counters[key] = fields
                incarnations[key][-1].update(replay_state['rows_published'],
                                             float(fields.get(RECEIVED[key][1], 0)))

    monitor.create_subscription(DiagnosticArray, 'anomalies', on_anomalies, EVENTS_QOS)
    monitor.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics,
                                DIAGNOSTICS_QOS)
    rate_client = AsyncParameterClient(monitor, 'telemetry_replay')
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(monitor)
    loads: list[float] = []
    kills: dict[str, dict[str, Any]] = {k: {} for k in NODES}

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
            for key, p in procs.items():
                if not p.check_alive():
                    incarnations[key].append(Incarnation())

    for key, p in procs.items():
        p.start()
        incarnations[key].append(Incarnation())
    ready_by = time.monotonic() + 180.0      # start-up can be slow on a loaded machine
    while not set(NODE_NAMES.values()) <= seen_nodes and time.monotonic() < ready_by:
        spin(0.5)
    nodes_up = sorted(seen_nodes)
    replay.start()
    start = time.monotonic()
    rate, rates, burst = cfg['start_rate'], [], {}
    next_control = start + cfg['control_period_s']
    next_sample = start
    while True:
        spin(0.2)
        now = time.monotonic()
        elapsed = now - start
        replay.check_alive()
        if now >= next_sample:
            next_sample = now + 10.0
            loads.append(os.getloadavg()[0])
            for p in procs.values():
                p.sample_rss()
        for key in NODES:            # back from a kill: its first status has arrived
            kill = kills[key]
            if 'killed_at_s' in kill and 'back_after_s' not in kill and \
                    incarnations[key][-1].base is not None:
                kill['back_after_s'] = round(now - start - kill['killed_at_s'], 1)
                kill['rows_published_while_down'] = \
                    replay_state['rows_published'] - kill['rows_published_at_kill']
        if now >= next_control:
            next_control = now + cfg['control_period_s']
            published = replay_state['rows_published']
            backlogs = {k: incarnations[k][-1].backlog(published) for k in NODES
                        if 'back_after_s' in kills[k] or 'killed_at_s' not in kills[k]}
            limit = max(cfg['backlog_min_rows'], cfg['backlog_s'] * rate * RATE_HZ)
            new = next_rate(rate, backlogs, limit, cfg['max_rate'])
            if new != rate and rate_client.services_are_ready():
                rate_client.set_parameters([Parameter('rate', value=new)])
                rate = new
            rates.append(rate)
        # Faults: kill each detector once after it has declared; one malformed burst.
        for key in NODES:
            kill = kills[key]
            if 'killed_at_s' in kill:
                continue
            declared = any(node == key and k[2] != 'healthy' for _, node, k in received)
            late = key == 'fss' and elapsed > cfg['fss_kill_by'] * cfg['duration_s']
            others_done = all('back_after_s' in kills[k] or 'killed_at_s' not in kills[k]
                              for k in NODES if k != key)
            if (declared or late) and others_done and elapsed > 30.0:
                published = replay_state['rows_published']
                kill.update(killed_at_s=round(elapsed, 1), declared_before_kill=declared,
                            rows_published_at_kill=published,
                            backlog_at_kill=incarnations[key][-1].backlog(published))
                procs[key].kill9()
                latched = _latched(journals[key], work / f'{key}.at_kill.jsonl', key)
                kill['latched'] = [list(e) for e in latched]
                kill['latched_before_kill'] = len(latched)
                spin(1.0)           # statuses still in flight from the killed process
                procs[key].start()
                incarnations[key].append(Incarnation())
                kill['restarted_wall'] = time.monotonic()
        if not burst and elapsed > 0.4 * cfg['duration_s']:
            burst = _malformed(monitor, cfg['burst'])
            for key in NODES:
                incarnations[key][-1].sent_extra += cfg['burst']
        all_killed = all('back_after_s' in k for k in kills.values())
        passes = int(replay_state['loops'])
        if elapsed >= cfg['duration_s'] and all_killed and passes >= cfg['min_passes']:
            break
        if elapsed >= cfg['max_duration_s']:
            break
    wall = time.monotonic() - start
    published = replay_state['rows_published']
    end_rss = {k: _rss_mb(p.proc.pid) for k, p in procs.items()}
    replay.stop()
    spin(8.0)       # the last statuses and anomalies
    final_backlog = {k: incarnations[k][-1].backlog(published) for k in NODES}
    for p in procs.values():
        p.stop()
    rate_client = None
    executor.shutdown()
    monitor.destroy_node()
    rclpy.try_shutdown(context=context)

    journalled = {k: set(_journalled(journals[k])) for k in NODES}
    got = {key for _, _, key in received}
    for key, kill in kills.items():
        after = {tuple(k) for t, node, k in received
                 if node == key and t >= kill.get('restarted_wall', math.inf)}
        kill['republished_after_restart'] = len(after & {tuple(e) for e in
                                                         kill.get('latched', [])})
        kill.pop('restarted_wall', None)
    lost = {}
    for key, inc in incarnations.items():
        # Every process counts from 0; what the last status of each did not count is lost.
        lost[key] = {'lost': round(published + sum(i.sent_extra for i in inc)
                                   - sum(i.received for i in inc)),
                     'while_down': round(kills[key].get('rows_published_while_down', 0)),
                     'backlog_at_kill': round(kills[key].get('backlog_at_kill', 0)),
                     'backlog_at_end': round(final_backlog[key])}
    all_journalled = set().union(*journalled.values())
    results = {
        'settings': cfg, 'seed': SEED, 'wall_s': wall, 'rows_in_file': len(tele),
        'nodes_up_before_replay': nodes_up, 'passes_completed': int(replay_state['loops']),
        'load_average_1min': {'mean': sum(loads) / max(len(loads), 1),
                              'max': max(loads, default=math.nan),
                              'end': os.getloadavg()[0]},
        'rows_published': published,
        'sustained_rows_per_s': published / wall,
        'replay_rate': {'final': rate, 'median': sorted(rates)[len(rates) // 2]
                        if rates else rate},
        'messages_lost': lost,
        'vsadc_unpaired_gyro': last_counters.get('vsadc', {}).get('unpaired_gyro'),
        'malformed_sent': burst,
        'expected_anomalies': [list(e) for e in expected],
        'expected_missed': [list(e) for e in expected if e not in got],
        'anomalies_journalled': len(all_journalled),
        'anomalies_received': len(got),
        'anomalies_lost': len(all_journalled - got),
        'kills': kills,
        'crashes': [c for p in (*procs.values(), replay) for c in p.crashes + p.tracebacks()],
        'memory_mb': {k: {'start': p.first_rss, 'end': end_rss[k]} for k, p in procs.items()},
        'diagnostics_messages_per_s': diag['messages'] / wall,
        'diagnostics_statuses_per_s': diag['statuses'] / wall,
        'machine': report.machine(),
        'commit': _commit(),
    }
    results['failed'] = verdict(results)
    results['passed'] = not results['failed']
    report.write_json(out_dir, 'soak', results)
    _section(results, quick)
    if not os.environ.get('RWA_SOAK_KEEP'):
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps({k: v for k, v in results.items() if k != 'machine'}, indent=1,
                     default=str))
    return results


def _commit() -> str:
    """Return the code's commit (``+changes`` when the work tree differs from it)."""
    def git(*args: str) -> str:
        return subprocess.run(['git', *args], cwd=report.REPO, capture_output=True,
                              text=True).stdout.strip()
    head = git('rev-parse', '--short', 'HEAD') or 'unknown'
    return head + ('+changes' if git('status', '--porcelain', '--', 'rwa_monitor') else '')


def _section(r: dict[str, Any], quick: bool) -> None:
    lost = r['messages_lost']
    rows = [['result', 'passed' if r['passed'] else 'FAILED: ' + '; '.join(r['failed'])],
            ['sustained rows/s (4 wheels + gyro/star/reference each row)',
             f'{r["sustained_rows_per_s"]:.0f} (replay rate median '
             f'{r["replay_rate"]["median"]:.1f}, final {r["replay_rate"]["final"]:.1f})'],
            ['rows published / passes of the file completed',
             f'{r["rows_published"]:.0f} / {r["passes_completed"]}'],
            *[[f'messages lost {k} (sent while down + backlog at kill; rest)',
               f'{v["lost"]} ({v["while_down"]} + {v["backlog_at_kill"]}; '
               f'{v["lost"] - v["while_down"] - v["backlog_at_kill"]})']
              for k, v in lost.items()],
            ['anomalies of the file (one pass) / never reported (must be 0)',
             f'{len(r["expected_anomalies"])} / {len(r["expected_missed"])}'],
            ['anomalies journalled / received / lost (must be 0)',
             f'{r["anomalies_journalled"]} / {r["anomalies_received"]} / '
             f'{r["anomalies_lost"]}'],
            *[[f'kill -9 {k}: at s / back after s / latched before / shown again',
               f'{v.get("killed_at_s", "-")} / {v.get("back_after_s", "-")} / '
               f'{v.get("latched_before_kill", "-")} / '
               f'{v.get("republished_after_restart", "-")}'
               + ('' if v.get('declared_before_kill', True) else ' (had not declared)')]
              for k, v in r['kills'].items()],
            ['crashes (must be 0)', len(r['crashes'])],
            *[[f'memory {k} start / end (MB)', f'{v["start"]:.0f} / {v["end"]:.0f}']
              for k, v in r['memory_mb'].items()],
            ['VSADC gyro samples released unpaired', r['vsadc_unpaired_gyro']],
            ['load average (1 min), 2 cores: mean / max',
             f'{r["load_average_1min"]["mean"]:.1f} / {r["load_average_1min"]["max"]:.1f}'],
            ['/diagnostics messages/s (statuses/s)',
             f'{r["diagnostics_messages_per_s"]:.2f} ({r["diagnostics_statuses_per_s"]:.1f})']]
    kind = 'quick smoke run, not a result' if quick else 'full run'
    s = r['settings']
    text = (f'Soak and faults ({kind}): {r["wall_s"]:.0f} s of paced replay in a loop into '
            f'llr_detector, vsadc_detector and fss_diagnoser (separate processes, DDS on '
            f'localhost), the rate steered to the highest every node sustains (backlog under '
            f'{s["backlog_s"]:.0f} s of data); each detector killed with SIGKILL once after '
            f'it declared and restarted; one burst of '
            f'{r["malformed_sent"].get("telemetry/wheels", 0)} malformed messages per input '
            f'topic; recording seed {r["seed"]} ({s["file_s"]:.0f} s, 4 wheels at 10 Hz, '
            f'dry step on rw2, gyro_y bias, in every pass). `python -m bench soak'
            f'{" --quick" if quick else ""}`; method in bench/bench_soak.py.\n\n'
            + report.table(['measure', 'value'], rows)
            + f'\n\nHow to read (measured on {r.get("commit", "?")}, '
            f'{r["machine"]["date"][:10]}, load average {r["load_average_1min"]["mean"]:.0f} '
            f'on {r["machine"]["cpus"]} cores): sustained rows/s is what the whole system '
            'kept up with on this machine at that load (the rate steers itself; a row is one '
            '4-wheel JointState plus one gyro, star-tracker and reference message). "Sent '
            'while down" counts the rows published from the kill to the first status of the '
            'new process (an upper bound of the downtime: the process subscribes shortly '
            'before its first status), "backlog at kill" the rows the node had fallen behind '
            'in the last 30 s; a SIGKILL loses what the node held, so the lost messages should '
            'not exceed their sum (a negative rest: the bound was generous). Unpaired gyro '
            'samples include the gyro messages of the malformed burst (random stamps, no '
            'partner). Anomalies of the file: the events of `rwa-monitor detect` on one pass; '
            'each must come from a node with the same change index in some pass.')
    report.update_section('soak', text)


if __name__ == '__main__':
    run(report.RESULTS_DIR, '--quick' in sys.argv)
