"""The fleet engine on Dask distributed: every spacecraft's passes through its detectors.

Graph (docs/usage.md "Fleet"): one ``scan`` task per spacecraft (first stamp and columns
of its candidate passes), then per spacecraft its passes in time order by first stamp,
in groups of consecutive passes (``task_bytes``): one ``read`` task per group and, per
component (each wheel with a friction column, the gyro), a chain of
``step`` tasks (:mod:`rwa_monitor.fleet.components`) that carries the detector state as
data from pass to pass. Chains of different components and spacecraft run in parallel;
a chain runs in pass order. Every task is pure: a worker that dies mid-run has its tasks
run again elsewhere by the scheduler, with the same result. The client keeps only the
last task of each chain, so the scheduler frees each pass once its components have
taken it.

The cluster is a ``LocalCluster`` of ``workers`` processes started here, or the one at
``scheduler`` (``dask scheduler`` / ``dask worker``).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
import functools
import logging
import math
import pathlib
import sys
import time as _time
from typing import Any, Callable, Iterator, Mapping

from rwa_monitor.core.schema import FLEET, LLR, VSADC
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet import archive as arc, components as comp, state
from rwa_monitor.telemetry.parameters_file import block_values, read_parameters_file

CALIBRATION_KEY = 'calibration_file'
# Passes of one component taken by one task: consecutive ones up to about this many bytes
# of files (a short pass is ~1 ms of detector work, less than a task's own cost).
TASK_BYTES = 32 << 20


@dataclass
class FleetResult:
    """A fleet run: events (dicts with ``spacecraft``), summary, trend rows, timings."""

    events: list[dict[str, Any]]
    summary: dict[str, Any]
    trend: list[dict[str, Any]]
    timings: dict[str, Any]
    anomaly: bool = False
    incomplete: bool = False
    save_state: Callable[[], None] | None = None

    def commit(self) -> None:
        """Write the detector state of this run into the ``--state`` folder (if any)."""
        if self.save_state is not None:
            self.save_state()
            self.save_state = None


@contextlib.contextmanager
def dask_client(workers: int = 2, scheduler: str | None = None) -> Iterator[Any]:
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
    # No dashboard; the scheduler's small HTTP server on a free port of this machine only.
    # No worker profiler: it samples the task thread every 10 ms for the dashboard, and
    # took the run's wall time from 0.85 s to 1.30 s (mean of 6 runs each, 3 spacecraft x
    # 2 days, 1 worker, load 5-7).
    import dask
    with dask.config.set({'distributed.worker.profile.enabled': False}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                         dashboard_address=None, silence_logs=logging.ERROR,
                         scheduler_kwargs={'dashboard_address': '127.0.0.1:0'}) as cluster, \
            Client(cluster) as client:
        yield client


def node_blocks(config_path: pathlib.Path | None) -> dict[str, dict[str, Any]]:
    """Return the checked llr, vsadc and fleet parameter blocks of a parameters file."""
    config = read_parameters_file(config_path)
    where = config_path or 'installed parameters'
    blocks = {'llr': dict(block_values(config, LLR, where)),
              'vsadc': dict(block_values(config, VSADC, where)),
              'fleet': dict(block_values(config, FLEET, where))}
    LLR.validate(blocks['llr'])
    VSADC.validate(blocks['vsadc'])
    if blocks['llr'].get('friction_model_file'):
        raise ConfigError('friction_model_file: a refined friction model is not supported '
                          'by rwa-monitor fleet yet (use detect per file)')
    return blocks


def run_archive(archive: str | pathlib.Path, *, client: Any = None, workers: int = 2,
                scheduler: str | None = None, config: pathlib.Path | None = None,
                state_dir: pathlib.Path | None = None, progress: bool = False,
                task_bytes: int = TASK_BYTES, commit: bool = True) -> FleetResult:
    """Run the fleet over ``archive`` and return the result (saves the state if given).

    ``client``: an existing distributed Client (else one is made from ``workers`` or
    ``scheduler``); ``task_bytes``: passes per ``step`` task, by their files' bytes (1:
    one pass per task). ``commit``: save the state at once; else the caller calls
    ``result.commit()`` once the outputs are written (the command does, so that a run
    whose outputs fail leaves the state where it was). Raise ConfigError for bad
    parameters or a refused state.
    """
    blocks = node_blocks(config)
    fleet = arc.list_archive(archive)
    start_wall, start_cpu = _time.perf_counter(), _time.process_time()
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(dask_client(workers, scheduler))
        plan = _plan(client, fleet, blocks, state_dir)
        finals = _submit(client, plan, task_bytes)
        if progress and sys.stderr.isatty():
            from distributed import progress as bar
            bar([f for f in finals.values() if not isinstance(f, dict)])
        chains = dict(zip(finals, client.gather(list(finals.values()))))
        engine = {'name': 'dask.distributed', 'scheduler': client.scheduler.address,
                  'workers': len(client.scheduler_info()['workers'])}
    wall = _time.perf_counter() - start_wall
    result = _assemble(plan, chains, engine)
    add_trends(result.summary, result.trend, trend_limits(blocks['fleet']))
    result.timings = _timings(chains, wall, _time.process_time() - start_cpu)
    result.summary['engine'].update(result.timings)
    result.summary['config'] = str(config or 'installed parameters')
    result.summary['state'] = None if state_dir is None else str(state_dir)
    if state_dir is not None:
        result.save_state = functools.partial(_save_states, pathlib.Path(state_dir), plan,
                                              chains)
        if commit:
            result.commit()
    return result


def _plan(client: Any, fleet: list[arc.Spacecraft], blocks: Mapping[str, Any],
          state_dir: pathlib.Path | None) -> list[dict[str, Any]]:
    """Return per spacecraft: specs, passes to run in time order, prior chains, issues."""
    plan = [_prior(craft, blocks, state_dir) for craft in fleet]
    batches = [entry['to_scan'] for entry in plan if entry['to_scan']]
    scans = {}
    found = client.gather(client.map(arc.scan_passes, batches, pure=False))
    for paths, passes in zip(batches, found):
        scans.update(zip(paths, passes))
    for entry in plan:
        readable = []
        for path in entry.pop('to_scan'):
            found = scans[path]
            if isinstance(found, str):
                entry['unreadable'][pathlib.Path(path).name] = found
            else:
                readable.append(found)
        if entry['error']:
            continue
        readable.sort(key=lambda p: (p.first, p.name))
        names = _components(entry, readable)
        try:
            entry['specs'] = _specs(entry['craft'], names, blocks, entry['calibration'])
        except ConfigError as err:
            entry['error'] = str(err)
            continue
        entry['passes'] = readable
    return plan


def _prior(craft: arc.Spacecraft, blocks: Mapping[str, Any],
           state_dir: pathlib.Path | None) -> dict[str, Any]:
    """Return a spacecraft's plan entry: calibration, saved state, passes left to scan.

    Passes the state holds (same name and size) are not scanned again.
    """
    entry: dict[str, Any] = {'craft': craft, 'unreadable': {}, 'passes': [], 'specs': [],
                             'prior': {}, 'done': [], 'error': None, 'skipped': [],
                             'to_scan': list(craft.candidates), 'calibration': ''}
    try:
        entry['calibration'], text = _calibration(craft)
    except ConfigError as err:
        entry['error'] = str(err)
        return entry
    entry['print'] = state.fingerprint({'llr': blocks['llr'], 'vsadc': blocks['vsadc'],
                                        'calibration': text})
    if state_dir is not None:
        saved = state.load(pathlib.Path(state_dir), craft.id, entry['print'])
        if saved is not None:
            entry['done'], entry['prior'] = saved
    done = {(p['name'], p['size']) for p in entry['done']}
    here = {path: (pathlib.Path(path).name, _size(path)) for path in craft.candidates}
    entry['skipped'] = [p['name'] for p in entry['done']
                        if (p['name'], p['size']) in here.values()]
    entry['to_scan'] = [path for path, key in here.items() if key not in done]
    return entry


def _size(path: str) -> int:
    """Return a pass's size in bytes, or -1 if it cannot be read now."""
    try:
        return arc.size_of(path)
    except OSError:
        return -1


