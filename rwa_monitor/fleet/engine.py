"""The fleet engine on Dask distributed: every spacecraft's passes through its runners.

Graph (docs/fleet.md "Engine"): ``scan`` tasks of up to 1000 candidate passes (first
stamp and columns, fleet/plan.py), then per spacecraft a chain of ``step`` tasks
(fleet/chain.py), each feeding a group of consecutive passes (about ``task_bytes`` of
files) to all the spacecraft's runners and handing their states, as data, to the next.
Spacecraft run in parallel; a spacecraft's passes run in time order. Every task is pure:
a worker that dies mid-run has its tasks run again elsewhere with the same result. The
client keeps only the last task of each chain.

The cluster is a ``LocalCluster`` of ``workers`` processes started here, or the one at
``scheduler`` (``dask scheduler`` / ``dask worker``).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import math
import pathlib
import sys
import threading
import time as _time
from typing import Mapping, TextIO, TYPE_CHECKING

from rwa_monitor import paths
from rwa_monitor.core.schema import FLEET, LLR, VSADC
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet import archive as arc, state
from rwa_monitor.fleet.chain import step
from rwa_monitor.fleet.cluster import ClusterStart
from rwa_monitor.fleet.plan import plan, SpacecraftPlan
from rwa_monitor.fleet.records import Chain, PassLog, PassRecord, SpacecraftRecord, WorkFacts
from rwa_monitor.fleet.result import FleetResult, SpacecraftResult
from rwa_monitor.fleet.trend_table import TrendTable
from rwa_monitor.telemetry.parameters_file import block_values, read_parameters_file

if TYPE_CHECKING:
    from distributed import Client, Future

# Passes of a spacecraft fed by one task: consecutive ones up to about this many bytes of
# files (a task costs a few milliseconds of the engine's own).
TASK_BYTES = 64 << 20
# Spacecraft folders listed by one task (_Listing): 100 spacecraft in 4 tasks.
LIST_TASK_FOLDERS = 25
FLEET_PARAMETERS = 'fleet.yaml'


def fleet_parameters_file() -> pathlib.Path:
    """Return the installed config/fleet.yaml: the fleet's parameters without --config."""
    return paths.config_file(FLEET_PARAMETERS)


def node_blocks(config_path: pathlib.Path | None) -> dict[str, dict[str, object]]:
    """Return the checked llr, vsadc and fleet parameter blocks of a parameters file.

    ``None``: the installed fleet parameters (config/fleet.yaml).
    """
    where = config_path or fleet_parameters_file()
    config = read_parameters_file(where)
    blocks = {'llr': dict(block_values(config, LLR, where)),
              'vsadc': dict(block_values(config, VSADC, where)),
              'fleet': dict(block_values(config, FLEET, where))}
    LLR.validate(blocks['llr'])
    VSADC.validate(blocks['vsadc'])
    return blocks


def archive_epoch(archive: pathlib.Path, configured: str,
                  fleet: list[arc.Spacecraft] | None = None) -> dt.datetime | None:
    """Return time 0 of the archive, from the first of these that gives one.

    ``epoch_utc`` of the config's fleet block; ``epoch_utc`` of ARCHIVE/archive.yaml; the
    ``epoch_utc`` of the telemetry maps of CCSDS passes (``telemetry_map.yaml`` in the
    spacecraft folders), which must then agree.
    """
    text, where = configured, 'fleet.epoch_utc'
    if not text:
        meta = arc.metadata(archive)
        text, where = str(meta.get('epoch_utc') or ''), str(archive / arc.METADATA)
    if not text:
        return _map_epoch(fleet or [])
    try:
        moment = dt.datetime.fromisoformat(str(text).replace('Z', '+00:00'))
    except ValueError:
        raise ConfigError(f'{where}: epoch_utc {text!r} is not an ISO 8601 time such as '
                          '2026-01-01T00:00:00Z') from None
    if moment.tzinfo is None:
        raise ConfigError(f'{where}: epoch_utc {text!r} has no time zone (end it with Z '
                          'for UTC)')
    return moment.astimezone(dt.timezone.utc)


def _map_epoch(fleet: list[arc.Spacecraft]) -> dt.datetime | None:
    """Return the epoch the spacecraft folders' telemetry maps share (CCSDS passes)."""
    from rwa_monitor.telemetry import ARCHIVE_MAP
    from rwa_monitor.telemetry.telemetry_map import read_map
    found = {}
    for craft in fleet:
        path = pathlib.Path(craft.folder) / ARCHIVE_MAP
        if path.is_file():
            epoch = read_map(path).epoch_utc
            if epoch is not None:
                found[str(path)] = epoch.astimezone(dt.timezone.utc)
    if len(set(found.values())) > 1:
        raise ConfigError('the telemetry maps give different epochs (' + ', '.join(
            f'{p}: {e.isoformat()}' for p, e in found.items()) + '); give epoch_utc in '
            'ARCHIVE/archive.yaml or in the fleet block of --config')
    return next(iter(found.values()), None)


