"""A raw websocket client speaking viser's protocol (what a hostile or buggy viewer can send).

It connects with the browser's subprotocol, says hello with a camera message, decodes every
frame the server sends (zstd msgpack, see ``viser.infra._infra._message_producer``) and, like a
browser tab, answers the lease's localStorage probes (so an operator built from it keeps
control). Shared by the client-guard tests and usable from a REPL.
"""

from __future__ import annotations

import socket
import threading
import time
from typing import Any, Callable

import msgspec
import viser
import zstandard
from viser import _messages
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

CAMERA = _messages.ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0,
                                       480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))


def encode(message: Any) -> bytes:
    """A viser message object or a plain dict (anything a client could send) as a frame."""
    if isinstance(message, dict):
        return msgspec.msgpack.encode(message)
    return msgspec.msgpack.encode(message.as_serializable_dict())


def decode_payload(frame: bytes) -> dict[str, Any]:
    """One server frame's msgpack payload: ``messages`` and ``binaryBufferLengths`` (the
    binary buffers themselves follow the compressed part and are left out)."""
    size = int.from_bytes(frame[:8], "little")
    csize = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + csize], max_output_size=size)
    return msgspec.msgpack.decode(inner)


def decode_frame(frame: bytes) -> list[dict[str, Any]]:
    """The messages in one server frame (binary buffers are left out)."""
    return list(decode_payload(frame)["messages"])


def open_socket(port: int, source: str | None = None) -> Any:
    """A websocket to the viser server on 127.0.0.1:``port`` with the browser's subprotocol,
    from the local address ``source`` (None: the system's choice); nothing sent yet."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=20,
                                    source_address=None if source is None else (source, 0))
    return connect(f"ws://127.0.0.1:{port}", sock=sock, max_size=None, open_timeout=20,
                   subprotocols=[f"viser-v{viser.__version__}"])  # type: ignore[list-item]


def viewer_socket(port: int, source: str | None = None) -> Any:
    """:func:`open_socket` that has said hello as a viewer (a camera message): viser and the
    console build its client; nothing is read."""
    ws = open_socket(port, source)
    ws.send(encode(CAMERA))
    return ws


def drain(ws: Any) -> None:
    """Read and drop whatever ``ws`` has received so far (as a browser takes it)."""
    try:
        while True:
            ws.recv(timeout=0)
    except Exception:  # noqa: BLE001 - nothing queued, or closed
        pass


class RawClient:
    """One websocket connection to a viser server, receiving on a thread.

    Args:
        server: The viser server (to learn this connection's client id).
        answer_probes: Answer localStorage reads like a browser tab (the operator's lease).
        source: The local address to connect from (another 127.x.y.z looks like another
            machine to the server); default the system's choice.
    """

    def __init__(self, server: viser.ViserServer, answer_probes: bool = True,
                 source: str | None = None) -> None:
        before = set(server.get_clients())
        self.url = f"ws://127.0.0.1:{server.get_port()}"
        self.ws = open_socket(server.get_port(), source)
        self.answer_probes = answer_probes
        self.messages: list[dict[str, Any]] = []
        self.closed: ConnectionClosed | None = None
        self.frames = 0
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()
        self.send(CAMERA)
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            new = set(server.get_clients()) - before
            if new:
                self.client_id = max(new)
                break
            time.sleep(0.02)
        else:
            raise AssertionError("the server never registered this client")

    def _receive(self) -> None:
        while True:
            try:
                frame = self.ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except ConnectionClosed as exc:
                self.closed = exc
                return
            assert isinstance(frame, bytes)
            self.on_frame(frame)

    def on_frame(self, frame: bytes) -> None:
        """Keep one frame's messages (and answer lease probes); a subclass that accounts for
        frames differently overrides this, the receive loop stays the one above."""
        messages = decode_frame(frame)
        with self._lock:
            self.frames += 1
            self.messages.extend(messages)
        if self.answer_probes:
            for m in messages:
                if m.get("type") == "LocalStorageGetItemRequestMessage":
                    self.send(_messages.LocalStorageGetItemResponseMessage(
                        None, None, m["request_uuid"]))

    def send(self, message: Any) -> bool:
        """Send one message (object, dict or raw bytes / str); False if the socket is closed."""
        data = message if isinstance(message, (bytes, str)) else encode(message)
        try:
            self.ws.send(data)
            return True
        except ConnectionClosed as exc:
            self.closed = exc
            return False

    def update(self, uuid: str, **updates: Any) -> bool:
        """A ``GuiUpdateMessage`` as a browser would send it (any keys a hostile one names)."""
        return self.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": updates})

    def received(self, kind: str, where: Callable[[dict[str, Any]], bool] = lambda m: True
                 ) -> list[dict[str, Any]]:
        with self._lock:
            return [m for m in self.messages if m.get("type") == kind and where(m)]

    def clear(self) -> None:
        with self._lock:
            self.messages.clear()

    def alive(self) -> bool:
        return self.closed is None and self._thread.is_alive()

    def wait_closed(self, timeout: float = 10.0) -> ConnectionClosed | None:
        self._thread.join(timeout)
        return self.closed

    def close(self) -> None:
        try:
            self.ws.close()
        except Exception:
            pass
        self._thread.join(5.0)


def wait_for(predicate: Callable[[], Any], timeout: float = 10.0,
             what: str | Callable[[], str] = "condition", interval: float = 0.02) -> Any:
    """Call ``predicate`` every ``interval`` s until it returns a true value (returned); fail
    after ``timeout`` s naming ``what`` (a callable: called then, so the message shows the state
    at the failure, not when the wait began)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            said = what() if callable(what) else what
            raise AssertionError(f"{said} not reached in {timeout} s")
        time.sleep(interval)

