"""One spacecraft's runners carried through its passes: the fleet's ``step`` task.

:func:`step` is a pure function of (spec, chain, passes): it makes the spacecraft's
runners (core/wheel_runner.py, core/gyro_runner.py, through pipelines/runners.py, as
``detect`` does), restores their states from the chain, feeds each pass's rows stamped
after the last one fed, and returns a new chain with the runners' states; its inputs are
never modified, so a task lost with a worker is simply run again with the same result.
Event indices count rows from the spacecraft's first pass, as in its passes joined into
one file, because the runners' row counts go on from pass to pass.

One task feeds every component of a spacecraft: each pass is read once, and the
spacecraft's chain is the unit of order (passes in time order). Spacecraft run in
parallel. Within a task, passes are read a block at a time (``BLOCK_BYTES``) and each
runner takes the whole block before the next one does.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
import functools
import gc
import json
import math
import resource
import time as _time
from typing import Iterator, Mapping, Sequence, TYPE_CHECKING

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gyro_runner import GyroRunner
from rwa_monitor.core.jit import kernel_array
from rwa_monitor.core.runner_facts import ComponentFacts
from rwa_monitor.core.wheel_runner import WheelRunner
from rwa_monitor.fleet.archive import after, PassFile, read_pass
from rwa_monitor.fleet.records import (Chain, ComponentRecord, GYRO, PassFacts, TrendRow,
                                       WorkFacts)
from rwa_monitor.telemetry.schema import Telemetry

if TYPE_CHECKING:
    from rwa_monitor.pipelines.runners import WheelSetup

# Checked parameter values (core/schema.py): what a YAML block holds once validated.
Values = Mapping[str, object]
# Passes read before the runners take them (about this many bytes of files): a step
# reads a block, then feeds it to each runner in turn (:func:`_feed_block`): 0.82 of the
# CPU of a pass-by-pass step. Larger blocks gain no more and raise a worker's peak
# memory (16 MiB: +55 MB on 96 passes; 8 MiB: +13 MB; docs/fleet.md "Engine").
BLOCK_BYTES = 8 << 20


@dataclass(frozen=True)
class SpacecraftSpec:
    """What a spacecraft's runners are made from: its components and checked blocks.

    ``llr``/``vsadc``: the checked parameter blocks (``calibration_file`` and
    ``friction_model_file`` included); ``aux``: the auxiliary channels of its passes (a
    refined model must find those it reads).
    """

    spacecraft: str
    wheels: tuple[str, ...]
    gyro: bool
    llr: Values = field(default_factory=dict)
    vsadc: Values = field(default_factory=dict)
    aux: tuple[str, ...] = ()

    @property
    def components(self) -> tuple[str, ...]:
        """Return the component names: the wheels, then ``gyro`` if it has one."""
        return self.wheels + ((GYRO,) if self.gyro else ())

    @property
    def calibrated(self) -> bool:
        """Return True if the wheels are tested against a calibration."""
        return bool(self.llr.get('calibration_file'))


def _key(values: Values) -> str:
    return json.dumps(values, sort_keys=True, default=str)


@functools.lru_cache(maxsize=64)
def _wheel_setup(llr: str, wheels: tuple[str, ...], aux: tuple[str, ...]) -> WheelSetup:
    """Return the wheels' set-up (files read once per worker and configuration)."""
    from rwa_monitor.pipelines.runners import wheel_setup
    return wheel_setup(json.loads(llr), wheels, aux)


@functools.lru_cache(maxsize=64)
def _gyro_calibration(path: str) -> Mapping[str, Values]:
    """Return the gyro block of a calibration file (read once per worker)."""
    from rwa_monitor.telemetry.calibration_file import load_gyro_calibration
    return load_gyro_calibration(path)


def setup_of(spec: SpacecraftSpec) -> WheelSetup:
    """Return the spacecraft's wheel set-up (pipelines/runners.py WheelSetup)."""
    return _wheel_setup(_key(spec.llr), spec.wheels, spec.aux)