def _calibration(craft: arc.Spacecraft) -> tuple[str, str | None]:
    """Return the spacecraft's calibration path ('' if none) and its text for the print."""
    if craft.calibration is None:
        return '', None
    try:
        return craft.calibration, pathlib.Path(craft.calibration).read_text()
    except OSError as err:
        raise ConfigError(f'{craft.calibration}: cannot read: {err}') from None


def _components(entry: dict[str, Any], readable: list[arc.PassFile]) -> list[str]:
    """Return the components of a spacecraft; passes with others are set aside."""
    names = list(entry['prior']) or (arc.components(readable[0].columns) if readable
                                     else [])
    for p in list(readable):
        found = arc.components(p.columns)
        if set(found) != set(names):        # column order may differ between passes
            readable.remove(p)
            entry['unreadable'][p.name] = (f'components {", ".join(found) or "none"} differ '
                                           f'from the spacecraft\'s {", ".join(names)}')
    return names


def _specs(craft: arc.Spacecraft, names: list[str], blocks: Mapping[str, Any],
           calibration: str) -> list[comp.ComponentSpec]:
    """Return the component specs (ConfigError if a wheel lacks a calibration)."""
    specs = []
    for name in names:
        params = dict(blocks['vsadc' if name == arc.GYRO_COMPONENT else 'llr'])
        params[CALIBRATION_KEY] = calibration
        specs.append(comp.ComponentSpec(craft.id, name, params))
    if calibration:
        from rwa_monitor.core.calibrate import check_wheels
        from rwa_monitor.telemetry.calibration_file import load, load_gyro_calibration
        check_wheels(load(calibration), [n for n in names if n != arc.GYRO_COMPONENT],
                     calibration)
        if arc.GYRO_COMPONENT in names:
            load_gyro_calibration(calibration)   # detect --calibration needs it too
    return specs


