"""Temporaries beside an output: named after their process, removed once it has ended.

Every file and folder output (telemetry/atomic.py) is built in a temporary beside its
target and renamed onto it. A run killed with SIGKILL cannot remove its temporary, so
each is named ``.<target>.<host>-<pid>-<start>.<random>.tmp``: the host and process that
made it (``start``: the process's start time in clock ticks since boot, so that a reused
pid is not mistaken for it). The next write to the same target removes those whose
process has ended (:func:`remove_stale`); one of a live process, or of another host
sharing the folder, is left alone, and so is a folder holding anything the output does
not put there.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import re
import shutil
import socket
from typing import Iterable

_TEMPORARY = re.compile(r'\.(?P<host>[A-Za-z0-9]{0,32})-(?P<pid>\d+)-(?P<start>\d+)'
                        r'\.[A-Za-z0-9_]+\.tmp')


def _process_start(pid: int) -> int | None:
    """Return the start time of process ``pid`` (clock ticks since boot), None if unknown."""
    try:
        text = pathlib.Path(f'/proc/{pid}/stat').read_text()
        return int(text.rsplit(')', 1)[1].split()[19])     # field 22, starttime
    except (OSError, IndexError, ValueError):
        return None


def _host() -> str:
    return re.sub(r'[^A-Za-z0-9]', '', socket.gethostname())[:32]


def temporary_prefix(target: pathlib.Path) -> str:
    """Return the prefix of this process's temporaries beside ``target``."""
    pid = os.getpid()
    return f'.{target.name}.{_host()}-{pid}-{_process_start(pid) or 0}.'


def _gone(host: str, pid: int, start: int) -> bool:
    """Return True if the process that made a temporary is known to have ended."""
    if host != _host():
        return False
    now = _process_start(pid)
    if now is not None:
        return start != 0 and now != start
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:
        return False
    return False


def remove_stale(target: pathlib.Path, contents: Iterable[str] = ()) -> list[str]:
    """Remove the temporaries of ``target`` left by ended processes; return their names.

    A folder is removed only if it holds nothing but ``contents`` (what
    :class:`FolderOutput` puts in it); anything unexpected is left for a person.
    """
    prefix = f'.{target.name}'
    removed = []
    with contextlib.suppress(OSError):
        entries = [e for e in os.scandir(target.parent) if e.name.startswith(prefix)]
        for entry in entries:
            found = _TEMPORARY.fullmatch(entry.name[len(prefix):])
            if found is None or not _gone(found['host'], int(found['pid']),
                                          int(found['start'])):
                continue
            with contextlib.suppress(OSError):
                if entry.is_dir(follow_symlinks=False):
                    inside = set(os.listdir(entry.path))
                    if not inside <= {*contents, '.previous'}:
                        continue
                    if '.previous' in inside and not os.path.lexists(target):
                        # Killed between the two renames of a swap: the previous output
                        # goes back in place rather than away.
                        os.rename(os.path.join(entry.path, '.previous'), target)
                    shutil.rmtree(entry.path)
                    removed.append(entry.name)
                elif entry.is_file(follow_symlinks=False):
                    os.unlink(entry.path)
                    removed.append(entry.name)
    return removed
