"""Fault cases of issue 36 (an audit of main 91ca172), each through the real code.

``CASES``: (name, function); each function is given a fresh temporary folder, builds its
input there, runs the command in this process (:func:`rwa_monitor.cli.main.main`) or as
its own process where the exit code, stderr or a signal matter, and returns a one-line
outcome; it raises AssertionError when the behaviour is wrong. bench/bench_faults.py
runs them beside the cases of issue 24 and test/test_audit_faults.py runs each as a
test. The fleet's cases of the issue live with the fleet.
"""

from __future__ import annotations

import contextlib
import io
import json
import pathlib
import subprocess
import sys
from typing import Callable

import numpy as np

from rwa_monitor.cli.main import main
from rwa_monitor.telemetry import read_telemetry, write_telemetry


def run(*argv: object) -> tuple[int, str, str]:
    """Run ``rwa-monitor ARGV`` in this process; return (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def run_process(*argv: object, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """Run the command line as its own process (exit code and stderr as a user sees them)."""
    return subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main',
                           *(str(a) for a in argv)], capture_output=True, text=True,
                          timeout=timeout)


def strict_json(path: pathlib.Path) -> dict:
    """Return the JSON of ``path``; AssertionError on NaN, Infinity or -Infinity."""
    def refuse(constant: str) -> None:
        raise AssertionError(f'{path.name} holds {constant}: not strict JSON')
    return json.loads(path.read_text(), parse_constant=refuse)


def one_line_error(code: int, err: str, expected: str) -> str:
    """Check exit 2 with one line naming ``expected`` and no traceback; return the line."""
    assert code == 2, f'exit {code}: {err[-300:]}'
    lines = err.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in err, err[-500:]
    assert expected in err, err
    assert 'unexpected error' not in err, err
    return lines[0].split('error: ', 1)[-1]


def wheels_file(folder: pathlib.Path, seconds: int = 600, name: str = 'wheels.csv'
                ) -> pathlib.Path:
    """Write a fault-free two-wheel friction file (10 Hz) and return its path."""
    path = folder / name
    code, _, err = run('simulate', 'friction', '--wheels', '2', '--seconds', seconds,
                       '--rate', '10', '--seed', '36', '-o', path)
    assert code == 0, err
    return path


def damaged(source: pathlib.Path, name: str, column: str, value: float,
            share: float = 1.0) -> pathlib.Path:
    """Write ``source`` with ``share`` of ``column``'s rows (seeded choice) set to ``value``."""
    tele = read_telemetry(source)
    wheel, kind = column.split('_')
    values = getattr(tele.wheels[wheel], kind)
    n = values.size
    rows = (np.arange(n) if share >= 1.0 else
            np.random.default_rng(36).choice(n, max(1, int(n * share)), replace=False))
    values[rows] = value
    out = source.with_name(name)
    write_telemetry(out, tele)
    return out


# ---------------------------------------------------------------------------- journals
def journal_pretty_json(folder: pathlib.Path) -> str:
    """Name a pretty-printed JSON file (detect's own output) as a journal: refused."""
    from rwa_monitor.exceptions import ConfigError
    from rwa_monitor.telemetry.alarms import AlarmStore
    path = folder / 'events.json'
    code, _, err = run('detect', wheels_file(folder, 300), '-o', path)
    assert code in (0, 3), err
    before = path.read_bytes()
    assert before.startswith(b'{\n')
    try:
        AlarmStore(path).load()
    except ConfigError as error:
        message = str(error)
    else:
        raise AssertionError('a pretty-printed JSON file was taken for a journal')
    assert path.read_bytes() == before, 'the file was changed'
    return f'JournalError: "{message.split(": ", 1)[-1][:110]}"; {len(before)} bytes untouched'


