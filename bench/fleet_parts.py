"""Where the fleet's CPU goes against ``detect``, in one process (``python -m bench fleet``).

The engine's own code without Dask, warm (a first run of each is left out): the plan's
scan of every pass (fleet/plan.py, as its ``scan`` tasks run it), each spacecraft's
``step`` tasks (fleet/chain.py, grouped as the engine groups them) split into reading the
passes, feeding the runners, the trend levels (``_trend_row``) and the rest, and ``detect``
on the joined files split into reading and detecting. The split times the calls inside
the running step (the caches as a step leaves them, not as a loop of one kind of call
would); what the cluster adds is the engine's CPU less these steps. docs/fleet.md "CPU
against detect" reads it.
"""

from __future__ import annotations

import contextlib
import math
import pathlib
import statistics
import time
from typing import Any, Callable, Iterator

PARTS = {'read': ('rwa_monitor.fleet.chain', 'read_pass'),
         'trend': ('rwa_monitor.fleet.chain', '_trend_row'),
         'feed': ('rwa_monitor.core.wheel_runner', 'WheelRunner.feed')}


@contextlib.contextmanager
def timed_calls(spent: dict[str, float]) -> Iterator[None]:
    """Add the CPU time of each call of PARTS to ``spent`` while inside; restore after."""
    import importlib
    saved = []
    for part, (module, name) in PARTS.items():
        owner: Any = importlib.import_module(module)
        *path, attribute = name.split('.')
        for step in path:
            owner = getattr(owner, step)
        original = getattr(owner, attribute)
        saved.append((owner, attribute, original))
        setattr(owner, attribute, _timer(original, part, spent))
    try:
        yield
    finally:
        for owner, attribute, original in saved:
            setattr(owner, attribute, original)


def _timer(function: Callable, part: str, spent: dict[str, float]) -> Callable:
    def timed(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            spent[part] = spent.get(part, 0.0) + time.process_time() - start
    return timed


def split(archive: pathlib.Path, joined: list[pathlib.Path], repeats: int = 5
          ) -> dict[str, float]:
    """Return the median CPU seconds of each part over ``repeats`` warm runs."""
    from rwa_monitor.cli.cmd_detect import load_config
    from rwa_monitor.fleet import archive as arc, plan
    from rwa_monitor.fleet.chain import step
    from rwa_monitor.fleet.engine import _groups, fleet_parameters_file, node_blocks, TASK_BYTES
    from rwa_monitor.fleet.records import Chain
    from rwa_monitor.pipelines import detect
    from rwa_monitor.telemetry import read_telemetry
    blocks = node_blocks(None)
    config = load_config(fleet_parameters_file())
    crafts = arc.list_archive(archive)

    def scan() -> list[plan.SpacecraftPlan]:
        plans = []
        for craft in crafts:
            first = plan._prior(craft, blocks, None)
            found = dict(zip(craft.candidates, arc.scan_passes(craft.candidates)))
            plans.append(plan._complete(first, found, blocks))
        return plans

    def steps(plans: list[plan.SpacecraftPlan]) -> int:
        events = 0
        for p in plans:
            chain = Chain(-math.inf, {})
            for first, end in _groups(p.passes, TASK_BYTES):
                chain = step(p.spec, chain, p.passes[first:end], end == len(p.passes))
            events += len(chain.events) + len(chain.end_of_run)
        return events

    steps(scan())
    detect(read_telemetry(joined[0]), config)
    runs = []
    for _ in range(repeats):
        run: dict[str, float] = {}
        start = time.process_time()
        plans = scan()
        run['scan'] = time.process_time() - start
        spent: dict[str, float] = {}
        with timed_calls(spent):
            start = time.process_time()
            fleet_events = steps(plans)
            run['step'] = time.process_time() - start
        run.update({f'step_{k}': v for k, v in spent.items()})
        run['step_rest'] = run['step'] - sum(spent.values())
        run['detect_read'] = run['detect_detect'] = 0.0
        detect_events = 0
        for path in joined:
            start = time.process_time()
            tele = read_telemetry(path)
            middle = time.process_time()
            detect_events += len(detect(tele, config).events)
            run['detect_read'] += middle - start
            run['detect_detect'] += time.process_time() - middle
        run['detect'] = run['detect_read'] + run['detect_detect']
        run['events_fleet'], run['events_detect'] = fleet_events, detect_events
        runs.append(run)
    return {k: statistics.median(r[k] for r in runs) for k in runs[0]}


def _idle(seconds: float) -> None:
    """Wait without computing (a task of the idle twin)."""
    time.sleep(seconds)


def dask_floor(client: Any, tasks: int, wall_s: float) -> dict[str, float]:
    """Return the CPU Dask spends on a run with nothing to compute (the idle twin).

    ``tasks`` tasks that each sleep ``wall_s / tasks``, submitted and collected as the
    engine does (fleet/engine.py ``_gather``: ``as_completed``, then each result), on the
    warm cluster of ``client``: about the fleet run's task count and wall time, so that
    what the client process (its scheduler, client and nanny threads) and the worker
    processes spend is the cluster's own cost at that size, with no pass read or fed.
    """
    from distributed import as_completed
    before = client.run(time.process_time)
    start_cpu, start_wall = time.process_time(), time.perf_counter()
    futures = [client.submit(_idle, wall_s / tasks, pure=False) for _ in range(tasks)]
    for future in as_completed(futures):
        future.result()
    client_cpu = time.process_time() - start_cpu
    wall = time.perf_counter() - start_wall
    after = client.run(time.process_time)
    workers = sum(after[w] - before[w] for w in after if w in before)
    return {'tasks': tasks, 'wall_s': wall, 'client_cpu_s': client_cpu,
            'worker_process_cpu_s': workers}
