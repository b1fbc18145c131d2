"""The one writer of every file and folder the package writes (docs/contracts.md, Outputs).

- A file is written to a temporary file beside its target, then renamed onto it: an
  interrupted or failed write leaves the previous file whole (or no file). A symbolic
  link is followed: its final target is replaced and the link kept. A FIFO, a character
  or block device is written to directly (streamed, as a shell redirection does:
  ``-o /dev/null`` discards), never replaced; a socket or a folder is refused.
- A new file gets the mode ``0666`` less the umask, as other tools give; a replaced file
  keeps its mode.
- A folder output (:class:`FolderOutput`) is built in a temporary sibling and swapped in
  whole; the folder it replaces may hold only what the command itself writes (its
  ``owned`` names), else it is refused and left untouched: nothing is ever deleted that
  the package did not write.
- Names taken from data become path components only through :func:`child`, which
  refuses anything but letters, digits, ``_`` and ``-``.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fnmatch
import os
import pathlib
import shutil
import signal
import stat
import tempfile
import threading
from typing import IO, Iterable, Iterator

from rwa_monitor.exceptions import OutputError
from rwa_monitor.telemetry.schema import NAME_RULE, valid_name
from rwa_monitor.telemetry.temporaries import remove_stale, temporary_prefix


def child(folder: str | os.PathLike, name: str, suffix: str = '') -> pathlib.Path:
    """Return the path of ``name + suffix`` in ``folder``; OutputError unless a safe name."""
    if not valid_name(name):
        raise OutputError(f'{folder}: refusing the name {str(name)[:80]!r} from the data as '
                          f'a file name (allowed: {NAME_RULE})')
    return pathlib.Path(folder) / (name + suffix)


def umask() -> int:
    """Return the file-creation mask of the process, read without changing it if possible."""
    with contextlib.suppress(OSError, ValueError):
        for line in pathlib.Path('/proc/self/status').read_text().splitlines():
            if line.startswith('Umask:'):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _resolve(path: str | os.PathLike) -> pathlib.Path:
    """Return the final target of ``path`` (links followed, a dangling one included).

    OutputError when the links loop (the error used to surface as a RuntimeError of
    pathlib, or as "cannot examine" naming the resolved path).
    """
    target = pathlib.Path(path)
    if not target.is_symlink():
        return target
    try:
        return pathlib.Path(os.path.realpath(target, strict=True))
    except FileNotFoundError:
        return pathlib.Path(os.path.realpath(target))    # dangling: its target is created
    except OSError as err:
        raise OutputError(f'{path}: {path_problem(path, err)}') from None


def path_problem(path: str | os.PathLike, err: OSError | None = None) -> str:
    """Return what is wrong with a path that cannot be used, in plain words.

    ``err`` is the error of the failed call if any; without it the path is examined. A
    loop of symbolic links, a dangling link (naming its target), a missing folder on the
    way, a component that is a file, or the error's own text.
    """
    path = pathlib.Path(path)
    if err is None:
        try:
            os.stat(path)
            return 'exists'
        except OSError as error:
            err = error
    if err.errno == errno.ELOOP:
        return 'its symbolic links form a loop (a link leads back to itself)'
    if err.errno == errno.ENOTDIR:
        return 'a part of the path that should be a folder is a file'
    if err.errno == errno.ENOENT:
        if path.is_symlink():
            return (f'a symbolic link to {os.readlink(path)}, which does not exist')
        parent = path.parent
        if str(parent) not in ('', '.') and not parent.is_dir():
            return f'no such file (its folder {parent} does not exist)'
        return 'no such file'
    return err.strerror or str(err)


def _mode_of(path: pathlib.Path, default: int) -> int:
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        return default & ~umask()


def _kind(path: pathlib.Path) -> str:
    """Return 'none', 'file', 'folder', 'stream' (FIFO, device) or 'other' (socket)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return 'none'
    except OSError as err:
        raise OutputError(f'{path}: cannot examine: {path_problem(path, err)}') from None
    if stat.S_ISREG(mode):
        return 'file'
    if stat.S_ISDIR(mode):
        return 'folder'
    if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return 'stream'
    return 'other'