def journal_node_pretty_json(folder: pathlib.Path) -> str:
    """Start a node on a pretty-printed JSON events_file: exit 2, one line, untouched."""
    path = folder / 'events.json'
    path.write_text(json.dumps({'events': [], 'summary': {'samples': 3}}, indent=2))
    before = path.read_bytes()
    out = subprocess.run([sys.executable, '-m', 'rwa_monitor.nodes.fss_diagnoser',
                          '--ros-args', '-p', f'events_file:={path}'],
                         capture_output=True, text=True, timeout=120)
    line = one_line_error(out.returncode, out.stderr, 'not an alarm journal')
    assert path.read_bytes() == before
    return f'fss_diagnoser exit 2: "{line[:120]}"; file untouched'


# ---------------------------------------------------------------------------- diagnose
def _diagnose(path: pathlib.Path, out: pathlib.Path) -> tuple[int, dict, str]:
    code, _, err = run('diagnose', path, '-o', out)
    assert 'unexpected error' not in err, err
    return code, (strict_json(out) if out.exists() else {}), err


def diagnose_friction_1e300(folder: pathlib.Path) -> str:
    """Diagnose a friction column of 1e300 N m: not examined (out of range), exit 3."""
    path = damaged(wheels_file(folder), 'f1e300.csv', 'rw1_friction', 1e300)
    code, doc, err = _diagnose(path, folder / 'd.json')
    assert code == 3, f'exit {code}: {err}'
    rw1 = doc['wheels']['rw1']
    assert not any(rw1['anomalies'].values()), rw1['anomalies']
    assert rw1['rejected']['out_of_range'] == rw1['coverage']['samples']
    assert 'rw1' in doc['not_examined'] and 'rw2' not in doc['not_examined']
    return f'exit 3; rw1 not examined: {doc["not_examined"]["rw1"]}; strict JSON'


def diagnose_friction_1pct_minus_1e300(folder: pathlib.Path) -> str:
    """1 % of friction rows at -1e300: counted out of range, diagnosed on the rest."""
    path = damaged(wheels_file(folder), 'f.csv', 'rw1_friction', -1e300, 0.01)
    code, doc, err = _diagnose(path, folder / 'd.json')
    assert code == 0, f'exit {code}: {err}'
    rw1 = doc['wheels']['rw1']
    assert rw1['rejected']['out_of_range'] == 60, rw1['rejected']
    noise = rw1['estimates']['noise_std_nm']
    assert 1e-5 < noise < 1e-3, noise
    return (f'exit 0; rw1: {rw1["rejected"]["out_of_range"]} of 6000 samples out of range, '
            f'noise_std_nm {noise:.3g}; strict JSON')


def diagnose_speed_1pct_1e300(folder: pathlib.Path) -> str:
    """1 % of speed rows at 1e300: a finite noise estimate, never ``Infinity``."""
    path = damaged(wheels_file(folder), 's.csv', 'rw1_speed', 1e300, 0.01)
    code, doc, err = _diagnose(path, folder / 'd.json')
    assert code == 0, f'exit {code}: {err}'
    rw1 = doc['wheels']['rw1']
    noise = rw1['estimates']['noise_std_nm']
    assert rw1['rejected']['out_of_range'] == 60 and 1e-5 < noise < 1e-3, rw1
    return f'exit 0; rw1 noise_std_nm {noise:.3g} (60 samples out of range); strict JSON'


# ------------------------------------------------------------------------------- paths
def output_symlink_loop(folder: pathlib.Path) -> str:
    """Give every command an -o (and an input) that is a loop of symbolic links."""
    source = wheels_file(folder, 300)
    (folder / 'a').symlink_to('b')
    (folder / 'b').symlink_to('a')
    loop = folder / 'a'
    lines = []
    for argv in (('detect', source, '-o', loop), ('diagnose', source, '-o', loop),
                 ('simulate', 'friction', '--seconds', '5', '-o', loop),
                 ('calibrate', source, '-o', loop),
                 ('identify', source, '--wheel', 'rw1', '-o', loop),
                 ('detect', loop, '-o', folder / 'x.json')):
        code, _, err = run(*argv)
        lines.append(one_line_error(code, err, 'symbolic links form a loop'))
    return f'6 commands, each exit 2 with one line: "{lines[0]}"'


