"""What a fleet run will do, per spacecraft: its runners' spec, prior state, passes to run.

:func:`plan` reads the archive's folders, the saved state (if any) and each candidate
pass's first stamp and columns (``scan`` tasks of up to SCAN_TASK_PASSES passes), and
returns one :class:`SpacecraftPlan` per spacecraft: the passes to run in time order, those
already processed (same name and size as in the state), those that cannot be read or run
(with the reason: unreadable, other components than the spacecraft's, late) and the spec
its runners are made from. A pass that starts before the last pass the state processed is
late: a full run would have fed it earlier, and a run cannot go back in time, so it is
reported, by name, as not examined. A pass that starts after it is fed as a full run would
feed it (its rows at or before the last stamp fed are dropped and counted).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import pathlib
from typing import Mapping, Sequence, TYPE_CHECKING

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet import archive as arc, state
from rwa_monitor.fleet.chain import SpacecraftSpec
from rwa_monitor.fleet.records import SpacecraftRecord
from rwa_monitor.telemetry.schema import (ATTITUDE, FRICTION_SUFFIX, GYRO, REFERENCE,
                                          SPEED_SUFFIX, TIME, TRUTH_PREFIX)

if TYPE_CHECKING:
    from distributed import Client

CALIBRATION_KEY = 'calibration_file'
# Candidate passes scanned by one task at most, whatever their spacecraft: a pass's scan
# costs about 0.05 ms and a task a few ms of the engine's own, so one task per spacecraft
# (bench fleet: 20 tasks of 42 passes) cost the client more than the scans. At least one
# task per worker, so that a day's passes are not all scanned by one worker.
SCAN_TASK_PASSES = 1000
Blocks = Mapping[str, Mapping[str, object]]
MODEL_KEY = 'friction_model_file'


@dataclass(frozen=True)
class SpacecraftPlan:
    """One spacecraft's part of a run (module docstring)."""

    craft: arc.Spacecraft
    spec: SpacecraftSpec | None = None
    fingerprint: str = ''
    prior: SpacecraftRecord | None = None
    passes: tuple[arc.PassFile, ...] = ()
    already: int = 0
    unreadable: Mapping[str, str] = field(default_factory=dict)
    late: Mapping[str, str] = field(default_factory=dict)
    error: str | None = None

    @property
    def id(self) -> str:
        """Return the spacecraft's folder name."""
        return self.craft.id