def is_stream(path: str | os.PathLike) -> bool:
    """Return True if ``path`` (links followed) is a FIFO or a device: written directly."""
    try:
        return _kind(_resolve(path)) == 'stream'
    except OutputError:
        return False


def _make_parent(path: str | os.PathLike, target: pathlib.Path, make_parents: bool) -> None:
    """Create the target's folder if allowed; never the folder of a link's target.

    A dangling symbolic link names a place the user made once: a folder missing on its
    way is not made up (OutputError naming both), the link's own target file is created.
    """
    parent = target.parent
    if parent.is_dir():
        return
    if pathlib.Path(path).is_symlink():
        raise OutputError(f'{path}: a symbolic link to {target}, whose folder {parent} does '
                          'not exist; not creating it (create the folder or fix the link)')
    if parent.exists():
        raise OutputError(f'{target}: {parent} is not a folder')
    if not make_parents:
        raise OutputError(f'{target}: folder {parent} does not exist')
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f'{target}: cannot create folder {parent}: '
                          f'{err.strerror or err}') from None


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = 'w', *, encoding: str | None = 'utf-8',
                 newline: str | None = None, make_parents: bool = True) -> Iterator[IO]:
    """Open ``path`` for writing as the module docstring says; yield the handle.

    ``mode`` is ``'w'`` (text) or ``'wb'`` (binary). A regular file (or none) is written
    to a temporary file, fsynced and renamed onto the target; on any exception the
    temporary file is removed and the target is left as it was. A FIFO or device is
    written directly. A missing parent folder is created when ``make_parents`` is true,
    else :class:`OutputError` names it.
    """
    if mode not in ('w', 'wb'):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    kwargs = {} if 'b' in mode else {'encoding': encoding, 'newline': newline}
    target = _resolve(path)
    kind = _kind(target)
    if kind == 'folder':
        raise OutputError(f'{path}: is a folder, not a file')
    if kind == 'other':
        raise OutputError(f'{path}: is not a file, a FIFO or a device; not writing to it')
    if kind == 'stream':
        with _streamed(path, target, mode, kwargs) as handle:
            yield handle
        return
    _make_parent(path, target, make_parents)
    remove_stale(target)
    tmp = None
    try:
        with _signals_held():
            fd, tmp_name = tempfile.mkstemp(prefix=temporary_prefix(target), suffix='.tmp',
                                            dir=target.parent)
            tmp = pathlib.Path(tmp_name)
    except BaseException as err:
        # A signal held while the file was made is raised as the block ends: the name
        # is known by then, so the file is removed before the interrupt goes on.
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.close(fd)
                tmp.unlink()
        if isinstance(err, OSError) and not isinstance(err, OutputError):
            raise OutputError(f'{path}: cannot write in {target.parent}: '
                              f'{err.strerror or err}') from None
        raise
    try:
        os.chmod(fd, _mode_of(target, 0o666))
        with os.fdopen(fd, mode, **kwargs) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError) and not isinstance(err, OutputError):
            raise OutputError(f'{path}: write failed: {err.strerror or err}') from None
        raise


