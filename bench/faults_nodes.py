"""Fault cases of issue 24 items 3, 4 and 6 on the node side: start-up, journal, replay.

Each case is ``(name, scenario)``; ``scenario(folder)`` runs it in a fresh temporary
folder and returns a one-line outcome, raising AssertionError when the behaviour is
wrong (bench/bench_faults.py collects them). Nodes run as a user runs them, each its
own process started through its console script's module (``python -m
rwa_monitor.nodes.llr_detector --ros-args ...``: exit code and stderr as a user sees
them), on a ROS domain leased with test/ros_harness.py (the tests' private graphs, so
a test run beside the bench never shares a domain); a case that has to see a node's
state from inside (the journal one) builds the node in a ``RosWorld`` of that harness.
"""

from __future__ import annotations

import os
import pathlib
import re
import select
import signal
import subprocess
import sys
import time
from typing import Any, Callable

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
LLR = 'rwa_monitor.nodes.llr_detector'
REPLAY = 'rwa_monitor.nodes.replay'
RECORDER = 'rwa_monitor.nodes.recorder'


def harness() -> Any:
    """Return the tests' ROS harness module (test/ros_harness.py)."""
    if str(REPO / 'test') not in sys.path:
        sys.path.insert(0, str(REPO / 'test'))
    import ros_harness
    return ros_harness


def node_env(domain_id: int) -> dict[str, str]:
    """Return the environment of a node process on ``domain_id`` importing this tree."""
    path = os.pathsep.join(filter(None, [str(REPO), os.environ.get('PYTHONPATH')]))
    return dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONPATH=path,
                ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')