def plan(client: Client, fleet: Sequence[arc.Spacecraft], blocks: Blocks,
         saved: Mapping[str, SpacecraftRecord]) -> list[SpacecraftPlan]:
    """Return the plans of the spacecraft; StateError if a saved state does not fit the run."""
    first = [_prior(craft, blocks, saved.get(craft.id)) for craft in fleet]
    batches = [(p, _to_scan(p)) for p in first if p.error is None]
    paths = [path for _, batch in batches for path in batch]
    size = -(-len(paths) // max(_workers(client), -(-len(paths) // SCAN_TASK_PASSES), 1))
    chunks = [paths[i:i + size] for i in range(0, len(paths), size)] if paths else []
    found = iter([f for chunk in client.gather(client.map(arc.scan_passes, chunks, pure=False))
                  for f in chunk] if chunks else [])
    scans = {p.id: {path: next(found) for path in batch} for p, batch in batches}
    return [_complete(p, scans.get(p.id, {}), blocks) for p in first]


def _workers(client: Client) -> int:
    """Return the workers the client knows of (its scheduler's last word; 1 if none)."""
    try:
        return max(1, len(client.scheduler_info().get('workers', {})))
    except (AttributeError, OSError):
        return 1


def _prior(craft: arc.Spacecraft, blocks: Blocks,
           prior: SpacecraftRecord | None) -> SpacecraftPlan:
    """Return the plan with the calibration read and the saved record checked."""
    try:
        texts = {'calibration': _text(craft.calibration),
                 'friction_model': _text(blocks['llr'].get(MODEL_KEY) or None)}
    except ConfigError as err:
        return SpacecraftPlan(craft, error=str(err))
    print_ = state.fingerprint({'llr': _block(blocks['llr'], craft),
                                'vsadc': _block(blocks['vsadc'], craft), **texts,
                                'records': state.record_versions()})
    if prior is not None and prior.fingerprint != print_:
        raise state.StateError(
            f'state of {craft.id}: saved with other parameters, calibration or friction '
            'model than this run; refusing to mix them (give a new --state folder, or the '
            'config and calibration it was made with)')
    return SpacecraftPlan(craft, fingerprint=print_, prior=prior)


def _to_scan(p: SpacecraftPlan) -> list[str]:
    done = p.prior.passes.keys() if p.prior else set()
    sizes, name = p.craft.sizes, p.craft.name
    return [path for path in p.craft.candidates if (name(path), sizes[path]) not in done]


def _complete(p: SpacecraftPlan, scans: Mapping[str, arc.PassFile | str], blocks: Blocks
              ) -> SpacecraftPlan:
    """Return the plan with its passes sorted, set aside or late, and its spec."""
    if p.error is not None:
        return p
    unreadable: dict[str, str] = {}
    readable = []
    for path, found in scans.items():
        if isinstance(found, str):
            unreadable[pathlib.Path(path).name] = found
        else:
            readable.append(found)
    readable.sort(key=lambda f: (f.first, f.name))
    already = len(p.craft.candidates) - len(scans)
    late: dict[str, str] = {}
    if p.prior is not None and p.prior.passes:
        last = p.prior.passes[-1]
        for f in list(readable):
            if (f.first, f.name) < (last.first, last.name):
                readable.remove(f)
                late[f.name] = (f'late: it starts at {f.first:.3f} s, before the last pass '
                                f'already processed ({last.name}, from {last.first:.3f} s); '
                                'a run does not go back in time (run the archive again with '
                                'a new --state folder to include it)')
    names = (list(p.prior.components) if p.prior else
             arc.components(readable[0].columns) if readable else [])
    for f in list(readable):
        found = arc.components(f.columns)
        if set(found) != set(names):
            readable.remove(f)
            unreadable[f.name] = (f'components {", ".join(found) or "none"} differ from the '
                                  f'spacecraft\'s {", ".join(names)}')
    out = replace(p, passes=tuple(readable), already=already, unreadable=unreadable,
                  late=late)
    if not names or not readable:
        return out
    try:
        return replace(out, spec=_spec(p.craft, names, readable, blocks))
    except ConfigError as err:
        return replace(out, error=str(err))


def _spec(craft: arc.Spacecraft, names: list[str], readable: Sequence[arc.PassFile],
          blocks: Blocks) -> SpacecraftSpec:
    """Return the spacecraft's runner spec; ConfigError if its files do not fit it."""
    wheels = tuple(n for n in names if n != arc.GYRO_COMPONENT)
    aux = tuple(sorted({c for f in readable[:1] for c in f.columns if _is_aux(c)}))
    spec = SpacecraftSpec(craft.id, wheels, arc.GYRO_COMPONENT in names,
                          _block(blocks['llr'], craft), _block(blocks['vsadc'], craft), aux)
    from rwa_monitor.fleet.chain import make_runners
    make_runners(spec)     # reads and checks the calibration and refined model now
    return spec


def _block(values: Mapping[str, object], craft: arc.Spacecraft) -> dict[str, object]:
    """Return a detector block with the spacecraft's calibration file set."""
    return {**values, CALIBRATION_KEY: craft.calibration or ''}


def _is_aux(column: str) -> bool:
    return not (column == TIME or column.endswith((SPEED_SUFFIX, FRICTION_SUFFIX))
                or column.startswith(TRUTH_PREFIX) or column in GYRO + ATTITUDE + REFERENCE)


def _text(path: str | None) -> str | None:
    if not path:
        return None
    try:
        return pathlib.Path(path).read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f'{path}: cannot read: {err}') from None
