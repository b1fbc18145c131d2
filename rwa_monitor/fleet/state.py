"""Fleet state, format 2: every spacecraft's runners after the last pass processed.

Layout of a state folder (docs/contracts.md "Fleet state")::

    STATE/current.json         the pointer: format, version, generation, sha256
    STATE/gen-000007/          one generation, written whole before the pointer moves
        state.json             records (core/records.py trees), versions, fingerprints
        arrays.npz             every array of the records (no object arrays)
        trend.parquet          every pass's friction levels so far (the trend's history)
        history.parquet        the cumulative event history (fleet/history.py)

``sha256`` in the pointer is the SHA-256 of the generation's four files, concatenated in
that order with their names and sizes: one hash over the whole state, checked on load
before anything in it is parsed. The records are read by their declared types only
(:func:`rwa_monitor.core.records.decode`): a state names no class, module or function, and
reading it imports and runs nothing it names. Every record's format version and every
spacecraft's fingerprint (parameters, calibration, refined model) must equal this run's
(the run's are authoritative). Files are opened only inside the state folder, by fixed
names, as regular files (no links, FIFOs or devices). Any deviation is a
:class:`StateError` (exit 2) naming the file and what is wrong.

A commit writes a new generation in a hidden folder, renames it into place, then replaces
the pointer atomically, then removes the previous generation: a crash at any point
leaves the old or the new state whole, and only files this module wrote (by their fixed
names, inside folders it named) are ever removed.

One run at a time: ``rwa-monitor fleet --state`` holds :func:`locked` (an exclusive
``flock`` on ``STATE/.lock``, released by the system when the process ends, however it
ends) from loading the state to committing it; a second run on the same folder is
refused at once, naming the process that holds it (two daily runs that overlap would
otherwise both load generation N and both write N + 1). :func:`commit` checks as well
that the pointer is still the one loaded, for callers of the engine that take no lock.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import pathlib
import re
import stat
from typing import Any, Iterable, Iterator, Mapping

import numpy as np

import rwa_monitor
from rwa_monitor.core.gyro_runner import GyroRunnerState
from rwa_monitor.core.records import decode, encode, RecordError
from rwa_monitor.core.wheel_runner import WheelRunnerState
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet.history import Entry, from_parquet
from rwa_monitor.fleet.records import SpacecraftRecord
from rwa_monitor.fleet.trend_table import TrendTable
from rwa_monitor.telemetry.atomic import write_text_atomic

FORMAT = 'rwa_monitor.fleet.state'
VERSION = 2
POINTER = 'current.json'
LOCK = '.lock'
FILES = ('state.json', 'arrays.npz', 'trend.parquet', 'history.parquet')
GENERATION = re.compile(r'gen-(\d{6})')
PARTIAL = re.compile(r'\.gen-(\d{6})\.partial')
MAX_BYTES = 8 << 30


class StateError(ConfigError):
    """A state folder that cannot be used: damaged, foreign, or of another configuration."""


def record_versions() -> dict[str, int]:
    """Return the format version of every record a state holds (core and fleet)."""
    from rwa_monitor.core.gyro_state import GyroDiagnosisState, VsadcState
    from rwa_monitor.core.llr_state import LLRState
    classes = (SpacecraftRecord, WheelRunnerState, GyroRunnerState, LLRState,
               GyroDiagnosisState, VsadcState)
    return {cls.__name__: int(getattr(cls, 'VERSION', 1)) for cls in classes}


class Loaded:
    """A state read from its folder: its generation, records, trend rows, event history.

    ``pointer``: the bytes of ``current.json`` as loaded (:func:`commit` checks them).
    """

    def __init__(self, generation: int, records: dict[str, SpacecraftRecord],
                 trend: TrendTable, history: list[Entry], pointer: bytes = b'') -> None:
        self.generation = generation
        self.records = records
        self.trend = trend
        self.history = history
        self.pointer = pointer


@contextlib.contextmanager
def locked(folder: pathlib.Path) -> Iterator[None]:
    """Hold the state folder for one run (created if missing); StateError if held."""
    import fcntl
    if _exists(folder) and not _is_dir(folder):
        raise StateError(f'{folder}: the state folder is not a folder')
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle = os.open(folder / LOCK, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW
                         | os.O_NONBLOCK, 0o644)
    except OSError as err:
        raise StateError(f'{folder / LOCK}: cannot open the lock: {err.strerror or err}'
                         ) from None
    try:
        if not stat.S_ISREG(os.fstat(handle).st_mode):
            raise StateError(f'{folder / LOCK}: not a regular file')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(handle, 32, 0).decode(errors='replace').strip() or 'unknown'
            raise StateError(f'{folder}: in use by another fleet run (process {holder}): let '
                             'it finish, or give another --state folder') from None
        os.ftruncate(handle, 0)
        os.pwrite(handle, f'{os.getpid()}\n'.encode(), 0)
        yield
    finally:
        os.close(handle)


def fingerprint(parts: Mapping[str, Any]) -> str:
    """Return the SHA-256 of the canonical JSON of ``parts`` (parameters, file contents)."""
    text = json.dumps(parts, sort_keys=True, separators=(',', ':'), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def check_folders(state: pathlib.Path | None, output: pathlib.Path) -> None:
    """Raise StateError if the state folder is the output folder or one holds the other."""
    if state is None:
        return
    a, b = state.resolve(), output.resolve()
    if a == b or a in b.parents or b in a.parents:
        raise StateError(f'--state {state}: must not be the output folder {output}, nor '
                         'inside it, nor hold it')


def load(folder: pathlib.Path) -> Loaded | None:
    """Return the state in ``folder``, or None if it holds none yet (StateError if bad)."""
    pointer = folder / POINTER
    if not _exists(pointer):
        if _exists(folder) and not _is_dir(folder):
            raise StateError(f'{folder}: the state folder is not a folder')
        return None
    raw = _read(pointer, 1 << 16)
    try:
        document = json.loads(raw)
    except ValueError as err:
        raise StateError(f'{pointer}: not a state pointer: {err}') from None
    if not isinstance(document, dict) or document.get('format') != FORMAT:
        raise StateError(f'{pointer}: not a {FORMAT} pointer')
    if document.get('version') != VERSION:
        raise StateError(f'{pointer}: state format version {document.get("version")!r}, '
                         f'this is {VERSION}: give a new --state folder')
    name = document.get('generation')
    match = GENERATION.fullmatch(name) if isinstance(name, str) else None
    if match is None:
        raise StateError(f'{pointer}: generation {name!r} is not gen-NNNNNN')
    gen = folder / name
    if not _is_dir(gen):
        raise StateError(f'{gen}: the generation the pointer names is not a folder')
    blobs = {f: _read(gen / f, MAX_BYTES) for f in FILES}
    if _digest(blobs) != document.get('sha256'):
        raise StateError(f"{gen}: its files do not match the pointer's sha256 (damaged, "
                         'edited or mixed with another state)')
    records = _records(gen / FILES[0], blobs)
    try:
        trend = TrendTable.from_parquet(blobs[FILES[2]])
        events = from_parquet(blobs[FILES[3]])
    except (ValueError, KeyError, TypeError, RecordError) as err:
        raise StateError(f'{gen}: its trend or event history cannot be read: {err}') from None
    return Loaded(int(match.group(1)), records, trend, events, raw)


def _records(path: pathlib.Path, blobs: Mapping[str, bytes]) -> dict[str, SpacecraftRecord]:
    try:
        manifest = json.loads(blobs[FILES[0]])
        with np.load(io.BytesIO(blobs[FILES[1]]), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (ValueError, OSError, KeyError) as err:
        raise StateError(f'{path}: cannot read: {err}') from None
    if not isinstance(manifest, dict) or manifest.get('format') != FORMAT:
        raise StateError(f'{path}: not a {FORMAT} file')
    wanted = record_versions()
    if manifest.get('records') != wanted:
        raise StateError(f'{path}: records of versions {manifest.get("records")}, this '
                         f'package writes {wanted}: give a new --state folder')
    crafts = manifest.get('spacecraft')
    if not isinstance(crafts, dict):
        raise StateError(f'{path}: no spacecraft mapping')
    out = {}
    for craft, tree in crafts.items():
        prefix = f'{craft}/'
        mine = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
        try:
            record = decode(SpacecraftRecord, tree, mine)
        except RecordError as err:
            raise StateError(f'{path}: spacecraft {craft!r}: {err}') from None
        if record.spacecraft != craft:
            raise StateError(f'{path}: spacecraft {craft!r} holds the record of '
                             f'{record.spacecraft!r}')
        out[craft] = record
    stray = [k for k in arrays if k.split('/', 1)[0] not in crafts]
    if stray:
        raise StateError(f'{path}: arrays of no spacecraft: {", ".join(stray[:3])}')
    return out


def commit(folder: pathlib.Path, previous: Loaded | None,
           records: Mapping[str, SpacecraftRecord], trend: bytes, history: bytes) -> None:
    """Write ``records`` (every spacecraft) as the next generation and switch to it."""
    generation = (previous.generation if previous else 0) + 1
    name = f'gen-{generation:06d}'
    pointer = folder / POINTER
    now = _read(pointer, 1 << 16) if _exists(pointer) else None
    if now != (previous.pointer if previous else None):
        raise StateError(f'{folder}: another run moved the state on during this one (its '
                         'pointer changed since it was loaded); this run is not saved: run '
                         'again to go on from the new state')
    try:
        folder.mkdir(parents=True, exist_ok=True)
        _remove_partials(folder)
        work = folder / f'.{name}.partial'
        work.mkdir()
        blobs = _blobs(records, trend, history)
        for file, data in blobs.items():
            _write(work / file, data)
        _sync(work)
        if _is_dir(folder / name):      # written by a run that crashed before its pointer
            _remove_generation(folder / name)
        os.replace(work, folder / name)
        _sync(folder)
        write_text_atomic(folder / POINTER, json.dumps(
            {'format': FORMAT, 'version': VERSION, 'generation': name,
             'sha256': _digest(blobs)}, indent=1) + '\n')
    except OSError as err:
        raise StateError(f'{folder}: cannot write the state: {err.strerror or err}') from None
    if previous is not None:
        _remove_generation(folder / f'gen-{previous.generation:06d}')


def _blobs(records: Mapping[str, SpacecraftRecord], trend: bytes, history: bytes
           ) -> dict[str, bytes]:
    arrays: dict[str, np.ndarray] = {}
    trees = {}
    for craft, record in sorted(records.items()):
        tree, found = encode(record)
        trees[craft] = tree
        arrays.update({f'{craft}/{k}': v for k, v in found.items()})
    manifest = {'format': FORMAT, 'version': VERSION,
                'package_version': rwa_monitor.__version__, 'records': record_versions(),
                'spacecraft': trees}
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return {FILES[0]: (json.dumps(manifest, allow_nan=False) + '\n').encode(),
            FILES[1]: buffer.getvalue(), FILES[2]: trend, FILES[3]: history}


def _digest(blobs: Mapping[str, bytes]) -> str:
    digest = hashlib.sha256()
    for name in FILES:
        data = blobs[name]
        digest.update(f'{name}\0{len(data)}\0'.encode())
        digest.update(data)
    return digest.hexdigest()


def _exists(path: pathlib.Path) -> bool:
    try:
        os.lstat(path)
        return True
    except FileNotFoundError:
        return False
    except OSError as err:
        raise StateError(f'{path}: {err.strerror or err}') from None


def _is_dir(path: pathlib.Path) -> bool:
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode)
    except OSError:
        return False


def _read(path: pathlib.Path, limit: int) -> bytes:
    """Return a regular file's bytes (never following a link, never blocking on a FIFO)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError as err:
        raise StateError(f'{path}: cannot open as a regular file of the state: '
                         f'{err.strerror or err}') from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise StateError(f'{path}: not a regular file')
        if info.st_size > limit:
            raise StateError(f'{path}: {info.st_size} bytes, more than a state file holds')
        with os.fdopen(fd, 'rb', closefd=False) as handle:
            return handle.read(limit + 1)
    except OSError as err:
        raise StateError(f'{path}: cannot read: {err.strerror or err}') from None
    finally:
        os.close(fd)


def _write(path: pathlib.Path, data: bytes) -> None:
    """Write a new file of a partial generation (the folder's rename makes it atomic)."""
    with open(path, 'xb') as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())


def _sync(folder: pathlib.Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _remove_generation(gen: pathlib.Path) -> None:
    """Remove a generation this module wrote: its fixed files, then the folder if empty."""
    for name in FILES:
        path = gen / name
        try:
            if stat.S_ISREG(os.lstat(path).st_mode):
                path.unlink()
        except OSError:
            pass
    try:
        gen.rmdir()            # fails, and is left, if anything else is in it
    except OSError:
        pass


def _remove_partials(folder: pathlib.Path) -> None:
    """Remove generations a crash left unfinished (``.gen-NNNNNN.partial``, ours only)."""
    for entry in _entries(folder):
        if PARTIAL.fullmatch(entry) and _is_dir(folder / entry):
            _remove_generation(folder / entry)


def _entries(folder: pathlib.Path) -> Iterable[str]:
    try:
        return os.listdir(folder)
    except OSError:
        return []