@dataclass
class Runners:
    """A spacecraft's runners: one per wheel, and the gyro's if it has one."""

    wheels: dict[str, WheelRunner]
    gyro: GyroRunner | None = None

    def all(self) -> dict[str, WheelRunner | GyroRunner]:
        """Return component -> runner, the wheels first."""
        out: dict[str, WheelRunner | GyroRunner] = dict(self.wheels)
        if self.gyro is not None:
            out[GYRO] = self.gyro
        return out

    def restore(self, states: Mapping[str, ComponentRecord]) -> None:
        """Restore each runner from its component's record (RecordError if one differs)."""
        from rwa_monitor.core.records import RecordError
        for name, runner in self.wheels.items():
            record = states.get(name)
            if record is not None:
                if record.wheel is None:
                    raise RecordError(f'{name}: the state holds no wheel runner for it')
                runner.restore(record.wheel)
        record = states.get(GYRO)
        if self.gyro is not None and record is not None:
            if record.gyro is None:
                raise RecordError('gyro: the state holds no gyro runner')
            self.gyro.restore(record.gyro)

    def records(self) -> dict[str, ComponentRecord]:
        """Return each runner's state as its component's record (copies)."""
        out = {name: ComponentRecord(wheel=r.state()) for name, r in self.wheels.items()}
        if self.gyro is not None:
            out[GYRO] = ComponentRecord(gyro=self.gyro.state())
        return out


def make_runners(spec: SpacecraftSpec) -> Runners:
    """Return fresh runners of every component of the spacecraft."""
    setup = setup_of(spec)
    gyro = None
    if spec.gyro:
        path = str(spec.vsadc.get('calibration_file') or '')
        gyro = GyroRunner(spec.vsadc, _gyro_calibration(path) if path else None)
    return Runners({wheel: setup.runner(wheel) for wheel in spec.wheels}, gyro)


@contextlib.contextmanager
def _no_cycle_collection() -> Iterator[None]:
    """Hold Python's cycle collector for the length of a task, then give it back.

    A Dask worker process holds many long-lived objects; the collector's full passes
    walk all of them, and they took about a fifth of a task's CPU (5 spacecraft-weeks on
    one worker: 0.59-0.61 s with it, 0.48-0.51 s without; 0.43-0.47 s in a plain
    process). A task makes few reference cycles and is bounded (``TASK_BYTES`` of
    passes); reference counting frees everything else as it goes.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def step(spec: SpacecraftSpec, chain: Chain, passes: Sequence[PassFile],
         last: bool = False) -> Chain:
    """Return the chain after ``passes`` (in time order).

    ``last``: these are the run's last passes: the record ends here for now, so every
    runner's open declaration gets its end-of-record categorisation (``finish``, as
    ``detect`` gives at the end of a file; docs/llr.md "End of record"): the chain's
    ``end_of_run`` events. The states kept are those before it, so that a later run with
    new passes continues as a full run would, and its own end-of-record events supersede
    these (fleet/history.py).
    """
    with _no_cycle_collection():
        return _step(spec, chain, passes, last)


def _step(spec: SpacecraftSpec, chain: Chain, passes: Sequence[PassFile],
          last: bool) -> Chain:
    start = _time.process_time()
    runners = make_runners(spec)
    runners.restore(chain.states)
    events = list(chain.events)
    facts = list(chain.passes)
    trend = list(chain.trend)
    last_time = chain.last_time
    for block in _blocks(passes, BLOCK_BYTES):
        read = []
        for found in block:
            got = _ReadPass.of(found, last_time)
            last_time = max(last_time, got.last)
            read.append(got)
        _feed_block(spec, runners, read)
        for got in read:
            events.extend(got.events)
            trend.extend(got.trend)
            facts.append(got.facts())
    states = runners.records()
    component_facts: dict[str, ComponentFacts] = {n: r.facts()
                                                  for n, r in runners.all().items()}
    end_of_run = [e for r in runners.all().values() for e in r.finish()] if last else []
    work = _account(chain.work, _time.process_time() - start)
    return Chain(last_time, states, tuple(events), tuple(end_of_run), tuple(facts),
                 tuple(trend), component_facts, work)


def _blocks(passes: Sequence[PassFile], size: int) -> Iterator[Sequence[PassFile]]:
    """Yield runs of consecutive passes of about ``size`` bytes of files (at least one)."""
    first, total = 0, 0
    for i, found in enumerate(passes):
        total += found.size
        if total >= size or i == len(passes) - 1:
            yield passes[first:i + 1]
            first, total = i + 1, 0


@dataclass
class _ReadPass:
    """One pass of a block: its rows after the chain's last stamp, and what it gave."""

    found: PassFile
    kept: Telemetry | None
    error: str | None = None
    dropped: int = 0
    last: float = -math.inf
    events: list[AnomalyEvent] = field(default_factory=list)
    trend: list[TrendRow] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)
    fed: int = 0

    @classmethod
    def of(cls, found: PassFile, last_time: float) -> '_ReadPass':
        """Read the pass; keep its rows stamped after ``last_time``."""
        tele = read_pass(found.path)
        if isinstance(tele, str):
            return cls(found, None, error=tele)
        kept, dropped = after(tele, last_time)
        return cls(found, kept, dropped=dropped, last=float(tele.time[-1]))

    def facts(self) -> PassFacts:
        """Return what the pass gave, or why it could not be read."""
        if self.kept is None:
            return PassFacts(self.found.name, error=self.error)
        return PassFacts(self.found.name, len(self.kept), self.dropped, self.fed,
                         self.last, None, self.errors)


