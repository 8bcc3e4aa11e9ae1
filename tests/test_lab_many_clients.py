"""Many browsers connecting at once: every one gets its session widgets (no lost clients).

viser runs connect callbacks concurrently in its thread pool. Found by the load benchmark: with
20 clients arriving together, building per-client widgets inside the shared Session folder raised
("GuiFolderHandle is already active") and those clients got no "Take control" button. These are
real websocket clients of a real server (the same handshake a browser does), without rendering.
"""

from __future__ import annotations

import threading
import time

import msgspec
import pytest
import viser
from viser import _messages
from websockets.sync.client import connect

from console.access import AccessControl
from console.app import ConsoleApp
from console.panels.session import SessionPanel
from core.robots import load

SOFT = load("soft-arm")


def _viewer(url: str, ready: threading.Barrier, stop: threading.Event) -> None:
    """Connect like a browser (one camera message), then keep the socket open until ``stop``."""
    cam = _messages.ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0,
                                        480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    with connect(url, max_size=None, subprotocols=[f"viser-v{viser.__version__}"]) as ws:
        ready.wait(10)  # all sockets open, then everyone says hello together
        ws.send(msgspec.msgpack.encode(cam.as_serializable_dict()))
        while not stop.is_set():
            try:
                ws.recv(timeout=0.1)
            except TimeoutError:
                continue


@pytest.mark.parametrize("n_clients", [12])
def test_clients_connecting_together_all_get_session_widgets(n_clients: int) -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        app = ConsoleApp(SOFT, server, access=AccessControl("tok"),
                         panels=(SessionPanel,))
        session = app.panel(SessionPanel)
        url = f"ws://127.0.0.1:{server.get_port()}"
        ready, stop = threading.Barrier(n_clients), threading.Event()
        threads = [threading.Thread(target=_viewer, args=(url, ready, stop), daemon=True)
                   for _ in range(n_clients)]
        for th in threads:
            th.start()
        deadline = time.monotonic() + 20.0
        while len(session.clients) < n_clients and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(session.clients) == n_clients, (
            f"{n_clients - len(session.clients)} of {n_clients} clients got no session widgets")
        assert len(server.get_clients()) == n_clients
        stop.set()
        for th in threads:
            th.join(5)
        deadline = time.monotonic() + 10.0
        while session.clients and time.monotonic() < deadline:
            time.sleep(0.05)
        assert session.clients == {}  # disconnects clean up every client's widgets
    finally:
        server.stop()