def dangling_link_missing_folder(folder: pathlib.Path) -> str:
    """Write through a dangling -o link whose folder is missing: refused, nothing made."""
    source = wheels_file(folder, 300)
    missing = folder / 'gone' / 'deeper'
    link = folder / 'events.json'
    link.symlink_to(missing / 'events.json')
    code, _, err = run('detect', source, '-o', link)
    line = one_line_error(code, err, 'whose folder')
    cal = folder / 'cal'
    cal.symlink_to(missing / 'cal')
    code, _, err = run('calibrate', source, '-o', cal)
    one_line_error(code, err, 'whose folder')
    assert not (folder / 'gone').exists(), 'the missing folder was created'
    (folder / 'gone').mkdir()
    code, _, err = run('detect', source, '-o', folder / 'elsewhere.json')
    assert code in (0, 3), err
    return f'detect and calibrate exit 2: "{line[:160]}"; nothing created'


_KILLED = '''
import os, signal, sys
from rwa_monitor.telemetry.atomic import FolderOutput
out = FolderOutput(sys.argv[1], ('calibration.yaml', 'report.md', '*_friction.png'))
work = out.open()
work.mkdir()
(work / 'calibration.yaml').write_text('half')
if sys.argv[2] == 'kill':
    os.kill(os.getpid(), signal.SIGKILL)
print('ready', flush=True)
sys.stdin.read()
'''


def killed_calibrate_temporary(folder: pathlib.Path) -> str:
    """Kill (SIGKILL) a run building -o cal: the next run removes its .cal.*.tmp/."""
    source = wheels_file(folder, 300)
    cal = folder / 'cal'
    killed = subprocess.run([sys.executable, '-c', _KILLED, str(cal), 'kill'],
                            capture_output=True, text=True, timeout=120)
    assert killed.returncode == -9, killed.stderr
    left = sorted(p.name for p in folder.glob('.cal.*.tmp'))
    assert len(left) == 1, left
    live = subprocess.Popen([sys.executable, '-c', _KILLED, str(cal), 'wait'],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert live.stdout.readline().strip() == 'ready'
        code, _, err = run('calibrate', source, '-o', cal)
        assert code == 0, err
        now = sorted(p.name for p in folder.glob('.cal.*.tmp'))
    finally:
        live.communicate('', timeout=60)
    assert left[0] not in now, "the killed run's temporary is still there"
    assert len(now) == 1, f"the live run's temporary should stay: {now}"
    assert (cal / 'calibration.yaml').read_text().startswith('calibration:')
    return ('a SIGKILLed run left 1 .cal.*.tmp/; the next calibrate removed it (exit 0) and '
            'kept the one of a run still alive')


def identify_column_1e300(folder: pathlib.Path) -> str:
    """Identify a friction column of 1e300 (all rows; then 1 %): named, never singular."""
    source = wheels_file(folder)
    code, _, err = run('identify', damaged(source, 'all.csv', 'rw1_friction', 1e300),
                       '--wheel', 'rw1', '-o', folder / 'id_all')
    line = one_line_error(code, err, 'rw1_friction: every value is at or beyond 1000 N m')
    assert 'Singular' not in err
    code, out, err = run('identify', damaged(source, 'some.csv', 'rw1_friction', -1e300, 0.01),
                         '--wheel', 'rw1', '-o', folder / 'id_some')
    assert code == 0 and '60 of 6000 values' in err, err
    report = strict_json(folder / 'id_some' / 'report.json')
    assert 0.0 < report['rmse_after']['held_out'] < 1e-3, report['rmse_after']
    return (f'all rows: exit 2, "{line[:110]}"; 1 % of rows: exit 0, 60 rows left out, '
            f'held-out RMSE {report["rmse_after"]["held_out"]:.3g} N m')


# ------------------------------------------------------------------------- wide files
def wide_csv(path: pathlib.Path, columns: int, rows: int = 20) -> pathlib.Path:
    """Write a CSV of ``time`` and ``columns`` wheel columns (speed, friction pairs)."""
    wheels = columns // 2
    rng = np.random.default_rng(36)
    header = ['time'] + [f'rw{i}_{k}' for i in range(wheels) for k in ('speed', 'friction')]
    table = np.column_stack([np.arange(rows) * 0.1, rng.normal(size=(rows, 2 * wheels))])
    np.savetxt(path, table, delimiter=',', fmt='%.6g', header=','.join(header), comments='')
    return path


def _cpu_seconds(*argv: object) -> tuple[float, subprocess.CompletedProcess]:
    """Run the command line as its own process; return (its CPU seconds, the result)."""
    import resource
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = run_process(*argv, timeout=900)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), done


