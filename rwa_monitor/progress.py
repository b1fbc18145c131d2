"""Progress of long work on standard error, and the notice of a machine's first compile.

Progress is redrawn on a terminal and written as a line every few seconds in a log.

:class:`Progress` is what a long command (``simulate fleet``, ``calibrate``...) reports
through: on a terminal one line redrawn in place (at most 5 times a second), otherwise
(a log, a pipe) one line every ``interval`` seconds and one at the end, so a log shows
the command alive without filling up. :class:`KernelNotice` is the reporter the CLI
gives core/jit.py: a kernel that loads from the cache says nothing; one that missed the
cache and still compiles after half a second (the machine's first run) prints a one-line
notice, then its progress (a line every few seconds while it compiles).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import Callable, TextIO

INTERVAL_S = 5.0      # seconds between progress lines in a log
REDRAW_S = 0.2        # seconds between redraws on a terminal
NOTICE_AFTER_S = 0.5  # a kernel taking longer than this is compiling, not loading


def is_terminal(out: TextIO) -> bool:
    """Return True when ``out`` is an interactive terminal."""
    return hasattr(out, 'isatty') and out.isatty() and os.environ.get('TERM') != 'dumb'


class Progress:
    """Report ``done`` of ``total`` steps of ``what`` (see the module docstring).

    Between two steps a heartbeat repeats the last state every ``interval`` seconds (the
    elapsed time moving on), so a slow step does not look like a hung command.
    """

    def __init__(self, what: str, total: int | None = None, out: TextIO | None = None,
                 interval: float = INTERVAL_S) -> None:
        self.what = what
        self.total = total
        self.out = sys.stderr if out is None else out
        self.tty = is_terminal(self.out)
        self.interval = REDRAW_S if self.tty else interval
        self.start = time.monotonic()
        self._last = self.start
        self.lines = 0
        self._state = (0, '')
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._beat = threading.Thread(target=self._heartbeat, daemon=True,
                                      args=(max(interval, REDRAW_S),))
        self._beat.start()

    def _heartbeat(self, interval: float) -> None:
        while not self._stop.wait(interval):
            with self._lock:
                if time.monotonic() - self._last >= interval:
                    self._last = time.monotonic()
                    self._write(self._text(*self._state))

    def _text(self, done: int, note: str) -> str:
        count = f'{done}/{self.total}' if self.total else f'{done}'
        share = f' ({100 * done / self.total:.0f} %)' if self.total else ''
        elapsed = time.monotonic() - self.start
        return f'{self.what}: {count}{share}, {elapsed:.0f} s' + (f' - {note}' if note else '')

    def update(self, done: int, note: str = '') -> None:
        """Report progress; printed only when the last line is old enough."""
        with self._lock:
            self._state = (done, note)
            now = time.monotonic()
            if now - self._last < self.interval:
                return
            self._last = now
            self._write(self._text(done, note))

    def finish(self, done: int | None = None, note: str = 'done') -> None:
        """Print the final line (and end the redrawn line on a terminal); stop the beat."""
        self._stop.set()
        with self._lock:
            self._write(self._text(self.total if done is None else done, note))
            if self.tty:
                self.out.write('\n')
                self.out.flush()

    def _write(self, text: str) -> None:
        if self.tty:
            self.out.write('\r\x1b[K' + text)
        else:
            self.out.write(text + '\n')
        self.out.flush()
        self.lines += 1


class KernelNotice:
    """core/jit.py's reporter for the CLI: silent for cached kernels, a notice otherwise."""

    def __init__(self, out: TextIO | None = None, after: float = NOTICE_AFTER_S,
                 interval: float = INTERVAL_S) -> None:
        self.out = sys.stderr if out is None else out
        self.after = after
        self.interval = interval
        self.noticed = False
        self.compiled: list[tuple[str, float]] = []
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()
        self._shown = False

    def __call__(self, event: str, kernel: str, seconds: float,
                 compiling: Callable[[], bool] = lambda: True) -> None:
        """Receive ``start`` / ``end`` of a kernel's first use (core/jit.py)."""
        with self._lock:
            if event == 'start':
                self._shown = False
                self._arm(kernel, time.monotonic(), self.after, compiling)
                return
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            if compiling():
                self.compiled.append((kernel, seconds))
            if self._shown:
                self._print(f'rwa-monitor: compiled {kernel} in {seconds:.1f} s')

    def _arm(self, kernel: str, start: float, delay: float,
             compiling: Callable[[], bool]) -> None:
        self._timer = threading.Timer(delay, self._still, (kernel, start, compiling))
        self._timer.daemon = True
        self._timer.start()

    def _still(self, kernel: str, start: float, compiling: Callable[[], bool]) -> None:
        with self._lock:
            if self._timer is None:
                return
            if not compiling():          # still loading from the cache: look again
                self._arm(kernel, start, self.after, compiling)
                return
            if not self.noticed:
                self.noticed = True
                self._print('rwa-monitor: first run on this machine: compiling the '
                            "detectors' kernels (once; cached for every later run)")
            self._shown = True
            self._print(f'rwa-monitor: compiling {kernel} ... '
                        f'{time.monotonic() - start:.0f} s')
            self._arm(kernel, start, self.interval, compiling)

    def _print(self, text: str) -> None:
        """Write a notice; a closed or broken stream drops it (a notice never fails a run)."""
        try:
            self.out.write(text + '\n')
            self.out.flush()
        except (OSError, ValueError):
            pass
