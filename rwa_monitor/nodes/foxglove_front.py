"""The Foxglove bridge's public WebSocket endpoint: both subprotocol names, an Origin check.

foxglove-sdk's server accepts only the ``foxglove.sdk.v1`` WebSocket subprotocol. The
protocol's published client library, and the viewers built on it, offer
``foxglove.websocket.v1``: the same protocol under its earlier name. The SDK has no
option for a second name nor for an Origin check, so the bridge serves clients through
this front, a ``websockets`` server on the public host and port that

- negotiates either name (the SDK's first when a client offers both),
- refuses a browser page whose ``Origin`` is not allowed (:func:`origin_allowed`), with
  HTTP 403 and a log line naming the origin and the parameter, and
- relays every WebSocket message of an accepted client, unread and unchanged, in both
  directions over its own connection to the SDK server on a loopback port.

The protocol (channels, subscriptions, message data) stays the SDK's; the front never
reads a message. The relay costs one loopback hop per message; a slow client still meets
the SDK's own per-client queue, since the relay stops reading the SDK while a send to the
client waits.
"""

from __future__ import annotations

import http
import ipaddress
import threading
from typing import Callable, Sequence

from websockets.exceptions import ConnectionClosed, InvalidHandshake
from websockets.http11 import Request, Response
from websockets.sync.client import ClientConnection, connect
from websockets.sync.server import serve, ServerConnection

SDK_SUBPROTOCOL = 'foxglove.sdk.v1'
SUBPROTOCOLS = (SDK_SUBPROTOCOL, 'foxglove.websocket.v1')
ANY_ORIGIN = '*'
# Close codes that may not be sent in a close frame (RFC 6455, 7.4.1): sent as 1000.
_UNSENDABLE = {None, 1005, 1006, 1015}


def is_loopback(host: str) -> bool:
    """Return True when ``host`` is a loopback address or ``localhost``."""
    if host == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:   # a host name: it may resolve beyond this machine
        return False


def origin_allowed(origin: str | None, allowed: Sequence[str], loopback: bool) -> bool:
    """Return True when a client sending ``origin`` may connect.

    A client that sends no Origin is not a browser page (the header is what browsers add)
    and is accepted. ``allowed`` lists the origins accepted (``*``: any); when it is
    empty, any origin is accepted on a loopback-bound server and none beyond it.
    """
    if origin is None or ANY_ORIGIN in allowed:
        return True
    return origin in allowed if allowed else loopback


class WebSocketFront:
    """Serve ``host``:``port`` and relay each accepted client to ``upstream_port``."""

    def __init__(self, host: str, port: int, upstream_port: int,
                 allowed_origins: Sequence[str], warn: Callable[[str], None]) -> None:
        """Start serving in a daemon thread (``port`` 0: a free port, see :attr:`port`)."""
        self.allowed_origins = list(allowed_origins)
        self.loopback = is_loopback(host)
        self.refused = 0   # clients refused for their Origin
        self._refused_lock = threading.Lock()
        self._upstream = f'ws://127.0.0.1:{upstream_port}'
        self._warn = warn
        # a client's messages are control requests: websockets' 1 MiB limit applies to them
        self._server = serve(self._relay, host, port, subprotocols=list(SUBPROTOCOLS),
                             process_request=self._check_origin, compression=None)
        self.port: int = self._server.socket.getsockname()[1]
        self._thread = threading.Thread(target=self._server.serve_forever,
                                        name='foxglove-front', daemon=True)
        self._thread.start()

    def _check_origin(self, connection: ServerConnection, request: Request
                      ) -> Response | None:
        origins = request.headers.get_all('Origin')
        origin = origins[0] if len(origins) == 1 else None
        if len(origins) <= 1 and origin_allowed(origin, self.allowed_origins, self.loopback):
            return None
        with self._refused_lock:   # handshakes run in one thread per client
            self.refused += 1
        if len(origins) > 1:
            rule = 'a request may carry one Origin only'
        elif self.allowed_origins:
            rule = f'not in parameter allowed_origins {self.allowed_origins}'
        else:
            rule = ('parameter allowed_origins is empty, so a server bound beyond localhost '
                    'accepts no browser page')
        self._warn(f'refused a WebSocket client from {connection.remote_address[0]}: '
                   f'Origin {", ".join(map(repr, origins))}: {rule}')
        return connection.respond(http.HTTPStatus.FORBIDDEN, 'Origin not allowed\n')

    def _relay(self, client: ServerConnection) -> None:
        try:
            upstream = connect(self._upstream, subprotocols=[SDK_SUBPROTOCOL],
                               compression=None, max_size=None, open_timeout=10)
        except (OSError, InvalidHandshake, TimeoutError) as err:
            self._warn(f'the Foxglove server behind the front is unreachable: {err}')
            client.close(1011, 'server unavailable')
            return
        with upstream:
            to_client = threading.Thread(target=_forward, args=(upstream, client),
                                         name='foxglove-front-relay', daemon=True)
            to_client.start()
            _forward(client, upstream)
            to_client.join()

    def stop(self) -> None:
        """Close the listening socket and every client (code 1001), wait for the relays."""
        self._server.shutdown()
        self._thread.join(timeout=10.0)


def _forward(source: ClientConnection | ServerConnection,
             sink: ClientConnection | ServerConnection) -> None:
    """Send every message of ``source`` to ``sink``; close ``sink`` as ``source`` closed."""
    try:
        for message in source:
            sink.send(message)
    except ConnectionClosed:  # either end went away: close the other below
        pass
    code = source.close_code
    sink.close(1000 if code in _UNSENDABLE else code, source.close_reason or '')