def _submit(client: Any, plan: list[dict[str, Any]], task_bytes: int
            ) -> dict[tuple[str, str], Any]:
    """Submit every chain; return (spacecraft, component) -> future of its last step.

    Submitted group by group (the group's reads, then each component's step): earlier
    tasks have the higher priority, so the scheduler reads a pass when the steps before
    it are done or running, and a worker holds a few passes, not a spacecraft's archive.
    """
    finals = {}
    for entry in plan:
        chains = {s.component: comp.new_chain(entry['prior'].get(s.component))
                  for s in entry['specs']}
        groups = _groups(entry['passes'], task_bytes)
        for first, end in groups:
            passes = entry['passes'][first:end]
            reads = client.submit(comp.read, [p.path for p in passes], pure=False)
            for n, spec in enumerate(entry['specs']):
                chains[spec.component] = client.submit(
                    comp.step, spec, chains[spec.component], reads, [p.name for p in passes],
                    n == 0, end == len(entry['passes']), pure=False)
        for spec in entry['specs']:
            finals[(spec.spacecraft, spec.component)] = chains[spec.component]
    return finals


def _groups(passes: list[arc.PassFile], task_bytes: int) -> list[tuple[int, int]]:
    """Return runs of consecutive passes of about ``task_bytes``, one task each."""
    groups, first, size = [], 0, 0
    for i, p in enumerate(passes):
        size += p.size
        if size >= task_bytes or i == len(passes) - 1:
            groups.append((first, i + 1))
            first, size = i + 1, 0
    return groups


def _assemble(plan: list[dict[str, Any]], chains: Mapping[tuple[str, str], Any],
              engine: dict[str, Any]) -> FleetResult:
    """Return events, summary and trend rows from the finished chains."""
    from rwa_monitor.fleet.summary import spacecraft_summary
    events: list[dict[str, Any]] = []
    trend: list[dict[str, Any]] = []
    crafts = {}
    anomaly = incomplete = False
    for entry in plan:
        craft = entry['craft']
        mine = {spec.component: chains[(craft.id, spec.component)] for spec in entry['specs']}
        found = [e for c in mine.values() for e in c['events']]
        found.sort(key=lambda e: (e.time, e.component, e.revision))
        anomaly |= any(e.kind != 'healthy' for e in found)
        events.extend({'spacecraft': craft.id, **e.to_json()} for e in found)
        for spec in entry['specs']:
            trend.extend(_history(entry, spec.component))
            trend.extend(mine[spec.component]['trend'])
        crafts[craft.id] = spacecraft_summary(entry, mine, found)
        incomplete |= bool(crafts[craft.id]['not_examined'])
    summary = {'spacecraft': crafts, 'events': len(events), 'engine': engine}
    return FleetResult(events, summary, trend, {}, anomaly, incomplete)