def run_archive(archive: str | pathlib.Path, *, client: Client | ClusterStart | None = None,
                workers: int = 2,
                scheduler: str | None = None, config: pathlib.Path | None = None,
                state_dir: pathlib.Path | None = None, log: TextIO | None = None,
                task_bytes: int = TASK_BYTES) -> FleetResult:
    """Run the fleet over ``archive`` and return the result (not yet committed).

    ``client``: an existing distributed Client, or a cluster being started
    (fleet/cluster.py ``ClusterStart``: it is released, its closing begun, once the
    tasks are done; its owner waits for the close); else one is started here from
    ``workers`` or ``scheduler``, while the parameters and the state are read, and
    closed while the result is assembled. ``task_bytes``: passes per ``step`` task, by
    their files' bytes (1: one pass per task); ``log``: where a line per spacecraft
    finished goes. The caller writes the outputs, then calls ``result.commit()`` to move
    the state on. Raise ConfigError for bad parameters, StateError for a state that does
    not fit this run.
    """
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(ClusterStart(workers, scheduler))
        return _run(pathlib.Path(archive), client, config, state_dir, log, task_bytes)


def _run(root: pathlib.Path, cluster: Client | ClusterStart, config: pathlib.Path | None,
         state_dir: pathlib.Path | None, log: TextIO | None, task_bytes: int
         ) -> FleetResult:
    blocks = node_blocks(config)
    listing = _Listing(cluster, arc.spacecraft_folders(root))
    loaded = state.load(pathlib.Path(state_dir)) if state_dir is not None else None
    fleet = listing.result()
    epoch = archive_epoch(root, str(blocks['fleet']['epoch_utc']), fleet)
    saved = loaded.records if loaded else {}
    start_wall, start_cpu = _time.perf_counter(), _time.process_time()
    client = cluster.client() if isinstance(cluster, ClusterStart) else cluster
    try:
        plans = plan(client, fleet, blocks, saved)
    except state.StateError as err:     # name the file this run's parameters came from
        raise state.StateError(f'{err}; this run read {config or fleet_parameters_file()}'
                               ) from None
    finals = _submit(client, plans, task_bytes)
    chains = _gather(client, finals, plans, log)
    engine = {'name': 'dask.distributed', 'scheduler': client.scheduler.address,
              'workers': len(client.scheduler_info()['workers'])}
    if isinstance(cluster, ClusterStart):
        cluster.release()
    wall = _time.perf_counter() - start_wall
    run = (loaded.generation + 1) if loaded else (1 if state_dir is not None else 0)
    crafts = [_result(p, chains.get(p.id), run) for p in plans]
    prior_history = loaded.history if loaded else []
    prior_trend = loaded.trend if loaded else TrendTable.empty()
    return FleetResult.assemble(
        crafts, blocks, engine, run=run, epoch=epoch, state_dir=state_dir, loaded=loaded,
        saved=saved, prior_history=prior_history, prior_trend=prior_trend,
        timings=_timings(chains, wall, _time.process_time() - start_cpu),
        config=str(config or fleet_parameters_file()))


class _Listing:
    """The spacecraft folders listed by the workers while this process reads the state.

    A daily run late in the year lists a year of passes (219,000 files for 100
    spacecraft: about 2 s here) and reads a state that grew as much. The listing tasks
    (LIST_TASK_FOLDERS folders each) are submitted as soon as the cluster has started,
    from its thread, and gathered once the state is read; if the cluster has not started
    by then (a small archive, read quickly), this process lists the folders itself.
    Either way the same :class:`~rwa_monitor.fleet.archive.Spacecraft` come back; a
    folder the workers cannot read is a ConfigError naming it.
    """

    def __init__(self, cluster: Client | ClusterStart, folders: list[str]) -> None:
        self._folders = folders
        self._lock = threading.Lock()
        self._client: Client | None = None
        self._futures: list[Future] | None = None
        self._here = False
        if isinstance(cluster, ClusterStart):
            cluster.when_started(self._submit)
        else:
            self._submit(cluster)

    def _submit(self, client: Client) -> None:
        with self._lock:
            if self._here:
                return
            parts = [self._folders[i:i + LIST_TASK_FOLDERS]
                     for i in range(0, len(self._folders), LIST_TASK_FOLDERS)]
            self._futures = client.map(arc.list_folders, parts, pure=False)
            self._client = client

    def result(self) -> list[arc.Spacecraft]:
        """Return the spacecraft, in folder order (listed here if the tasks never left)."""
        with self._lock:
            self._here = self._futures is None
        if self._here:
            return arc.list_folders(self._folders)
        assert self._client is not None and self._futures is not None
        try:
            parts = self._client.gather(self._futures)
        except OSError as err:
            raise ConfigError(f'the workers cannot list the archive: {err} (with '
                              '--scheduler, every worker needs the archive at the same '
                              'path)') from None
        return [craft for part in parts for craft in part]


