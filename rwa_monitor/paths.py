"""Where installed files are: config/ in the ROS share directory, the prefix, or the source."""

from __future__ import annotations

import os
import pathlib
import sys

PACKAGE = 'rwa_monitor'


def share_candidates() -> list[pathlib.Path]:
    """Return the directories that may hold ``config/``, most specific first."""
    found = []
    try:
        from ament_index_python.packages import get_package_share_directory
        found.append(pathlib.Path(get_package_share_directory(PACKAGE)))
    except Exception:  # noqa: BLE001 - no ament index (plain pip install) or not found
        pass
    found.append(pathlib.Path(sys.prefix) / 'share' / PACKAGE)
    found.append(pathlib.Path(__file__).resolve().parents[1])
    return found


def config_file(name: str = 'rwa_monitor.yaml') -> pathlib.Path:
    """Return the path of an installed configuration file; FileNotFoundError names where."""
    candidates = [base / 'config' / name for base in share_candidates()]
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f'{name} not found in: {", ".join(map(str, candidates))}')


def installed_or_given(path: str | os.PathLike) -> pathlib.Path:
    """Return ``path``, or the installed copy when ``path`` is a missing ``config/NAME``.

    The docs write ``--params-file config/rwa_monitor.yaml``, the file of a clone; a pip
    install keeps it in ``share/rwa_monitor/config`` (:func:`config_file`). A relative
    ``config/NAME`` that does not exist from the current folder is taken as that copy,
    so the documented commands run as written for both.
    """
    given = pathlib.Path(path)
    if given.exists() or given.is_absolute() or len(given.parts) != 2 or \
            given.parts[0] != 'config':
        return given
    try:
        return config_file(given.name)
    except FileNotFoundError:
        return given


def with_installed_params_files(argv: list[str]) -> tuple[list[str], list[str]]:
    """Return (``argv`` with each missing ``--params-file config/NAME`` installed, notes)."""
    out, notes = list(argv), []
    for i, arg in enumerate(out[:-1]):
        if arg == '--params-file':
            found = installed_or_given(out[i + 1])
            if str(found) != out[i + 1]:
                notes.append(f'--params-file {out[i + 1]}: not in this folder; using the '
                             f'installed copy {found}')
                out[i + 1] = str(found)
    return out, notes