def _feed_block(spec: SpacecraftSpec, runners: Runners, block: list[_ReadPass]) -> None:
    """Feed a block of read passes to each runner in turn, keeping each pass's results.

    A wheel's runner takes the block's passes one after the other, then the next wheel's
    does, then the gyro's: each runner sees its passes in time order as before, and each
    pass's events, trend rows and errors are kept in the order of a pass-by-pass feed
    (wheels in order, then the gyro), so the chain is the same. Why blocks: the Parquet
    reader, a wheel's detector and the trend kernels each run over many passes in a row
    instead of evicting each other's code and data from the processor's caches at every
    pass (docs/fleet.md "Engine").
    """
    setup = setup_of(spec)
    # The kernels' writable copies of the read-only columns, made once a pass for the
    # detector and the trend levels alike (kernel_array returns them as they are).
    wheels = [(got, rows, kernel_array(rows.time)) for got in block if got.kept is not None
              for rows in (got.kept.only('wheels'),)]
    for name in spec.wheels:
        runner = runners.wheels[name]
        aux = setup.reads_aux(name)
        for got, rows, t in wheels:
            channel = rows.wheels.get(name)
            if channel is None or channel.friction is None:
                got.errors[name] = f'no {name}_speed and {name}_friction columns'
                continue
            got.fed += len(t)
            w = kernel_array(channel.speed)
            got.events.extend(runner.feed(t, w, channel.friction, rows.aux if aux else None))
            if len(t):
                got.trend.append(_trend_row(spec, name, got.found.name, t, w,
                                            runner.last_input))
    if runners.gyro is None:
        return
    for got, _, _ in wheels:
        kept = got.kept
        if not len(kept):
            continue
        if kept.gyro is None or kept.attitude is None:
            got.errors[GYRO] = 'no gyro_x/y/z and q_x/y/z/w columns'
        else:
            from rwa_monitor.pipelines.runners import gyro_columns
            got.events.extend(runners.gyro.feed(gyro_columns(kept)))


def _trend_row(spec: SpacecraftSpec, wheel: str, name: str, t: np.ndarray, w: np.ndarray,
               residual: np.ndarray) -> TrendRow:
    """Return the pass's friction levels of the wheel (core/trend.py pass_levels).

    ``residual``: what the detector was fed, friction minus the nominal with a calibration
    (NaN where the detector does not test: the low-speed band and speeds outside the
    calibrated range), so the levels use the detector's samples only; pass_levels drops
    and counts the NaN (``nonfinite``).
    """
    from rwa_monitor.core.trend import pass_levels
    levels = pass_levels(t, w, residual)
    return TrendRow(spec.spacecraft, wheel, name, levels.t_start, levels.t_end,
                    levels.samples, levels.dry, levels.dry_se, levels.viscous,
                    levels.viscous_se, 'nominal' if spec.calibrated else 'zero')


def _account(work: Mapping[str, WorkFacts], cpu_s: float) -> dict[str, WorkFacts]:
    """Return the per-worker facts with this task's CPU time and peak memory added."""
    try:
        from distributed import get_worker
        worker = get_worker().address
    except (ImportError, ValueError):
        worker = 'client'
    peak = peak_memory_mb()
    out = dict(work)
    out[worker] = out.get(worker, WorkFacts()).plus(WorkFacts(cpu_s, 1, peak))
    return out


def peak_memory_mb() -> float:
    """Return this process's peak resident memory in MB (its own, not its starter's).

    ``VmHWM`` of /proc/self/status: the high-water mark of this process image, which a
    new process starts afresh at exec. ``ru_maxrss`` where /proc is absent: Linux keeps
    it across exec, so a spawned worker's figure would include the RSS of the process
    that started it.
    """
    try:
        with open('/proc/self/status', encoding='ascii') as status:
            for line in status:
                if line.startswith('VmHWM:'):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
