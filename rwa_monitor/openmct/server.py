"""The operator's view server: the Open MCT page, its history API and the live WebSocket.

One tornado application on ``host``:``port`` (127.0.0.1 by default; port 0 takes a free
one):

- ``/`` the page (``web/index.html``), ``/rwa/*`` the plugin, ``/openmct/*`` the Open MCT
  bundle (files of this machine only: :mod:`rwa_monitor.openmct.bundle`);
- ``/api/dictionary`` the object tree (:meth:`GroundStore.dictionary`);
- ``/api/history?key=K&start=S&end=E[&domain=utc][&size=N][&strategy=latest]`` a point's
  samples, S and E in telemetry seconds (``met``) or UTC milliseconds (``utc``);
- ``/api/live`` a WebSocket: the client sends ``{"subscribe": [keys]}`` /
  ``{"unsubscribe": [keys]}``; the server sends ``{"type": "data", "data": [[key,
  datum], ...]}`` every ``FLUSH_MS`` and ``{"type": "dictionary", "version": n}`` when
  the tree grew.

Safety (docs/usage.md, "The operator's view"): every response carries a Content Security
Policy that lets the page load and connect to its own origin only; a request whose
``Host`` is not this server's own name (``127.0.0.1``, ``localhost``, ``[::1]`` or the
bound host, with its port) is refused with 403, which closes the DNS-rebinding path to a
loopback server; the WebSocket accepts only the page's own origin unless
``allowed_origins`` lists others (``*``: any).
"""

from __future__ import annotations

import asyncio
import json
import math
import pathlib
import socket
from typing import Any, Callable, Sequence
from urllib.parse import urlsplit

import tornado.ioloop
import tornado.web
import tornado.websocket

from rwa_monitor.openmct.bundle import WEB_DIR
from rwa_monitor.openmct.store import GroundStore

FLUSH_MS = 100
MAX_HISTORY = 200_000      # samples one history answer holds at most
CSP = ("default-src 'self'; script-src 'self' 'unsafe-eval'; style-src 'self' "
       "'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
       "connect-src 'self'; worker-src 'self' blob:; frame-ancestors 'none'; "
       "base-uri 'none'; form-action 'none'")
LOOPBACK_NAMES = ('127.0.0.1', 'localhost', '[::1]')


def _finite(value: Any) -> Any:
    return None if isinstance(value, float) and not math.isfinite(value) else value


def dumps(document: Any) -> str:
    """Return JSON with NaN and infinities as null (browsers refuse them)."""
    def clean(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v) for v in value]
        return _finite(value)
    return json.dumps(clean(document), separators=(',', ':'))


class _Guarded(tornado.web.RequestHandler):
    """A handler that refuses foreign Host headers and sets the security headers."""

    def prepare(self) -> None:
        if not self.application.settings['host_allowed'](self.request.host):
            raise tornado.web.HTTPError(403, reason='Host not allowed')

    def set_default_headers(self) -> None:
        self.set_header('Content-Security-Policy', CSP)
        self.set_header('X-Content-Type-Options', 'nosniff')
        self.set_header('Referrer-Policy', 'no-referrer')
        self.set_header('Cache-Control', 'no-store')


class _Static(tornado.web.StaticFileHandler):
    """Static files under the same rules (bundle files may be cached: they are pinned)."""

    def prepare(self) -> None:
        if not self.application.settings['host_allowed'](self.request.host):
            raise tornado.web.HTTPError(403, reason='Host not allowed')

    def set_default_headers(self) -> None:
        self.set_header('Content-Security-Policy', CSP)
        self.set_header('X-Content-Type-Options', 'nosniff')
        self.set_header('Referrer-Policy', 'no-referrer')


class _Page(_Guarded):
    def get(self) -> None:
        self.set_header('Content-Type', 'text/html; charset=utf-8')
        self.write((WEB_DIR / 'index.html').read_bytes())


class _Dictionary(_Guarded):
    def get(self) -> None:
        self.set_header('Content-Type', 'application/json')
        self.write(dumps(self.application.settings['store'].dictionary()))