def wide_file_scaling(folder: pathlib.Path) -> str:
    """Detect on 25,000 and 100,000 columns x 20 rows: CPU time grows linearly, not faster."""
    times = {}
    for columns in (25_000, 100_000):
        path = wide_csv(folder / f'wide_{columns}.csv', columns)
        seconds, done = _cpu_seconds('detect', path, '-o', folder / f'wide_{columns}.json')
        assert done.returncode == 3, done.stderr[-300:]        # 20 rows: not examined
        times[columns] = seconds
    baseline, _ = _cpu_seconds('detect', wide_csv(folder / 'narrow.csv', 2), '-o',
                               folder / 'narrow.json')          # start-up and imports
    ratio = (times[100_000] - baseline) / max(times[25_000] - baseline, 1e-3)
    assert ratio < 6.0, f'4 x the columns took {ratio:.1f} x the time (linear: 4)'
    return (f'CPU s: 25,000 columns {times[25_000]:.1f}, 100,000 columns '
            f'{times[100_000]:.1f} (start-up {baseline:.1f}): {ratio:.1f} x the time for '
            '4 x the columns')


# ------------------------------------------------------------------------ the bridge
def _bridge_ports(**front_options: object):
    """Return (front, SDK server) set up as the bridge does (TLS upstream, default origins)."""
    import foxglove

    from rwa_monitor.nodes.foxglove_front import loopback_certificate, trusting, WebSocketFront
    certificate, key = loopback_certificate()
    context = foxglove.Context()
    channel = foxglove.Channel('/busy', schema={'type': 'object'}, context=context)
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context,
                                   tls_cert=certificate, tls_key=key)
    gate = WebSocketFront('127.0.0.1', 0, server.port, [], lambda text: None,
                          upstream_tls=trusting(certificate), **front_options)
    gate.sdk_context = context      # a context no one holds stops advertising its channels
    return gate, server, channel


def bridge_foreign_page(folder: pathlib.Path) -> str:
    """Connect with Origin https://evil.example to the front and to the SDK's own port."""
    import ssl

    from websockets.exceptions import InvalidMessage, InvalidStatus
    from websockets.sync.client import connect
    gate, server, _ = _bridge_ports()
    outcomes = []
    try:
        try:
            connect(f'ws://127.0.0.1:{gate.port}', subprotocols=['foxglove.sdk.v1'],
                    open_timeout=5, origin='https://evil.example').close()
            outcomes.append('front open')
        except InvalidStatus as err:
            outcomes.append(f'front HTTP {err.response.status_code}')
        for scheme in ('ws', 'wss'):
            try:
                connect(f'{scheme}://127.0.0.1:{server.port}', open_timeout=5,
                        subprotocols=['foxglove.sdk.v1'], origin='https://evil.example').close()
                outcomes.append(f'SDK {scheme} open')
            except ssl.SSLCertVerificationError:
                outcomes.append(f'SDK {scheme}: certificate not trusted')
            except (InvalidMessage, OSError, EOFError) as err:
                outcomes.append(f'SDK {scheme}: {type(err).__name__}')
        with connect(f'ws://127.0.0.1:{gate.port}', subprotocols=['foxglove.sdk.v1'],
                     open_timeout=5, origin='http://localhost:3000') as ws:
            assert ws.recv(timeout=5)
    finally:
        gate.stop()
        server.stop()
    assert outcomes[0] == 'front HTTP 403' and not any('open' in o for o in outcomes), outcomes
    return '; '.join(outcomes) + '; a page of http://localhost:3000 served'


