"""The Foxglove bridge's public WebSocket endpoint: both subprotocol names, an Origin check.

foxglove-sdk's server accepts only the ``foxglove.sdk.v1`` WebSocket subprotocol. The
protocol's published client library, and the viewers built on it, offer
``foxglove.websocket.v1``: the same protocol under its earlier name. The SDK has no
option for a second name nor for an Origin check, so the bridge serves clients through
this front, a ``websockets`` (asyncio) server on the public host and port that

- negotiates either name (the SDK's first when a client offers both),
- refuses a browser page whose ``Origin`` is not allowed (:func:`origin_allowed`; by
  default only pages of this machine, ``http(s)://localhost`` or a loopback address),
  with HTTP 403 and a log line naming the origin and the parameter,
- serves at most ``max_clients`` connections at once (HTTP 503 beyond), and
- relays every WebSocket message of an accepted client, unread and unchanged, in both
  directions over its own connection to the SDK server.

The SDK's own server is where no browser can reach it: it listens on a loopback port
with TLS under a certificate made at start and trusted by nothing but this front
(:func:`loopback_certificate`; the SDK then refuses plain ``ws://``), so a web page that
finds the port can neither connect in the clear nor complete a TLS handshake (issue 36:
on main 91ca172 it accepted ``Origin: https://evil.example``).

One event loop in one thread serves every client: a client costs three file descriptors
(its socket, the relay's socket to the SDK, the SDK's end of it), released when it
leaves; a client that stops answering keepalive pings, or stops reading so that a
message to it waits the keepalive timeout, is dropped. Disconnects are ordinary events:
they are counted (:attr:`disconnects`), never logged with a traceback
(:class:`QuietDisconnects`).
"""

from __future__ import annotations

import asyncio
import datetime
import http
import ipaddress
import logging
import ssl
import threading
from typing import Callable, Sequence
import urllib.parse

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import serve, Server, ServerConnection
from websockets.exceptions import ConnectionClosed, InvalidHandshake
from websockets.http11 import Request, Response

SDK_SUBPROTOCOL = 'foxglove.sdk.v1'
SUBPROTOCOLS = (SDK_SUBPROTOCOL, 'foxglove.websocket.v1')
ANY_ORIGIN = '*'
KEEPALIVE_S = (20.0, 20.0)     # ping interval, pong timeout (websockets' defaults)
# Close codes that may not be sent in a close frame (RFC 6455, 7.4.1): sent as 1000.
_UNSENDABLE = {None, 1005, 1006, 1015}
_DISCONNECTS = (ConnectionClosed, ConnectionError, TimeoutError, EOFError,
                asyncio.IncompleteReadError, ssl.SSLError)


def is_loopback(host: str | None) -> bool:
    """Return True when ``host`` is a loopback address or ``localhost``."""
    if not host:
        return False
    host = host.strip('[]').lower()
    if host == 'localhost' or host.endswith('.localhost'):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:   # a host name: it may resolve beyond this machine
        return False


def is_loopback_origin(origin: str) -> bool:
    """Return True for the Origin of a page served by this machine (http(s), loopback)."""
    try:
        parts = urllib.parse.urlsplit(origin)
    except ValueError:
        return False
    return parts.scheme in ('http', 'https') and is_loopback(parts.hostname)


def origin_allowed(origin: str | None, allowed: Sequence[str], loopback: bool) -> bool:
    """Return True when a client sending ``origin`` may connect.

    A client that sends no Origin is not a browser page (the header is what browsers add)
    and is accepted. ``allowed`` lists the origins accepted (``*``: any); when it is
    empty, a loopback-bound server accepts only pages of this machine
    (:func:`is_loopback_origin`: any other web page open in the operator's browser could
    otherwise read the telemetry) and a server bound beyond loopback none.
    """
    if origin is None or ANY_ORIGIN in allowed:
        return True
    if allowed:
        return origin in allowed
    return loopback and is_loopback_origin(origin)


class QuietDisconnects(logging.Filter):
    """Drop the websockets log records of ordinary disconnects; count them.

    A client that leaves without a closing handshake, stops answering pings or resets
    its connection makes websockets log an error with a traceback ("keepalive ping
    failed", "connection handler failed", ...). That is how clients leave, not a fault
    of the bridge; other records pass unchanged.
    """

    def __init__(self) -> None:
        super().__init__()
        self.dropped = 0

    def filter(self, record: logging.LogRecord) -> bool:
        """Return False (drop) for a record whose exception is a disconnect."""
        error = record.exc_info[1] if record.exc_info else None
        if isinstance(error, _DISCONNECTS):
            self.dropped += 1
            return False
        return True


