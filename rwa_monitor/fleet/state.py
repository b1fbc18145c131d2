"""Fleet state on disk: each spacecraft's detectors after the last pass processed.

``STATE/<spacecraft>.json`` (format, version, package version, configuration
fingerprint, the passes processed, and per component the detector tree of
:mod:`rwa_monitor.fleet.codec` with the last stamp and offsets, and the trend rows of
the passes processed, non-finite values as null) and
``STATE/<spacecraft>.<sha>.npz`` (the trees' arrays, ``<component>/<key>``; read with
``allow_pickle=False``), named by the first 16 hex digits of its SHA-256, which the JSON
holds in full. The ``.npz`` is written first, then the JSON atomically, then the older
``.npz`` removed: a save cut short leaves the previous state whole. A state whose
format, version or fingerprint differs from this run's is refused
(:class:`StateMismatch`), never mixed (docs/contracts.md "Fleet state").
"""

from __future__ import annotations

import glob
import hashlib
import io
import json
import math
import pathlib
from typing import Any, Mapping

import numpy as np

import rwa_monitor
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.atomic import write_bytes_atomic, write_text_atomic

FORMAT = 'rwa_monitor.fleet.state'
VERSION = 1


class StateMismatch(ConfigError):
    """A saved state that belongs to another format, version or configuration."""


def fingerprint(parts: Mapping[str, Any]) -> str:
    """Return the SHA-256 of the canonical JSON of ``parts`` (parameters, calibration)."""
    text = json.dumps(parts, sort_keys=True, separators=(',', ':'), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def save(folder: pathlib.Path, spacecraft: str, print_: str, passes: list[dict],
         chains: Mapping[str, Mapping[str, Any]]) -> None:
    """Write one spacecraft's state (``chains``: component -> persistent chain)."""
    arrays: dict[str, np.ndarray] = {}
    components = {}
    for component, chain in chains.items():
        entry = {k: v for k, v in chain.items() if k != 'detector'}
        entry['last_time'] = _float(entry['last_time'])
        entry['history'] = [{k: None if isinstance(v, float) and not np.isfinite(v) else v
                             for k, v in row.items()} for row in entry.get('history', [])]
        if chain['detector'] is not None:
            tree, found = chain['detector']
            arrays.update({f'{component}/{k}': v for k, v in found.items()})
            entry['detector'] = tree
        components[component] = entry
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    data = buffer.getvalue()
    document = {'format': FORMAT, 'version': VERSION,
                'package_version': rwa_monitor.__version__, 'spacecraft': spacecraft,
                'fingerprint': print_, 'arrays_sha256': hashlib.sha256(data).hexdigest(),
                'passes': passes, 'components': components}
    arrays_file = f'{spacecraft}.{document["arrays_sha256"][:16]}.npz'
    document['arrays_file'] = arrays_file
    write_bytes_atomic(folder / arrays_file, data)
    write_text_atomic(folder / f'{spacecraft}.json', json.dumps(document, indent=1) + '\n')
    for old in folder.glob(f'{glob.escape(spacecraft)}.*.npz'):
        if old.name != arrays_file:
            old.unlink()


def load(folder: pathlib.Path, spacecraft: str, print_: str
         ) -> tuple[list[dict], dict[str, dict[str, Any]]] | None:
    """Return (passes processed, component -> persistent chain), or None if never saved.

    Raise StateMismatch for a state of another format, version or configuration, and
    ConfigError for a damaged one.
    """
    path = folder / f'{spacecraft}.json'
    if not path.exists():
        return None
    try:
        document = json.loads(path.read_text())
        data = (folder / str(document.get('arrays_file'))).read_bytes()
    except (OSError, ValueError) as err:
        raise ConfigError(f'{path}: cannot read the fleet state: {err}') from None
    found = (document.get('format'), document.get('version'),
             document.get('package_version'))
    wanted = (FORMAT, VERSION, rwa_monitor.__version__)
    if found != wanted:
        raise StateMismatch(f'{path}: a fleet state of {found}, this is {wanted}; refusing '
                            'to mix them (give a new --state folder)')
    if document.get('fingerprint') != print_:
        raise StateMismatch(f'{path}: saved with other parameters or calibration than this '
                            'run; refusing to mix them (give a new --state folder, or the '
                            'config and calibration it was made with)')
    if hashlib.sha256(data).hexdigest() != document.get('arrays_sha256'):
        raise ConfigError(f'{path}: its .npz does not match (damaged or from another save)')
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    chains = {}
    for component, entry in document['components'].items():
        chain = dict(entry)
        chain['last_time'] = float(chain['last_time'])
        chain['history'] = [{k: math.nan if v is None else v for k, v in row.items()}
                            for row in chain.get('history', [])]
        if 'detector' in entry:
            prefix = f'{component}/'
            chain['detector'] = (entry['detector'], {k[len(prefix):]: v for k, v in
                                                     arrays.items() if k.startswith(prefix)})
        else:
            chain['detector'] = None
        chains[component] = chain
    return document['passes'], chains


def _float(value: float) -> float | str:
    return value if np.isfinite(value) else repr(value)
