"""One port for every Foxglove client: ``foxglove.websocket.v1`` and ``foxglove.sdk.v1`` alike.

foxglove-sdk 0.30's WebSocket server accepts only the subprotocol name ``foxglove.sdk.v1``,
which carries the same messages as the older ``foxglove.websocket.v1`` under a new name (see the
SDK's handshake); Lichtblick releases before its ``foxglove.sdk.v1`` support, and every client
built on ``@foxglove/ws-protocol``, ask for ``foxglove.websocket.v1`` only and would be turned
away. :class:`SubprotocolRelay` listens on the public port, accepts either name and relays every
frame unchanged, both ways, to the SDK server on a loopback port. It decides nothing: what a
client may do (here: nothing but subscribe) is still the SDK server's answer. It remembers which
client is behind each of its loopback connections (:meth:`SubprotocolRelay.client_of`), so what
the SDK logs about a connection can name the client's real address.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect
from websockets.sync.server import ServerConnection, serve
from websockets.typing import Subprotocol

log = logging.getLogger(__name__)
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
SUBPROTOCOLS = (Subprotocol(SDK_SUBPROTOCOL), Subprotocol("foxglove.websocket.v1"))
MAX_FRAME = 64 << 20


def _address(addr: Any) -> str:
    """A socket address as "host:port" (IPv6 hosts in brackets, as the SDK writes them)."""
    try:
        host, port = addr[0], addr[1]
    except (TypeError, IndexError):
        return str(addr)
    return f"[{host}]:{port}" if ":" in str(host) else f"{host}:{port}"


def _pump(src: Any, dst: Any) -> None:
    """Copy frames from ``src`` to ``dst`` until either closes; then close both."""
    try:
        for frame in src:
            dst.send(frame)
    except (ConnectionClosed, OSError):
        pass
    finally:
        for conn in (src, dst):
            try:
                conn.close()
            except Exception:  # already closing
                log.debug("relay close failed", exc_info=True)


class SubprotocolRelay:
    """Relays Foxglove WebSocket clients on ``host:port`` to the SDK server on ``upstream_port``.

    Args:
        upstream_port: The foxglove-sdk server's port on 127.0.0.1.
        host: Address to bind (as serve.py's ``--host``).
        port: Public port (0: an ephemeral one, see :attr:`port`).
    """

    def __init__(self, upstream_port: int, host: str, port: int) -> None:
        self.upstream = f"ws://127.0.0.1:{upstream_port}"
        self._clients: dict[str, str] = {}  # our loopback "host:port" -> the client's address
        self._lock = threading.Lock()
        self._server = serve(self._handle, host, port, subprotocols=list(SUBPROTOCOLS),
                             compression=None, max_size=MAX_FRAME)
        self.port = int(self._server.socket.getsockname()[1])
        self._thread = threading.Thread(target=self._server.serve_forever,
                                        name="foxglove-relay", daemon=True)
        self._thread.start()

    def _handle(self, client: ServerConnection) -> None:
        try:
            upstream = connect(self.upstream, subprotocols=[SUBPROTOCOLS[0]],
                               compression=None, max_size=MAX_FRAME, open_timeout=5)
        except (OSError, TimeoutError, ConnectionClosed) as exc:
            log.warning("foxglove relay: SDK server unreachable (%s)", exc)
            client.close(1011, "live data server unavailable")
            return
        ours, theirs = _address(upstream.local_address), _address(client.remote_address)
        with self._lock:
            self._clients[ours] = theirs
        down = threading.Thread(target=_pump, args=(upstream, client),
                                name="foxglove-relay-down", daemon=True)
        down.start()
        try:
            _pump(client, upstream)
            down.join(5.0)
        finally:
            with self._lock:
                self._clients.pop(ours, None)

    def client_of(self, address: str) -> str | None:
        """The address ("host:port") of the client relayed through our loopback ``address``."""
        with self._lock:
            return self._clients.get(address)

    def stop(self) -> None:
        self._server.shutdown()
        self._thread.join(5.0)