_IDLE_CLIENT = '''
import json, sys, time
from websockets.sync.client import connect
ws = connect(sys.argv[1], subprotocols=['foxglove.sdk.v1'], ping_interval=None)
while True:
    frame = ws.recv()
    if isinstance(frame, str) and json.loads(frame).get('op') == 'advertise':
        channel = json.loads(frame)['channels'][0]['id']
        ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 1, 'channelId': channel}]}))
        break
print('subscribed', flush=True)
time.sleep(600)
'''


def bridge_idle_clients(folder: pathlib.Path) -> str:
    """Let 5 subscribed clients stop reading (SIGSTOP) under load, then kill them."""
    import logging
    import os
    import signal
    import threading
    import time

    def fds() -> int:
        return len(os.listdir('/proc/self/fd'))
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append
    logging.getLogger().addHandler(handler)
    gate, server, channel = _bridge_ports(max_clients=32)      # default keepalive (20 s)
    stop = threading.Event()

    def pump() -> None:
        payload = b'{"x": "' + b'y' * 2000 + b'"}'
        while not stop.is_set():
            channel.log(payload)
            time.sleep(0.0005)
    threading.Thread(target=pump, daemon=True).start()
    before = fds()
    clients = [subprocess.Popen([sys.executable, '-c', _IDLE_CLIENT,
                                 f'ws://127.0.0.1:{gate.port}'], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True) for _ in range(5)]
    try:
        for client in clients:
            assert client.stdout.readline().strip() == 'subscribed'
            client.stdout.close()
        held = fds() - before
        for client in clients:
            client.send_signal(signal.SIGSTOP)
        start = time.monotonic()
        while gate.clients and time.monotonic() - start < 120:
            time.sleep(0.2)
        dropped_after = time.monotonic() - start
    finally:
        for client in clients:
            client.kill()
            client.wait()
        stop.set()
    end = time.monotonic() + 30
    while fds() > before and time.monotonic() < end:
        time.sleep(0.2)
    left = fds() - before
    gate.stop()
    server.stop()
    logging.getLogger().removeHandler(handler)
    tracebacks = [r for r in records if r.exc_info]
    assert not tracebacks, f'{len(tracebacks)} tracebacks: {tracebacks[0].getMessage()}'
    assert held <= 15 and left <= 0, (held, left)
    return (f'{held} descriptors for 5 clients, {max(left, 0)} left after; dropped '
            f'{dropped_after:.0f} s after they stopped reading; 0 tracebacks logged '
            f'({gate.disconnects} disconnects counted)')


# ---------------------------------------------------------------------- the first run
def first_detect_cold_cache(folder: pathlib.Path) -> str:
    """Run the first detect of a machine (an empty kernel cache): a notice, then a result."""
    import os
    import resource
    import time
    source = wheels_file(folder, 600)
    env = {**os.environ, 'NUMBA_CACHE_DIR': str(folder / 'kernel_cache')}
    outcomes = []
    for label in ('cold', 'warm'):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', 'detect', source,
                               '-o', folder / f'{label}.json'], capture_output=True, text=True,
                              env=env, timeout=900)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        assert done.returncode in (0, 3), done.stderr[-500:]
        outcomes.append((label, cpu, wall, done.stderr))
    cold, warm = outcomes
    assert 'first run on this machine: compiling' in cold[3], cold[3][-500:]
    assert 'compiling' not in warm[3], warm[3][-500:]
    kernels = cold[3].count('rwa-monitor: compiled ')
    return (f'cold cache: notice, {kernels} kernels compiled, {cold[1]:.1f} s CPU '
            f'({cold[2]:.0f} s wall); warm: no notice, {warm[1]:.1f} s CPU '
            f'({warm[2]:.0f} s wall)')


