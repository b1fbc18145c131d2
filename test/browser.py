"""Headless Chromium for the browser tests: Debian's chromium, driven by playwright.

``make test`` installs chromium when it is missing and it can (root with apt-get); where
it cannot, or playwright is absent, :func:`chromium_or_skip` skips with the reason.
:class:`Watch` records what a page did: console errors, page errors, failed requests and
every request that leaves the allowed origins (``data:`` and ``blob:`` stay inside).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from typing import Any, Iterator, Sequence

import pytest

# The flags the machine notes give for a closed network: no background connections.
ARGS = ['--headless=new', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
        '--disable-background-networking', '--disable-component-update', '--disable-sync',
        '--disable-default-apps', '--disable-extensions', '--mute-audio']
VIEWPORT = {'width': 1600, 'height': 1000}


def chromium_or_skip() -> str:
    """Return the chromium executable; skip the test (with the reason) when unusable."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        pytest.skip('playwright is not installed (requirements.txt; make venv)')
    path = os.environ.get('RWA_MONITOR_CHROMIUM') or shutil.which('chromium') or (
        '/usr/bin/chromium' if os.access('/usr/bin/chromium', os.X_OK) else None)
    if path is None:
        pytest.skip('chromium not found: make test installs it as root (apt-get install '
                    'chromium); set RWA_MONITOR_CHROMIUM to use another build')
    return path


@contextlib.contextmanager
def browser() -> Iterator[Any]:
    """Yield a launched headless chromium (playwright Browser), closed afterwards."""
    from playwright.sync_api import sync_playwright
    executable = chromium_or_skip()
    with sync_playwright() as driver:
        chrome = driver.chromium.launch(executable_path=executable, args=ARGS)
        try:
            yield chrome
        finally:
            chrome.close()


class Watch:
    """What a page did: errors, and requests outside ``origins``."""

    def __init__(self, page: Any, origins: Sequence[str]) -> None:
        self.errors: list[str] = []
        self.outside: list[str] = []
        self.failed: list[str] = []
        self.requests: list[str] = []
        self.origins = tuple(origins) + ('data:', 'blob:')
        page.on('console', self._console)
        page.on('pageerror', lambda err: self.errors.append(f'pageerror: {err}'))
        page.on('request', self._request)
        page.on('requestfailed', lambda r: self.failed.append(f'{r.url}: {r.failure}'))

    def _console(self, message: Any) -> None:
        if message.type == 'error':
            self.errors.append(f'console: {message.text}')

    def _request(self, request: Any) -> None:
        self.requests.append(request.url)
        if not request.url.startswith(self.origins):
            self.outside.append(request.url)


def free_port() -> int:
    """Return a TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def start_server(args: Sequence[str], env: dict[str, str] | None = None,
                 timeout: float = 120.0) -> tuple[subprocess.Popen, str]:
    """Start ``rwa-monitor openmct ARGS`` and return (process, page URL) once it serves."""
    proc = subprocess.Popen([sys.executable, '-m', 'rwa_monitor.cli.main', 'openmct',
                             '--port', '0', *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + timeout
    lines = []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if "operator's view on " in line:
            url = line.split("operator's view on ", 1)[1].split()[0]
            proc.log = lines        # type: ignore[attr-defined]
            drain = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
            drain.start()           # a full pipe would stop the server
            proc.drain = drain      # type: ignore[attr-defined]
            return proc, url
    proc.kill()
    raise AssertionError('rwa-monitor openmct did not start:\n' + ''.join(lines)
                         + (proc.stdout.read() or ''))


def stop(proc: subprocess.Popen) -> str:
    """Stop a process started by a test (SIGINT, then kill); return its output."""
    if proc.poll() is None:
        proc.send_signal(2)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    drain = getattr(proc, 'drain', None)
    if drain is not None:
        drain.join(timeout=5)
        return ''.join(proc.log)
    out, _ = proc.communicate()
    return out or ''