def trend_limits(fleet_block: Mapping[str, Any]) -> dict[str, float]:
    """Return the limits of the fleet block that are set (``dry``/``viscous``; 0 = none)."""
    return {level: float(fleet_block[f'{level}_limit']) for level in ('dry', 'viscous')
            if fleet_block[f'{level}_limit'] > 0.0}


def add_trends(summary: dict[str, Any], trend_rows: list[dict[str, Any]],
               limits: Mapping[str, float]) -> None:
    """Write each wheel's trend (fleet/report.py wheel_trends) into its summary entry.

    ``summary['trend_limits']``: the limits; per spacecraft and wheel ``trend``: passes,
    reference and per level the slope per day, its standard error, p-value, the limit and
    the projected crossing with its interval (telemetry time in s; null where a number is
    not defined, and for an end of the interval the data cannot bound).
    """
    from rwa_monitor.fleet.report import wheel_trends
    summary['trend_limits'] = dict(limits)
    for entry in wheel_trends(trend_rows, limits):
        craft = summary['spacecraft'].get(entry['spacecraft'])
        wheel = craft and craft['components'].get(entry['wheel'])
        if wheel is None:
            continue
        wheel['trend'] = {k: _json_number(v) for k, v in entry.items()
                          if k not in ('spacecraft', 'wheel')}


def _json_number(value: Any) -> Any:
    """Return ``value`` with a non-finite float as None (JSON has no NaN or infinity)."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _timings(chains: Mapping[Any, Any], wall: float, client_cpu: float) -> dict[str, Any]:
    """Return wall, client CPU, per-worker CPU and peak RSS, samples and rate."""
    workers: dict[str, dict[str, float]] = {}
    samples = 0
    for chain in chains.values():
        samples += sum(p.get('samples', 0) for p in chain['passes'])
        for worker, facts in chain['work'].items():
            entry = workers.setdefault(worker, {'cpu_s': 0.0, 'peak_rss_mb': 0.0, 'tasks': 0})
            entry['cpu_s'] += facts['cpu_s']
            entry['tasks'] += facts['tasks']
            entry['peak_rss_mb'] = max(entry['peak_rss_mb'], facts['peak_rss_mb'])
    cpu = sum(w['cpu_s'] for w in workers.values())
    return {'wall_s': wall, 'client_cpu_s': client_cpu, 'cpu_s': cpu, 'per_worker': workers,
            'component_samples': samples,
            'samples_per_cpu_s': samples / cpu if cpu > 0 else math.nan}


def _save_states(folder: pathlib.Path, plan: list[dict[str, Any]],
                 chains: Mapping[tuple[str, str], Any]) -> None:
    """Write each spacecraft's state: prior passes plus the ones this run read."""
    for entry in plan:
        if entry['error'] or not entry['specs']:
            continue
        craft = entry['craft']
        mine = {s.component: chains[(craft.id, s.component)] for s in entry['specs']}
        failed = {p['pass'] for c in mine.values() for p in c['passes'] if 'error' in p}
        done = list(entry['done']) + [{'name': p.name, 'size': p.size, 'first': p.first}
                                      for p in entry['passes'] if p.name not in failed]
        state.save(folder, craft.id, entry['print'], done,
                   {k: comp.persistent(c, _history(entry, k)) for k, c in mine.items()})


def _history(entry: Mapping[str, Any], component: str) -> list[dict[str, Any]]:
    """Return the trend rows of a component's passes before this run (from the state)."""
    return entry['prior'].get(component, {}).get('history', [])


def measure(archive: str | pathlib.Path, *, workers: int = 1,
            config: pathlib.Path | None = None) -> dict[str, Any]:
    """Run the engine on a local cluster of ``workers``; return its timings (bench fleet).

    Keys: ``wall_s``, ``cpu_s`` (sum over workers), ``per_worker`` (``cpu_s``,
    ``peak_rss_mb``, ``tasks``), ``component_samples``, ``samples_per_cpu_s``, ``events``.
    """
    result = run_archive(archive, workers=workers, config=config)
    return {**result.timings, 'events': len(result.events)}