def loopback_certificate() -> tuple[bytes, bytes]:
    """Return (certificate, private key), PEM, of a new self-signed key for 127.0.0.1.

    Made at every start and kept in memory only: the SDK's server presents it, the front
    alone trusts it. Needs ``cryptography`` (extra ``foxglove``).
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, 'rwa_monitor foxglove bridge')])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=3650))
            .add_extension(x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address('127.0.0.1'))]), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    return (cert.public_bytes(serialization.Encoding.PEM),
            key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                              serialization.NoEncryption()))


def trusting(certificate: bytes) -> ssl.SSLContext:
    """Return a TLS client context that trusts ``certificate`` (PEM) and nothing else."""
    return ssl.create_default_context(cadata=certificate.decode('ascii'))


class WebSocketFront:
    """Serve ``host``:``port`` and relay each accepted client to ``upstream_port``.

    ``upstream_tls``: the context trusting the SDK server's certificate (``wss://``);
    None connects in the clear (a server without TLS, e.g. in tests of the front alone).
    ``max_clients``: connections served at once (None: no limit).
    """

    def __init__(self, host: str, port: int, upstream_port: int,
                 allowed_origins: Sequence[str], warn: Callable[[str], None], *,
                 upstream_tls: ssl.SSLContext | None = None, max_clients: int | None = None,
                 keepalive: tuple[float, float] = KEEPALIVE_S) -> None:
        """Start serving in a daemon thread (``port`` 0: a free port, see :attr:`port`)."""
        self.allowed_origins = list(allowed_origins)
        self.loopback = is_loopback(host)
        self.max_clients = max_clients
        self.refused = 0    # clients refused for their Origin
        self.busy = 0       # clients refused beyond max_clients
        self.stalled = 0    # clients dropped for reading nothing for the keepalive timeout
        self.quiet = QuietDisconnects()
        self.logger = logging.getLogger(f'rwa_monitor.foxglove_front.{id(self):x}')
        self.logger.addFilter(self.quiet)
        scheme = 'ws' if upstream_tls is None else 'wss'
        self._upstream = f'{scheme}://127.0.0.1:{upstream_port}'
        self._tls = upstream_tls
        self._warn = warn
        self._keepalive = keepalive
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name='foxglove-front',
                                        daemon=True)
        self._thread.start()
        try:
            self._server: Server = asyncio.run_coroutine_threadsafe(
                self._serve(host, port), self._loop).result(timeout=30.0)
        except BaseException:
            self._end_loop()
            raise
        self.port: int = self._server.sockets[0].getsockname()[1]

    async def _serve(self, host: str, port: int) -> Server:
        interval, timeout = self._keepalive
        # a client's messages are control requests: websockets' 1 MiB limit applies to them
        return await serve(self._relay, host, port, subprotocols=list(SUBPROTOCOLS),
                           process_request=self._check, compression=None,
                           ping_interval=interval, ping_timeout=timeout, close_timeout=5.0,
                           logger=self.logger)

    @property
    def disconnects(self) -> int:
        """Ordinary disconnects websockets would have logged with a traceback."""
        return self.quiet.dropped

    @property
    def clients(self) -> int:
        """Connections open now (those still in their handshake or closing included)."""
        return len(self._server.all_connections)

    def _check(self, connection: ServerConnection, request: Request) -> Response | None:
        origins = request.headers.get_all('Origin')
        origin = origins[0] if len(origins) == 1 else None
        address = (connection.remote_address or ('?',))[0]
        if len(origins) <= 1 and origin_allowed(origin, self.allowed_origins, self.loopback):
            if not self._full(len(self._server.all_connections) + 1):   # with this one
                return None
            self.busy += 1
            self._warn(f'refused a WebSocket client from {address}: {self.max_clients} '
                       'clients are connected (the most served at once)')
            return connection.respond(http.HTTPStatus.SERVICE_UNAVAILABLE,
                                      'Too many clients\n')
        self.refused += 1
        if len(origins) > 1:
            rule = 'a request may carry one Origin only'
        elif self.allowed_origins:
            rule = f'not in parameter allowed_origins {self.allowed_origins}'
        elif self.loopback:
            rule = ('parameter allowed_origins is empty, so only pages of this machine '
                    '(http(s)://localhost or a loopback address) may connect')
        else:
            rule = ('parameter allowed_origins is empty, so a server bound beyond localhost '
                    'accepts no browser page')
        self._warn(f'refused a WebSocket client from {address}: '
                   f'Origin {", ".join(map(repr, origins))}: {rule}')
        return connection.respond(http.HTTPStatus.FORBIDDEN, 'Origin not allowed\n')

    def _full(self, connections: int) -> bool:
        return self.max_clients is not None and connections > self.max_clients

    async def _relay(self, client: ServerConnection) -> None:
        if self._full(len(self._server.all_connections)):  # handshakes that raced past
            self.busy += 1
            await client.close(1013, 'too many clients, try again later')
            return
        try:
            upstream = await connect(self._upstream, subprotocols=[SDK_SUBPROTOCOL],
                                     compression=None, max_size=None, open_timeout=10,
                                     ping_interval=None, ssl=self._tls, logger=self.logger)
        except (OSError, InvalidHandshake, TimeoutError) as err:
            self._warn(f'the Foxglove server behind the front is unreachable: {err}')
            await client.close(1011, 'server unavailable')
            return
        stall = self._keepalive[1]
        async with upstream:
            down = asyncio.ensure_future(_forward(upstream, client, stall))
            await _forward(client, upstream, stall)
            if await down:
                self.stalled += 1

    def stop(self) -> None:
        """Close the listening socket and every client (code 1001), end the thread."""
        async def close() -> None:
            self._server.close()
            await self._server.wait_closed()
        try:
            asyncio.run_coroutine_threadsafe(close(), self._loop).result(timeout=15.0)
        finally:
            self._end_loop()

    def _end_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10.0)
        if not self._thread.is_alive():
            self._loop.close()


async def _forward(source: ClientConnection | ServerConnection,
                   sink: ClientConnection | ServerConnection, stall: float | None) -> bool:
    """Send every message of ``source`` to ``sink``; close ``sink`` as ``source`` closed.

    A send that cannot progress for ``stall`` seconds (a peer that stopped reading: its
    buffers full, so even a keepalive ping cannot be written and never times out) drops
    ``sink`` at once (its transport aborted). Returns True when it did.
    """
    try:
        async for message in source:
            try:
                async with asyncio.timeout(stall):
                    await sink.send(message)
            except TimeoutError:
                sink.transport.abort()
                return True
    except _DISCONNECTS:  # either end went away: close the other below
        pass
    code = source.close_code
    try:
        await sink.close(1000 if code in _UNSENDABLE else code, source.close_reason or '')
    except _DISCONNECTS:
        pass
    return False