@contextlib.contextmanager
def work_folder(path: str | os.PathLike, contents: Iterable[str] = ()
                ) -> Iterator[pathlib.Path]:
    """Yield a temporary folder beside ``path``, removed when the block ends in any way.

    For outputs built from several files before one of them is installed (a bare
    ``.mcap`` written through a recording folder). Named as every temporary here
    (telemetry/temporaries.py), so a killed run's is removed by the next write when it
    holds only ``contents``, and made with the signals held, so that an interrupt cannot
    leave one whose name is not known.
    """
    target = _resolve(path)
    _make_parent(path, target, True)
    remove_stale(target, contents)
    work = None
    try:
        try:
            with _signals_held():
                work = pathlib.Path(tempfile.mkdtemp(prefix=temporary_prefix(target),
                                                     suffix='.tmp', dir=target.parent))
        except OSError as err:
            raise OutputError(f'{path}: cannot write in {target.parent}: '
                              f'{err.strerror or err}') from None
        yield work
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while a temporary is made and named.

    A Ctrl-C that arrives after the temporary exists but before the code that removes it
    on failure has its name would leave it behind. Held, the signal is raised as the
    block ends, when the name is known: the callers assign it inside the block and
    remove it on any exception, the interrupt included. Only the main thread receives
    these signals; elsewhere, or where the platform has no signal masks, nothing is held.
    """
    mask = getattr(signal, 'pthread_sigmask', None)
    if mask is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    previous = mask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        mask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def _streamed(path: str | os.PathLike, target: pathlib.Path, mode: str,
              kwargs: dict) -> Iterator[IO]:
    """Write straight into a FIFO or device (opened without creating or truncating)."""
    try:
        fd = os.open(target, os.O_WRONLY)
    except OSError as err:
        raise OutputError(f'{path}: cannot open for writing: {err.strerror or err}') from None
    try:
        with os.fdopen(fd, mode, **kwargs) as handle:
            yield handle
            handle.flush()
    except OSError as err:
        if isinstance(err, OutputError):
            raise
        raise OutputError(f'{path}: write failed: {err.strerror or err}') from None


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_write(path, 'w') as handle:
        handle.write(text)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path, 'wb') as handle:
        handle.write(data)


def install_file(source: str | os.PathLike, path: str | os.PathLike) -> None:
    """Copy a finished temporary file ``source`` onto ``path`` through :func:`atomic_write`."""
    with open(source, 'rb') as data, atomic_write(path, 'wb') as handle:
        shutil.copyfileobj(data, handle, 1 << 20)


def append_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Append ``data`` to the file ``path`` (created with the umask's mode) and fsync it.

    The one append-only writer (the alarm journal). OSError on failure.
    """
    target = _resolve(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(target, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)


# ----------------------------------------------------------------------------- folders
def _exchange(a: pathlib.Path, b: pathlib.Path) -> bool:
    """Swap two paths in one step (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        call = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if call(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    errno = ctypes.get_errno()
    if errno in (22, 38, 95):   # EINVAL, ENOSYS, EOPNOTSUPP: not on this file system
        return False
    raise OSError(errno, os.strerror(errno), str(b))


def foreign_files(folder: pathlib.Path, owned: Iterable[str]) -> list[str]:
    """Return the entries of ``folder`` (relative, sorted) that no ``owned`` pattern matches.

    Patterns are shell patterns on the relative path (``*`` does not cross ``/``); a
    sub-folder is owned when a pattern matches its path followed by ``/``, and then only
    its own entries are examined.
    """
    patterns = [p.split('/') for p in owned]

    def mine(rel: str) -> bool:
        parts = rel.split('/')
        return any(len(p) == len(parts) and all(map(fnmatch.fnmatchcase, parts, p))
                   for p in patterns)

    out: list[str] = []
    stack = [pathlib.PurePosixPath()]
    while stack:
        rel = stack.pop()
        for entry in os.scandir(folder / rel):
            name = (rel / entry.name).as_posix()
            if entry.is_dir(follow_symlinks=False) and mine(name + '/'):
                stack.append(rel / entry.name)
            elif entry.is_dir(follow_symlinks=False) or not entry.is_file(
                    follow_symlinks=False) or not mine(name):
                out.append(name + ('/' if entry.is_dir(follow_symlinks=False) else ''))
    return sorted(out)


class FolderOutput:
    """A folder output built beside its target and swapped in whole (module docstring).

    ``with FolderOutput(path, owned) as work:`` yields the empty temporary folder to fill;
    on success the target is replaced by it in one rename (renameat2 exchange, or two
    renames where the file system lacks it), the previous folder removed; on failure the
    temporary folder is removed and the target left byte-identical. ``owned``: the
    patterns of what the command writes (:func:`foreign_files`); a target holding
    anything else is refused (OutputError) before any work and again before the swap.
    Also usable without ``with``: :meth:`open`, :meth:`commit`, :meth:`abort`.
    """

    def __init__(self, path: str | os.PathLike, owned: Iterable[str],
                 what: str = 'outputs of this command') -> None:
        """Check the target (OutputError if it exists and is not ours)."""
        self.path = pathlib.Path(path)
        self.target = _resolve(self.path)
        self.owned = tuple(owned)
        self.what = what
        self.work: pathlib.Path | None = None
        self.check()

    def check(self) -> None:
        """Raise OutputError if the target is not a folder this output may replace."""
        kind = _kind(self.target)
        if kind == 'none':
            return
        if kind != 'folder':
            raise OutputError(f'{self.path}: exists and is not a folder; not replacing it')
        try:
            foreign = foreign_files(self.target, self.owned)
        except OSError as err:
            raise OutputError(f'{self.path}: cannot examine: {err.strerror or err}') from None
        if foreign:
            more = f' and {len(foreign) - 5} more' if len(foreign) > 5 else ''
            shown = ', '.join(foreign[:5]) + more
            raise OutputError(f'{self.path}: not replacing this folder: it holds files that '
                              f'are not {self.what} ({shown}); choose a new or empty folder')

    def open(self) -> pathlib.Path:
        """Create the temporary folder beside the target; return the path to fill.

        Temporaries of this target left by a killed run are removed first
        (telemetry/temporaries.py).
        """
        parent = self.target.parent
        _make_parent(self.path, self.target, True)
        remove_stale(self.target, (self.target.name,))
        try:
            self.work = pathlib.Path(tempfile.mkdtemp(prefix=temporary_prefix(self.target),
                                                      suffix='.tmp', dir=parent))
        except OSError as err:
            raise OutputError(f'{self.path}: cannot write in {parent}: '
                              f'{err.strerror or err}') from None
        return self.work / self.target.name

    def commit(self) -> None:
        """Swap the filled folder onto the target; remove the previous one."""
        new = self.work / self.target.name
        try:
            if not new.is_dir():
                new.mkdir()
            os.chmod(new, _mode_of(self.target, 0o777))
            self.check()
            if _kind(self.target) == 'none':
                os.rename(new, self.target)
            elif not _exchange(new, self.target):
                old = self.work / '.previous'
                os.rename(self.target, old)
                try:
                    os.rename(new, self.target)
                except OSError:
                    os.rename(old, self.target)
                    raise
        except OSError as err:
            if isinstance(err, OutputError):
                raise
            raise OutputError(f'{self.path}: write failed: {err.strerror or err}') from None
        finally:
            self.abort()

    def abort(self) -> None:
        """Remove the temporary folder (the target is left as it was).

        Also one whose name was not yet known (an interrupt inside ``mkdtemp``): it carries
        this process's prefix (telemetry/temporaries.py).
        """
        if self.work is not None:
            shutil.rmtree(self.work, ignore_errors=True)
            self.work = None
            return
        with contextlib.suppress(OSError):
            prefix = temporary_prefix(self.target)
            for entry in os.scandir(self.target.parent):
                if entry.name.startswith(prefix) and entry.name.endswith('.tmp') and \
                        entry.is_dir(follow_symlinks=False):
                    shutil.rmtree(entry.path, ignore_errors=True)

    def __enter__(self) -> pathlib.Path:
        """Open the temporary folder (created) and return it."""
        work = self.open()
        work.mkdir()
        return work

    def __exit__(self, kind: type | None, *_: object) -> None:
        """Commit on success; abort on an exception (which propagates)."""
        if kind is None:
            self.commit()
        else:
            self.abort()
