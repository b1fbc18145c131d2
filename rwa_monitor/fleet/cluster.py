"""The fleet's Dask cluster: made in a thread while the run does its own start, closed so too.

A local cluster's start is mostly waiting: its worker processes start Python and import
Dask while the client process idles, then the client imports the engine and loads the
state while the workers idle. :class:`ClusterStart` overlaps the two: it makes the client
in a thread of its own at once, and the run asks for it (:meth:`ClusterStart.client`)
only when the plan needs it. At the other end :meth:`ClusterStart.release` closes the
cluster in the same thread while the run assembles and writes its outputs. The run's
results do not depend on it: the same tasks reach the same workers either way.
Measured in docs/fleet.md "Fixed costs of a command".

Its workers are forks of one server process (multiprocessing's fork server) that imported
the engine and loaded the compiled kernels once (fleet/worker_start.py); the server is
started first of all, so that it loads them while the client imports and reads the
state. A worker that is spawned instead starts a new Python and imports and loads all of
it again, each worker for itself.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import multiprocessing
from multiprocessing import forkserver
from typing import Any, Callable, Iterator, TYPE_CHECKING

from rwa_monitor.exceptions import ConfigError

if TYPE_CHECKING:
    from distributed import Client


WORKER_START = 'rwa_monitor.fleet.worker_start'


def start_fork_server() -> None:
    """Start the server local workers fork from, loading what they need (once a process).

    The server stays for the life of this process, and every local cluster it makes forks
    its workers from it; a server already running is left as it is.
    """
    multiprocessing.get_context('forkserver').set_forkserver_preload([WORKER_START])
    forkserver.ensure_running()


@contextlib.contextmanager
def dask_client(workers: int = 2, scheduler: str | None = None) -> Iterator[Client]:
    """Yield a distributed Client: to ``scheduler``, or to a local cluster of processes."""
    from distributed import Client, LocalCluster
    if scheduler:
        try:
            client = Client(scheduler, timeout=30)
        except (OSError, TimeoutError) as err:
            raise ConfigError(f'cannot reach the Dask scheduler {scheduler}: {err}') from None
        with client:
            yield client
        return
    if workers < 1:
        raise ConfigError(f'--workers must be at least 1, got {workers}')
    start_fork_server()
    # No dashboard; the scheduler's small HTTP server on a free port of this machine only.
    # No worker profiler: it samples the task thread every 10 ms for the dashboard, and
    # took the run's wall time from 0.85 s to 1.30 s (mean of 6 runs each, 3 spacecraft x
    # 2 days, 1 worker, load 5-7). The C library's own memory trimming, as in `detect`'s
    # process: the nanny's MALLOC_TRIM_THRESHOLD_ (64 KiB) also fixes the size from which
    # allocations are mapped and unmapped, and the same 5 spacecraft-weeks took 0.61 s of
    # the task thread's CPU with it, 0.44 s without (median of 3; 0.42 s in-process).
    import dask
    environ = dict(dask.config.get('distributed.nanny.pre-spawn-environ', None) or {})
    environ.pop('MALLOC_TRIM_THRESHOLD_', None)
    with dask.config.set({'distributed.worker.profile.enabled': False,
                          'distributed.worker.multiprocessing-method': 'forkserver',
                          'distributed.nanny.pre-spawn-environ': environ}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                         dashboard_address=None, silence_logs=logging.ERROR,
                         scheduler_kwargs={'dashboard_address': '127.0.0.1:0'}) as cluster, \
            Client(cluster) as client:
        yield client


class ClusterStart:
    """A :func:`dask_client` made in a thread from construction; closed by ``close``.

    Use it as a context manager: leaving it closes the cluster and waits for that, also
    when the run failed or never asked for the client. Errors of the start (a scheduler
    out of reach, bad ``workers``) are raised by :meth:`client`.
    """

    def __init__(self, workers: int = 2, scheduler: str | None = None) -> None:
        if not scheduler and workers >= 1:
            start_fork_server()
        self._context = dask_client(workers, scheduler)
        self._thread = concurrent.futures.ThreadPoolExecutor(
            1, thread_name_prefix='fleet-cluster')
        self._started = self._thread.submit(self._context.__enter__)
        self._closed: concurrent.futures.Future | None = None

    def client(self) -> Client:
        """Return the client, waiting for the cluster's start (its error, if it failed)."""
        if self._closed is not None:
            raise RuntimeError('the cluster was released')
        return self._started.result()

    def when_started(self, call: Callable[[Client], None]) -> None:
        """Have ``call(client)`` run in the cluster's thread once it has started.

        At once in this thread if it has already; never if the start failed (then
        :meth:`client` raises its error). What ``call`` raises is logged, not raised.
        """
        def started(future: concurrent.futures.Future) -> None:
            if future.exception() is None:
                call(future.result())
        self._started.add_done_callback(started)

    def release(self) -> None:
        """Begin closing the cluster in its thread; return at once (no more tasks)."""
        if self._closed is None:
            self._closed = self._thread.submit(self._close)

    def close(self) -> None:
        """Close the cluster (after its start, if still starting) and wait for it."""
        self.release()
        assert self._closed is not None
        try:
            self._closed.result()
        finally:
            self._thread.shutdown()

    def _close(self) -> None:
        if self._started.exception() is None:
            self._context.__exit__(None, None, None)

    def __enter__(self) -> ClusterStart:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