def fleet_progress_in_a_log(folder: pathlib.Path) -> str:
    """Run simulate fleet --calibrate with stderr to a file: lines while it works."""
    done = run_process('simulate', 'fleet', '-o', folder / 'fleet', '--spacecraft', '1',
                       '--days', '1', '--wheels', '2', '--calibrate', '--seed', '1')
    assert done.returncode == 0, done.stderr[-500:]
    lines = [line for line in done.stderr.splitlines() if 'simulate fleet:' in line]
    assert any('passes written' in line for line in lines), done.stderr
    assert lines[-1].endswith('done') and '\r' not in done.stderr
    return f'{len(lines)} progress lines in the log, e.g. "{lines[-1]}"'


def readable_tables(folder: pathlib.Path) -> str:
    """Print detect's table and the demo's view and summary: numbers a person reads."""
    import re

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from rwa_monitor.cli import cmd_dashboard, cmd_demo
    from rwa_monitor.core.events import AnomalyEvent
    from rwa_monitor.nodes import messages
    path = folder / 'run.csv'
    code, _, err = run('simulate', 'friction', '--wheels', '2', '--seconds', '600',
                       '--anomaly', 'rw2:dry:300:+3e-4', '--seed', '36', '-o', path)
    assert code == 0, err
    code, table, err = run('detect', path)
    assert code == 1 and '{' not in table and not re.search(r'\d\.\d{8,}', table), table
    board = cmd_dashboard.Board()
    events = DiagnosticArray()
    events.status = [messages.event_status(AnomalyEvent('llr', 'rw2', 'dry', 300.0, 3000,
                                                        375.0, 3750, 0.0), 'llr_detector'),
                     messages.event_status(AnomalyEvent('fss', 'rw3', 'viscous', 10.0, 100,
                                                        20.0, 200), 'fss_diagnoser')]
    board.on_anomalies(events)
    health = DiagnosticArray()
    health.status = [DiagnosticStatus(
        level=DiagnosticStatus.STALE, name='fss_diagnoser: rw1 window diagnosis',
        hardware_id='rw1', message='unknown: not examined yet, waiting for a full window',
        values=[KeyValue(key='waiting_samples', value='79000')])]
    board.on_diagnostics(health)
    view = cmd_dashboard.render(board)
    assert 'p=< 1e-300' in view and 'p=n/a' in view and 'nan' not in view
    assert ' WAIT ' in next(line for line in view.splitlines() if line.startswith('rw1'))
    result = cmd_demo.DemoResult(
        rows=10, wall_s=1.0, executor='events', events=[], pipeline_events=[], changes=[],
        matches=[], false_alarms=[], notes=[], other_detectors={'vsadc': 1},
        other_events=[{'component': 'gyro_y', 'level': 2, 'fields': {
            'detector': 'vsadc', 'kind': 'drift', 'change_time_s': 185.0,
            'declaration_time_s': 230.0}}], gyro_faults=[('gyro_y', 'drift', 180.0)])
    summary = cmd_demo.summary(result)
    assert any(line.startswith('gyro_y drift') for line in summary.splitlines())
    assert 'levels: OK' in summary
    return ('detect table without JSON or 17-digit floats; view: p=< 1e-300, p=n/a, a '
            'filling window diagnoser WAIT, levels legend; demo truth table lists gyro_y drift')


