"""Where installed files are: config/ in the ROS share directory, the prefix, or the source."""

from __future__ import annotations

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
