"""The fleet on a real cluster: ``dask scheduler`` and two ``dask worker`` processes.

One worker is killed (SIGKILL) while the run is under way, holding results the rest of
its chains still need: the scheduler runs those tasks again on the other worker and the
events are still those of detect on the joined passes. Ports are free ones of this
machine; every wait is bounded; the processes are ended in any case.
"""

import os
import pathlib
import signal
import socket
import subprocess
import sys
import threading
import time

from distributed import Client
from fleet_archive import events_of, make_archive, references
import pytest

from rwa_monitor.fleet.engine import run_archive

DASK = str(pathlib.Path(sys.executable).with_name('dask'))
REPO = pathlib.Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def _start(args: list[str]) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO), os.environ.get('PYTHONPATH', '')]))
    return subprocess.Popen([DASK, *args], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


@pytest.fixture
def cluster():
    """Yield (scheduler address, worker processes by name); end them all afterwards."""
    port = _free_port()
    address = f'tcp://127.0.0.1:{port}'
    procs = [_start(['scheduler', '--host', '127.0.0.1', '--port', str(port),
                     '--no-dashboard'])]
    workers = {}
    try:
        for name in ('w1', 'w2'):
            workers[name] = _start(['worker', address, '--name', name, '--nthreads', '1',
                                    '--no-nanny', '--no-dashboard', '--host', '127.0.0.1'])
            procs.append(workers[name])
        yield address, workers
    finally:
        for proc in procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in procs:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=20)


def test_worker_killed_mid_run_gives_the_same_events(cluster, tmp_path):
    address, workers = cluster
    joined = make_archive(tmp_path / 'archive', tmp_path / 'work')
    reference = references(tmp_path / 'archive', joined)
    with Client(address, timeout=60) as client:
        client.wait_for_workers(2, timeout=60)
        victim = next(a for a, w in client.scheduler_info()['workers'].items()
                      if w['name'] == 'w1')
        outcome = {}

        def run():
            try:
                outcome['result'] = run_archive(tmp_path / 'archive', client=client,
                                                task_bytes=1)
            except BaseException as err:  # reported by the assertion below
                outcome['error'] = err

        thread = threading.Thread(target=run)
        thread.start()
        deadline = time.monotonic() + 120
        held = []
        while time.monotonic() < deadline and thread.is_alive():
            held = [k for k in client.has_what().get(victim, ()) if 'step' in str(k)]
            if held:
                break
            time.sleep(0.005)
        assert held and thread.is_alive(), 'the worker must hold step results mid-run'
        workers['w1'].send_signal(signal.SIGKILL)
        workers['w1'].wait(timeout=20)
        thread.join(timeout=300)
        assert not thread.is_alive()
        assert 'error' not in outcome, outcome.get('error')
        assert victim not in client.scheduler_info()['workers']
    for craft, events in reference.items():
        assert events_of(outcome['result'], craft) == events