CASES: list[tuple[str, Callable[[pathlib.Path], str]]] = [
    ('36 events_file naming a pretty-printed JSON file', journal_pretty_json),
    ('36 node: events_file naming a pretty-printed JSON file', journal_node_pretty_json),
    ('36 diagnose: a friction column of 1e300', diagnose_friction_1e300),
    ('36 diagnose: 1 % of friction rows at -1e300', diagnose_friction_1pct_minus_1e300),
    ('36 diagnose: 1 % of speed rows at 1e300', diagnose_speed_1pct_1e300),
    ('36 -o (and an input) through a loop of symbolic links', output_symlink_loop),
    ('36 -o a dangling link whose folder is missing', dangling_link_missing_folder),
    ('36 .cal.*.tmp/ left by a SIGKILLed calibrate', killed_calibrate_temporary),
    ('36 identify on a friction column of 1e300', identify_column_1e300),
    ('36 detect on a CSV of 100,000 columns x 20 rows', wide_file_scaling),
    ('36 bridge: a page of another origin, on the front and on the SDK port',
     bridge_foreign_page),
    ('36 bridge: 5 idle clients stop reading, then leave', bridge_idle_clients),
    ('36 the first detect of a machine (empty kernel cache)', first_detect_cold_cache),
    ('36 simulate fleet with its output to a log', fleet_progress_in_a_log),
    ('36 tables: detect, the live view, the demo summary', readable_tables),
]

# The command a person runs to see each case (bench/bench_faults.py tables it).
COMMANDS = {
    '36 events_file naming a pretty-printed JSON file':
        'rwa-monitor detect run.csv -o events.json; rwa-monitor-llr --ros-args -p '
        'events_file:=events.json',
    '36 node: events_file naming a pretty-printed JSON file':
        'rwa-monitor-fss --ros-args -p events_file:=events.json',
    '36 diagnose: a friction column of 1e300': 'rwa-monitor diagnose f1e300.csv -o d.json',
    '36 diagnose: 1 % of friction rows at -1e300': 'rwa-monitor diagnose f.csv -o d.json',
    '36 diagnose: 1 % of speed rows at 1e300': 'rwa-monitor diagnose s.csv -o d.json',
    '36 -o (and an input) through a loop of symbolic links':
        'ln -s b a; ln -s a b; rwa-monitor detect run.csv -o a',
    '36 -o a dangling link whose folder is missing':
        'ln -s gone/deeper/events.json events.json; rwa-monitor detect run.csv -o events.json',
    '36 .cal.*.tmp/ left by a SIGKILLed calibrate':
        'kill -9 during rwa-monitor calibrate run.csv -o cal; rwa-monitor calibrate run.csv '
        '-o cal',
    '36 identify on a friction column of 1e300':
        'rwa-monitor identify f1e300.csv --wheel rw1 -o id',
    '36 detect on a CSV of 100,000 columns x 20 rows': 'rwa-monitor detect wide.csv -o w.json',
    '36 bridge: a page of another origin, on the front and on the SDK port':
        'rwa-monitor-foxglove; a page of https://evil.example opens ws://127.0.0.1:PORT',
    '36 bridge: 5 idle clients stop reading, then leave':
        'rwa-monitor-foxglove; 5 clients subscribe, kill -STOP, kill -9',
    '36 the first detect of a machine (empty kernel cache)':
        'NUMBA_CACHE_DIR=empty rwa-monitor detect run.csv -o e.json (twice)',
    '36 simulate fleet with its output to a log':
        'rwa-monitor simulate fleet -o fleet --spacecraft 1 --days 1 --calibrate 2> log',
    '36 tables: detect, the live view, the demo summary': 'rwa-monitor detect run.csv; make demo',
}

# Cases run by the bench only, never as unit tests: a timing (no timing assertions in
# tests) and one that waits out the real keepalive (test_foxglove_bridge.py runs it short).
BENCH_ONLY = ('36 detect on a CSV of 100,000 columns x 20 rows',   # a timing
              '36 bridge: 5 idle clients stop reading, then leave',  # ~50 s: real keepalive
              '36 the first detect of a machine (empty kernel cache)',   # minutes of compile
              '36 simulate fleet with its output to a log')   # test_jit_first_use: Progress