class _History(_Guarded):
    def get(self) -> None:
        store: GroundStore = self.application.settings['store']
        key = self.get_argument('key')
        domain = self.get_argument('domain', 'met')
        try:
            start = float(self.get_argument('start', '-inf'))
            end = float(self.get_argument('end', 'inf'))
            size = int(self.get_argument('size', '0')) or None
        except ValueError:
            raise tornado.web.HTTPError(400, reason='start, end and size must be numbers')
        if domain == 'utc':
            if store.epoch_unix_s is None:
                raise tornado.web.HTTPError(400, reason='no epoch: use domain=met')
            start, end = start / 1000.0 - store.epoch_unix_s, end / 1000.0 - store.epoch_unix_s
        elif domain != 'met':
            raise tornado.web.HTTPError(400, reason='domain must be met or utc')
        latest = self.get_argument('strategy', '') == 'latest'
        try:
            data = store.history(key, start, end, size or MAX_HISTORY // 2, latest)
        except KeyError:
            raise tornado.web.HTTPError(404, reason=f'no point {key}')
        self.set_header('Content-Type', 'application/json')
        self.write(dumps(data))


class _Live(tornado.websocket.WebSocketHandler):
    """The live feed; only the page's own origin (or an allowed one) may connect."""

    def prepare(self) -> None:
        if not self.application.settings['host_allowed'](self.request.host):
            raise tornado.web.HTTPError(403, reason='Host not allowed')

    def check_origin(self, origin: str) -> bool:
        allowed = self.application.settings['allowed_origins']
        if '*' in allowed or origin in allowed:
            return True
        ok = super().check_origin(origin)   # same host and port as the page
        if not ok:
            self.application.settings['refused'].append(origin)
        return ok

    def open(self) -> None:
        self.keys: set[str] = set()
        self.version = -1
        self.application.settings['clients'].add(self)

    def on_message(self, message: str | bytes) -> None:
        try:
            request = json.loads(message)
            for key in request.get('subscribe', []):
                self.keys.add(str(key))
            for key in request.get('unsubscribe', []):
                self.keys.discard(str(key))
        except (ValueError, AttributeError, TypeError):
            self.close(1003, 'expected {"subscribe": [keys]} or {"unsubscribe": [keys]}')

    def on_close(self) -> None:
        self.application.settings['clients'].discard(self)


def host_check(port_of: Callable[[], int], bound: str) -> Callable[[str], bool]:
    """Return the test of a request's Host header: this server's own names and port."""
    names = set(LOOPBACK_NAMES)
    if bound not in ('', '0.0.0.0', '::'):
        names.add(f'[{bound}]' if ':' in bound else bound)
        names.add(socket.getfqdn(bound) if bound not in LOOPBACK_NAMES else bound)
    else:
        names.update({socket.gethostname(), socket.getfqdn()})

    def allowed(host: str) -> bool:
        parts = urlsplit(f'//{host}')
        try:
            port = parts.port
        except ValueError:
            return False
        name = host.rsplit(':', 1)[0] if port is not None else host
        return name.lower() in names and port in (None, port_of())
    return allowed


class GroundServer:
    """Serve ``store`` with the bundle at ``bundle`` (its ``dist`` folder)."""

    def __init__(self, store: GroundStore, bundle: pathlib.Path, host: str = '127.0.0.1',
                 port: int = 8090, allowed_origins: Sequence[str] = ()) -> None:
        self.store = store
        self.host = host
        self.clients: set[_Live] = set()
        self.refused: list[str] = []
        self._sent_version = store.version
        self.app = tornado.web.Application([
            (r'/', _Page),
            (r'/api/dictionary', _Dictionary),
            (r'/api/history', _History),
            (r'/api/live', _Live),
            (r'/rwa/(.*)', _Static, {'path': str(WEB_DIR)}),
            (r'/openmct/(.*)', _Static, {'path': str(bundle)}),
        ], store=store, clients=self.clients, refused=self.refused,
            allowed_origins=list(allowed_origins),
            host_allowed=host_check(lambda: self.port, host),
            websocket_ping_interval=20)
        self.server = self.app.listen(port, address=host, max_body_size=1 << 16)
        sockets = list(self.server._sockets.values())
        self.port: int = sockets[0].getsockname()[1]
        self._flusher = tornado.ioloop.PeriodicCallback(self.flush, FLUSH_MS)
        self._flusher.start()

    @property
    def url(self) -> str:
        """Return the page's address."""
        host = f'[{self.host}]' if ':' in self.host else self.host
        return f'http://{host}:{self.port}/'

    def flush(self) -> None:
        """Send the live samples gathered since the last call to their subscribers."""
        pending = self.store.take_pending()
        version = self.store.version
        for client in list(self.clients):
            try:
                if version != self._sent_version:
                    client.write_message(dumps({'type': 'dictionary', 'version': version}))
                mine = [[k, d] for k, d in pending if k in client.keys]
                if mine:
                    client.write_message(dumps({'type': 'data', 'data': mine}))
            except tornado.websocket.WebSocketClosedError:
                self.clients.discard(client)
        self._sent_version = version

    def stop(self) -> None:
        """Stop listening and close every client."""
        self._flusher.stop()
        self.server.stop()
        for client in list(self.clients):
            client.close(1001, 'server stopping')


async def serve_forever(server: GroundServer, stop: asyncio.Event) -> None:
    """Wait until ``stop`` is set, then stop the server."""
    await stop.wait()
    server.stop()