class NodeProcess:
    """A node run as its own process (``python -m MODULE --ros-args ARGS``); stderr kept."""

    def __init__(self, module: str, args: list[object], domain_id: int) -> None:
        """Start the process."""
        self.stderr = ''
        self.proc = subprocess.Popen(
            [sys.executable, '-m', module, '--ros-args', *map(str, args)],
            env=node_env(domain_id), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

    def _read(self, timeout: float) -> bool:
        """Append what stderr holds within ``timeout`` s; False at its end."""
        ready, _, _ = select.select([self.proc.stderr], [], [], timeout)
        if not ready:
            return True
        chunk = os.read(self.proc.stderr.fileno(), 65536)
        self.stderr += chunk.decode(errors='replace')
        return bool(chunk)

    def wait_for(self, text: str, timeout: float) -> bool:
        """Read stderr until it holds ``text`` (True), the process ends or ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while text not in self.stderr and time.monotonic() < deadline:
            if not self._read(min(0.2, max(0.0, deadline - time.monotonic()))):
                break
        return text in self.stderr

    def finish(self, timeout: float, interrupt: bool = False) -> int:
        """Wait for the end (Ctrl-C first if ``interrupt``); kill after ``timeout`` s."""
        if interrupt and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout
        while self._read(0.2) and time.monotonic() < deadline:
            pass
        try:
            return self.proc.wait(max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise AssertionError(f'still running after {timeout:g} s; stderr: '
                                 f'{self.stderr[-300:]}') from None


def start_refused(args: list[object], module: str = LLR,
                  timeout: float = 120.0) -> tuple[int, str]:
    """Start the node of ``module`` with ``args``; return (exit code, stderr) (it must end)."""
    lease = harness().DomainLease()
    try:
        node = NodeProcess(module, args, lease.domain_id)
        return node.finish(timeout), node.stderr.strip()
    finally:
        lease.release()


def one_error_line(code: int, err: str, expected: str) -> str:
    """Check exit 2 and one ``error:`` line holding ``expected``; return the line."""
    lines = err.splitlines()
    assert code == 2, f'exit {code}: {err[-300:]}'
    assert len(lines) == 1 and lines[0].startswith('error: ') and expected in lines[0], err
    return lines[0]


def wheels_file(folder: pathlib.Path, rows: int) -> tuple[pathlib.Path, np.ndarray]:
    """Write a one-wheel file of ``rows`` rows at 10 Hz from t = 5 s; return (path, time)."""
    from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry
    stamps = 5.0 + 0.1 * np.arange(rows)
    path = folder / 'wheels.csv'
    write_telemetry(path, Telemetry(time=stamps, wheels={
        'rw1': Wheel(np.linspace(1.0, 2.0, rows), np.zeros(rows))}))
    return path, stamps


# ------------------------------------------------------------------ 1. and 2. data
def recorder_folder(folder: pathlib.Path) -> str:
    """Let the recorder replace its own recording, never a folder holding a user's database."""
    import sqlite3
    lease = harness().DomainLease()
    try:
        codes = []
        for _ in range(2):              # the second run replaces the first one's recording
            node = NodeProcess(RECORDER, ['-p', f'output:={folder / "rec"}'], lease.domain_id)
            assert node.wait_for('recording ', 120.0), node.stderr[-300:]
            codes.append(node.finish(30.0, interrupt=True))
    finally:
        lease.release()
    assert codes == [0, 0] and (folder / 'rec' / 'metadata.yaml').is_file(), codes
    user = folder / 'mine'
    user.mkdir()
    with sqlite3.connect(user / 'data.db3') as db:
        db.execute('create table notes (text)')
    db.close()
    before = (user / 'data.db3').read_bytes()
    line = one_error_line(*start_refused(['-p', f'output:={user}'], RECORDER), 'data.db3')
    assert (user / 'data.db3').read_bytes() == before and len(list(user.iterdir())) == 1
    return ('a second run replaced the recording of the first (exit 0 on Ctrl-C each); a '
            f'folder holding data.db3: exit 2, "...{line.split("this folder: ")[-1][:150]}", '
            'untouched')


def live_wheel_names(folder: pathlib.Path) -> str:
    """Wheel ids of a live message that are not valid names: dropped, counted, no crash."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, telemetry_qos
    bad = ['../../x', 'rw 1', 'rw1\nforged log line', 'a' * 65, 'x' * 100_000]
    names, sent = ['rw1', *bad], 20
    journal = folder / 'events.jsonl'
    ros = harness()
    with ros.RosWorld() as world:
        node = NodeProcess(LLR, ['-p', f'events_file:={journal}', '-p',
                                 'diagnostic_period:=0.5'], world.domain_id)
        try:
            feeder = world.node(Node, 'fault_feeder')
            pub = feeder.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
            diagnostics = ros.Collector(feeder, DiagnosticArray, '/diagnostics',
                                        DIAGNOSTICS_QOS)
            world.wait_for_subscribers(pub, timeout_sec=120.0)

            def counters() -> dict[str, Any]:
                found = [messages.status_fields(s) for m in diagnostics.messages
                         for s in m.status if s.hardware_id == 'telemetry/wheels']
                return found[-1] if found else {}
            for i in range(sent):
                pub.publish(messages.joint_state(1.0 + 0.1 * i, names, [5.0] * len(names),
                                                 [1e-4] * len(names)))
            world.wait_until(lambda: counters().get('messages') == sent, 60.0,
                             'every message counted on /diagnostics')
            alive = node.proc.poll() is None
        finally:
            code = node.finish(30.0, interrupt=True)
    got = counters()
    assert alive and code == 0, f'node ended (exit {code}): {node.stderr[-300:]}'
    assert got.get('invalid_name') == sent * len(bad), got
    assert "monitoring wheel 'rw1'" in node.stderr and node.stderr.count('monitoring') == 1
    assert not any(b in (journal.read_text() if journal.exists() else '') for b in bad)
    return (f'{sent} messages of rw1 and {len(bad)} invalid ids: invalid_name = '
            f'{got["invalid_name"]} on /diagnostics, only rw1 monitored, node alive, exit 0 '
            'on Ctrl-C')


# -------------------------------------------------------------- 4. parameters files
def bad_parameters_file(folder: pathlib.Path) -> str:
    block = 'llr_detector:\n  ros__parameters:\n'
    bomb = ''.join(f'{b}: &{b} [{", ".join([f"*{a}"] * 9)}]\n'
                   for a, b in zip('abcde', 'bcdef'))    # 9^6 values once expanded
    files = {
        'alias bomb': ('a: &a [x, x, x, x, x, x, x, x, x]\n' + bomb + block
                       + '    window: *f\n', 'params file'),
        'broken YAML': (block + '    window: [1\n', 'params file'),
        'window -5': (block + '    window: -5\n', 'window'),
        'false_alarm_rate many': (block + '    false_alarm_rate: many\n', 'false_alarm_rate'),
    }
    outcomes, wrong = [], []
    for name, (text, expected) in files.items():
        path = folder / f'{name.replace(" ", "_")}.yaml'
        path.write_text(text)
        code, err = start_refused(['--params-file', path])
        try:
            line = one_error_line(code, err, expected)
            outcomes.append(f'{name}: "{line[len("error: "):][:60]}"')
        except AssertionError:
            first = re.sub(r'\[\d+\.\d+\] ', '', err.splitlines()[0] if err else '')
            wrong.append(f'{name}: exit {code}, {len(err.splitlines())} lines ("{first[:48]}" '
                         'first)')
    assert not wrong, '; '.join(wrong) + (
        f'; one line for {", ".join(o.split(":")[0] for o in outcomes)}' if outcomes else '')
    return f'{len(files)} files, each exit 2 with one line: ' + '; '.join(outcomes)


# ----------------------------------------------------------------------- 3. journals
def journal_refuses_node(folder: pathlib.Path) -> str:
    notes = folder / 'notes.txt'
    notes.write_text('three years of notes\n')
    line = one_error_line(*start_refused(['-p', f'events_file:={notes}']), 'events_file')
    assert notes.read_text() == 'three years of notes\n', 'the file was changed'
    one_error_line(*start_refused(['-p', f'events_file:={folder}']), 'events_file')
    return (f'a foreign file: exit 2, "{line[len("error: "):][:110]}", file untouched; '
            'a folder: exit 2 with one line too')


def unwritable_journal(folder: pathlib.Path) -> str:
    """Declare an anomaly whose journal append fails: the alarms status must turn ERROR."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, ERROR, EVENTS_QOS, OK
    from rwa_monitor.nodes.latched import ALARMS_ID
    from rwa_monitor.nodes.llr_detector import LLRDetectorNode
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    ros = harness()
    tele, _ = simulate_friction_with_truth(wheels=['rw1', 'rw2'], n_samples=3000,
                                           rate_hz=10.0, seed=11, anomalies=[
                                               Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    journals = folder / 'journals'
    journals.mkdir()
    journal = journals / 'events.jsonl'
    with ros.RosWorld() as world:
        node = world.node(LLRDetectorNode, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('events_file', value=str(journal)),
            Parameter('window', value=200), Parameter('k_verif', value='auto'),
            Parameter('false_alarm_rate', value=1e-5), Parameter('noise_std', value='auto'),
            Parameter('diagnostic_period', value=0.2)])
        sink = world.node(Node, 'fault_sink')
        diagnostics = ros.Collector(sink, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        anomalies = ros.Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)

        def alarms() -> Any:
            found = [s for m in diagnostics.messages for s in m.status
                     if s.hardware_id == ALARMS_ID]
            return found[-1] if found else None
        world.wait_until(lambda: alarms() is not None, 30.0, 'the alarms status')
        assert alarms().level == OK, alarms().message
        journal.unlink()                 # created at start with its header
        journals.rmdir()
        journals.write_text('')          # its folder is now a regular file: appends fail
        names = list(tele.wheels)
        speed = np.column_stack([tele.wheels[w].speed for w in names]).tolist()
        friction = np.column_stack([tele.wheels[w].friction for w in names]).tolist()
        for i, t in enumerate(tele.time.tolist()):   # the bytes the subscription delivers
            node.on_raw_wheels(serialize_message(messages.joint_state(
                t, names, speed[i], friction[i])))
        assert node.events, 'the friction step of rw2 was not declared'
        world.wait_until(lambda: alarms().level == ERROR, 30.0, 'the alarms status ERROR')
        world.wait_until(lambda: len(anomalies) > 0, 10.0, 'the anomaly on anomalies')
        status = alarms()
        fields = messages.status_fields(status)
    assert fields['alarms_journal_errors'] >= 1 and str(journal) in fields['journal_last_error']
    return (f'{len(node.events)} rw2 event(s) declared and published; /diagnostics alarms ERROR: '
            f'"{status.message[:130]}"')


# ----------------------------------------------------------------------------- 6. ROS
def beaten_override(folder: pathlib.Path) -> str:
    from rwa_monitor.nodes.llr_detector import LLRDetectorNode
    from rwa_monitor.nodes.parameters import beaten_overrides
    config = folder / 'p.yaml'
    config.write_text('llr_detector:\n  ros__parameters:\n    events_file: ""\n'
                      '    window: 300\n')
    journal = folder / 'events.jsonl'
    fix = f'-p llr_detector:events_file:={journal}'
    ros = harness()
    with ros.RosWorld() as world:
        node = NodeProcess(LLR, ['-p', f'events_file:={journal}', '-p', 'window:=300',
                                 '--params-file', config], world.domain_id)
        warned = node.wait_for(f'put {fix} after --params-file', 120.0)
        code = node.finish(30.0, interrupt=True)
        assert warned, f'no warning naming the fix; stderr: {node.stderr[-300:]}'
        assert code == 0, f'exit {code} after Ctrl-C'
        assert node.stderr.count('was beaten') == 1, node.stderr  # window: the same value
        kept = ['--params-file', str(config), *fix.split()]
        fixed = world.node(LLRDetectorNode, cli_args=['--ros-args', *kept])
        assert fixed.params['events_file'] == str(journal), fixed.params['events_file']
        assert beaten_overrides(fixed, ['prog', '--ros-args', *kept]) == []
    line = next(x for x in node.stderr.splitlines() if 'was beaten' in x)
    return (f'warned at start: "{line.split("]: ", 1)[-1][:150]}"; with the fix the value is '
            'in force, no warning')


def replay_waits(folder: pathlib.Path) -> str:
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from rwa_monitor.nodes import messages
    from rwa_monitor.nodes.common import telemetry_qos
    rows, rate, late = 60, 20.0, 4.0
    path, stamps = wheels_file(folder, rows)
    ros = harness()
    with ros.RosWorld() as world:
        watcher = world.node(Node, 'fault_watcher')
        replay = NodeProcess(REPLAY, ['-p', f'file:={path}', '-p', f'rate:={rate}',
                                      '-p', 'subscriber_timeout:=120.0'], world.domain_id)
        try:
            world.wait_until(lambda: watcher.count_publishers('/telemetry/wheels') > 0, 120.0,
                             'the replay process')
            world.spin_for(late)          # the whole file would be published by now
            wheels = ros.Collector(watcher, JointState, 'telemetry/wheels', telemetry_qos())
            world.wait_until(lambda: len(wheels) >= rows, 120.0, 'every row')
            world.spin_for(0.5)
            code = replay.finish(60.0)
        finally:
            if replay.proc.poll() is None:
                replay.finish(10.0, interrupt=True)
    got = [messages.to_seconds(m.header.stamp) for m in wheels.messages]
    assert code == 0, f'replay exit {code}: {replay.stderr[-300:]}'
    assert len(got) == rows and np.allclose(got, stamps, atol=1e-9), \
        f'{len(got)} of {rows} rows, first {got[:3]}'
    line = next((x for x in replay.stderr.splitlines() if 'starting after' in x), '')
    assert 'with the matched subscribers: /telemetry/wheels 1' in line, replay.stderr[-300:]
    return (f'subscriber joined {late:g} s after the replay appeared (file: {rows / rate:g} s '
            f'at rate {rate:g}): {len(got)} of {rows} rows received, stamps equal; replay log '
            f'"{line.split("]: ", 1)[-1][:80]}", exit 0')


def replay_timeout(folder: pathlib.Path) -> str:
    path, _ = wheels_file(folder, 5)
    timeout = 1.0
    lease = harness().DomainLease()
    try:
        replay = NodeProcess(REPLAY, ['-p', f'file:={path}', '-p', 'rate:=50.0',
                                      '-p', f'subscriber_timeout:={timeout}'], lease.domain_id)
        code = replay.finish(120.0)
    finally:
        lease.release()
    line = next((x for x in replay.stderr.splitlines() if 'starting after' in x), '')
    assert code == 0, f'exit {code}: {replay.stderr[-300:]}'
    assert f'subscriber_timeout of {timeout:g} s' in line and '/telemetry/wheels 0' in line, \
        replay.stderr[-300:]
    return f'exit 0 by itself; WARN "{line.split("]: ", 1)[-1][:150]}"'


CASES: list[tuple[str, Callable[[pathlib.Path], str]]] = [
    ('1 rwa-monitor-record output: its recording, a folder holding data.db3', recorder_folder),
    ('2 live wheel ids that are not valid names (llr_detector)', live_wheel_names),
    ('3 node: events_file naming a foreign file or a folder', journal_refuses_node),
    ('3 node: the journal cannot be written when an anomaly is declared', unwritable_journal),
    ('4 node given a bad parameters file', bad_parameters_file),
    ('6 -p beaten by a later parameters-file block', beaten_override),
    ('6 replay at rate 20 with the subscriber started late', replay_waits),
    ('6 replay without subscribers (subscriber_timeout)', replay_timeout),
]
