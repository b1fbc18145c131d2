"""Safe outputs of the commands: never onto an input, always atomic, ``-`` is stdout.

Used by ``detect`` and ``diagnose`` (docs/usage.md "Outputs and exit codes"):

- :func:`check_output` refuses an output path that names one of the command's inputs
  (same file after resolving links), so ``-o run.csv`` cannot replace the telemetry;
- :func:`write_output` writes through :func:`rwa_monitor.telemetry.atomic.write_text_atomic`
  (a failed or interrupted write leaves the previous file whole and raises
  :class:`OutputError`: one line, no traceback), or to standard output for ``-``;
- :func:`quiet_broken_pipe` lets ``rwa-monitor detect FILE | head`` end quietly;
- :func:`json_text` is the JSON every command writes: strict (RFC 8259), a non-finite
  number written ``null``, never ``NaN`` or ``Infinity``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import pathlib
import sys
from typing import Any, Iterator

from rwa_monitor.exceptions import OutputError
from rwa_monitor.telemetry.atomic import path_problem, write_text_atomic

STDOUT = '-'


def _same_file(a: pathlib.Path, b: pathlib.Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(output: str | os.PathLike | None, *inputs: str | os.PathLike | None
                 ) -> None:
    """Raise OutputError if ``output`` is one of ``inputs`` (or a folder)."""
    if output is None or str(output) == STDOUT:
        return
    target = pathlib.Path(output)
    problem = path_problem(target)
    if 'loop' in problem:       # a link chain that never ends: nothing to write through
        raise OutputError(f'{target}: {problem}')
    if target.is_dir():
        raise OutputError(f'{target}: is a folder; give a file name for the output')
    for source in inputs:
        if source is None:
            continue
        source = pathlib.Path(source)
        if _same_file(target, source) or os.path.realpath(target) == os.path.realpath(source):
            raise OutputError(f'{target}: is an input of this command; refusing to '
                              'overwrite it (choose another output file)')


def finite_or_null(value: Any) -> Any:
    """Return ``value`` with every non-finite float (NaN, +-Inf) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    return value


def json_text(document: Any, indent: int | None = 2) -> str:
    """Return ``document`` as strict JSON text (non-finite numbers as null) and a newline."""
    return json.dumps(finite_or_null(document), indent=indent, allow_nan=False) + '\n'


def write_output(output: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``output`` atomically, or to standard output for ``-``."""
    if str(output) == STDOUT:
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    write_text_atomic(output, text)


@contextlib.contextmanager
def quiet_broken_pipe() -> Iterator[None]:
    """End quietly when the reader of standard output goes away (``| head``)."""
    try:
        yield
        sys.stdout.flush()
    except BrokenPipeError:
        # Python flushes stdout again at exit: point it at /dev/null so that this
        # second flush cannot fail and print a traceback.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
