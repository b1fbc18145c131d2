"""Which existing folder a rosbag2 writer may replace: a recording, judged by its metadata.

A folder output replaces its target whole (telemetry/atomic.py :class:`FolderOutput`),
so the target must hold nothing but a recording. A name pattern (any ``*.mcap`` or
``*.db3``) would take a user's own database for a recording; the folder's own
``metadata.yaml`` says which files a recording holds instead. It must parse (aliases
bounded, telemetry/yaml_file.py) as rosbag2 metadata (a ``rosbag2_bagfile_information``
mapping with ``version``, ``storage_identifier`` and ``relative_file_paths``) listing
plain file names of a storage the package writes (``.mcap``, ``.db3``). Then the
metadata, the listed files and the SQLite side files of a listed ``.db3`` are the
recording; anything else in the folder, or every file when the metadata does not
qualify, is not, and the folder is refused.
"""

from __future__ import annotations

import glob
import os
import pathlib
import stat
from typing import Any

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.atomic import FolderOutput
from rwa_monitor.telemetry.yaml_file import read_yaml

METADATA = 'metadata.yaml'
STORAGE_SUFFIXES = ('.mcap', '.db3')
SQLITE_SIDE_FILES = ('-wal', '-shm', '-journal')
WHAT = 'part of a rosbag2 recording'


def listed_files(document: Any) -> list[str]:
    """Return the storage files a rosbag2 metadata document lists; ValueError if it is not one."""
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    if not isinstance(info, dict):
        raise ValueError('no rosbag2_bagfile_information mapping')
    if not isinstance(info.get('version'), int) or not isinstance(
            info.get('storage_identifier'), str):
        raise ValueError('no version or storage_identifier')
    names = info.get('relative_file_paths')
    if not isinstance(names, list):
        raise ValueError('no relative_file_paths list')
    for name in names:
        if not isinstance(name, str) or name in ('', '.', '..') or '/' in name \
                or '\0' in name or not name.endswith(STORAGE_SUFFIXES):
            raise ValueError(f'relative_file_paths lists {str(name)[:80]!r}, not a '
                             f'{" or ".join(STORAGE_SUFFIXES)} file of the folder')
    return names


def recording_files(folder: str | os.PathLike) -> tuple[tuple[str, ...], str]:
    """Return (patterns of the files of the recording in ``folder``, why none if empty).

    The patterns are the exact names (escaped for :func:`atomic.foreign_files`).
    """
    path = pathlib.Path(folder, METADATA)
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return (), f'its {METADATA} is not a regular file'
    except FileNotFoundError:
        return (), f'no {METADATA}'
    except OSError as err:
        return (), f'{METADATA}: {err.strerror or err}'
    try:
        names = listed_files(read_yaml(path))
    except ConfigError as err:
        return (), str(err).replace(os.fspath(path), METADATA)
    except ValueError as err:
        return (), f'{METADATA} is not rosbag2 metadata: {err}'
    owned = [METADATA, *names]
    owned += [n + side for n in names if n.endswith('.db3') for side in SQLITE_SIDE_FILES]
    return tuple(glob.escape(n) for n in owned), ''


def recording_output(path: str | os.PathLike) -> FolderOutput:
    """Return the FolderOutput of a recording at ``path`` (OutputError if not replaceable)."""
    owned, why = recording_files(path) if os.path.isdir(path) else ((), '')
    return FolderOutput(path, owned, f'{WHAT} ({why})' if why else WHAT)