def _submit(client: Client, plans: list[SpacecraftPlan], task_bytes: int
            ) -> dict[str, Future]:
    """Submit every spacecraft's chain; return spacecraft -> future of its last step."""
    finals = {}
    for p in plans:
        if p.spec is None or not p.passes:
            continue
        prior = p.prior
        chain: Chain | Future = Chain(prior.last_time if prior else -math.inf,
                                      dict(prior.components) if prior else {})
        groups = _groups(p.passes, task_bytes)
        for first, end in groups:
            chain = client.submit(step, p.spec, chain, p.passes[first:end],
                                  end == len(p.passes), pure=False)
        finals[p.id] = chain
    return finals


def _gather(client: Client, finals: Mapping[str, Future], plans: list[SpacecraftPlan],
            log: TextIO | None) -> dict[str, Chain]:
    """Return each spacecraft's last chain, logging a line as each spacecraft finishes."""
    from distributed import as_completed
    names = {future.key: craft for craft, future in finals.items()}
    passes = {p.id: len(p.passes) for p in plans}
    chains: dict[str, Chain] = {}
    started = _time.perf_counter()
    for future in as_completed(list(finals.values())):
        craft = names[future.key]
        chains[craft] = future.result()
        if log is not None:
            done = chains[craft]
            print(f'fleet: {craft} done: {passes[craft]} passes, {len(done.events)} events '
                  f'({len(chains)}/{len(finals)} spacecraft, '
                  f'{_time.perf_counter() - started:.1f} s)', file=log, flush=True)
    return chains


def _groups(passes: tuple[arc.PassFile, ...], task_bytes: int) -> list[tuple[int, int]]:
    """Return runs of consecutive passes of about ``task_bytes``, one task each."""
    groups, first, size = [], 0, 0
    for i, p in enumerate(passes):
        size += p.size
        if size >= task_bytes or i == len(passes) - 1:
            groups.append((first, i + 1))
            first, size = i + 1, 0
    return groups


def _result(p: SpacecraftPlan, chain: Chain | None, run: int) -> SpacecraftResult:
    """Return a spacecraft's result: its new record, events and facts of this run."""
    record = p.prior
    if chain is not None and p.spec is not None:
        fed = {f.name: f for f in chain.passes if not f.error}
        done = tuple(PassRecord(f.name, f.size, f.first, fed[f.name].last)
                     for f in p.passes if f.name in fed)
        record = SpacecraftRecord(p.id, p.fingerprint, chain.last_time,
                                  (p.prior.passes if p.prior else PassLog()).plus(done),
                                  dict(chain.states))
    return SpacecraftResult(p, chain, record, run)


def _timings(chains: Mapping[str, Chain], wall: float, client_cpu: float
             ) -> dict[str, object]:
    """Return wall, client CPU, per-worker CPU and peak RSS, samples and rate."""
    workers: dict[str, WorkFacts] = {}
    samples = 0
    for chain in chains.values():
        samples += sum(f.wheel_samples for f in chain.passes)
        for worker, facts in chain.work.items():
            workers[worker] = workers.get(worker, WorkFacts()).plus(facts)
    cpu = sum(w.cpu_s for w in workers.values())
    return {'wall_s': wall, 'client_cpu_s': client_cpu, 'cpu_s': cpu,
            'per_worker': {k: vars(v) for k, v in workers.items()},
            'wheel_samples': samples,
            'wheel_samples_per_cpu_s': samples / cpu if cpu > 0 else math.nan}


def measure(archive: str | pathlib.Path, *, workers: int = 1,
            config: pathlib.Path | None = None) -> dict[str, object]:
    """Run the engine on a local cluster of ``workers``; return its timings (bench fleet).

    Keys: ``wall_s``, ``cpu_s`` (sum over workers), ``per_worker`` (``cpu_s``,
    ``peak_rss_mb``, ``tasks``), ``wheel_samples``, ``wheel_samples_per_cpu_s``,
    ``events``.
    """
    result = run_archive(archive, workers=workers, config=config, log=sys.stderr)
    return {**result.timings, 'events': len(result.current_events())}
