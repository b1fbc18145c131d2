"""Atomic output files: write to a temporary file beside the target, then rename.

An interrupted or failed write leaves the previous file whole (or no file): readers never
see a half-written output. Every file the package writes goes through :func:`atomic_write`.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import tempfile
from typing import IO, Iterator

from rwa_monitor.exceptions import OutputError


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = 'w', *, encoding: str | None = 'utf-8',
                 newline: str | None = None, make_parents: bool = True) -> Iterator[IO]:
    """Open a temporary file for writing; on success, fsync and rename it onto ``path``.

    ``mode`` is ``'w'`` (text) or ``'wb'`` (binary). On any exception the temporary file
    is removed and ``path`` is left as it was. A missing parent folder is created when
    ``make_parents`` is true, else :class:`OutputError` names it.
    """
    if mode not in ('w', 'wb'):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    target = pathlib.Path(path)
    parent = target.parent
    if not parent.exists():
        if not make_parents:
            raise OutputError(f'{target}: folder {parent} does not exist')
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f'{target}: cannot create folder {parent}: '
                              f'{err.strerror or err}') from None
    if target.is_dir():
        raise OutputError(f'{target}: is a folder, not a file')
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f'.{target.name}.', suffix='.tmp', dir=parent)
    except OSError as err:
        raise OutputError(f'{target}: cannot write in {parent}: {err.strerror or err}') from None
    tmp = pathlib.Path(tmp_name)
    try:
        kwargs = {} if 'b' in mode else {'encoding': encoding, 'newline': newline}
        with os.fdopen(fd, mode, **kwargs) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError) and not isinstance(err, OutputError):
            raise OutputError(f'{target}: write failed: {err.strerror or err}') from None
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_write(path, 'w') as handle:
        handle.write(text)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path, 'wb') as handle:
        handle.write(data)
