"""Many browsers connecting at once: every one gets its session widgets (no lost clients).

viser runs connect callbacks concurrently in its thread pool. Found by the load benchmark: with
20 clients arriving together, building per-client widgets inside the shared Session folder raised
("GuiFolderHandle is already active") and those clients got no "Take control" button. These are
real websocket clients of a real server (the same handshake a browser does), without rendering.
"""

from __future__ import annotations

import asyncio
import collections
import threading
import time

import msgspec
import pytest
import viser
from viser import _messages
from websockets.sync.client import connect

from console.core.access import AccessControl
from console.app import ConsoleApp
from console.panels.common.session import SessionPanel
from console.web import installed
from console.web.shared_sends import LoopSafeEvent
from core.robots import load

SOFT = load("soft-arm")
WAIT_S = 60.0  # deadline of every wait: each takes well under a second, but 2 cores are busy


def _viewer(url: str, ready: threading.Barrier, stop: threading.Event) -> None:
    """Connect like a browser (one camera message), then keep the socket open until ``stop``."""
    cam = _messages.ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0,
                                        480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    with connect(url, max_size=None, subprotocols=[f"viser-v{viser.__version__}"]) as ws:
        ready.wait(WAIT_S)  # all sockets open, then everyone says hello together
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
        deadline = time.monotonic() + WAIT_S
        while len(session.clients) < n_clients and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(session.clients) == n_clients, (
            f"{n_clients - len(session.clients)} of {n_clients} clients got no session widgets")
        assert len(server.get_clients()) == n_clients
        stop.set()
        for th in threads:
            th.join(WAIT_S)
        deadline = time.monotonic() + WAIT_S
        while session.clients and time.monotonic() < deadline:
            time.sleep(0.05)
        assert session.clients == {}  # disconnects clean up every client's widgets
    finally:
        server.stop()


def test_browsers_connected_before_the_session_panel_is_built_get_their_widgets() -> None:
    """serve.py answers browsers before its panels exist. A browser already connected when the
    Session panel was built crashed serve.py (the panel built its widgets inside its own folder's
    `with` block: "GuiFolderHandle is already active"); seen in a full browser-test run.
    (A browser's messages are read only once the console's client guard exists, so the console
    is built first and the panel added after, as ``serve.build`` adds its panels.)"""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    ready, stop = threading.Barrier(2), threading.Event()
    url = f"ws://127.0.0.1:{server.get_port()}"
    threads = [threading.Thread(target=_viewer, args=(url, ready, stop), daemon=True)
               for _ in range(2)]
    try:
        for th in threads:
            th.start()
        app = ConsoleApp(SOFT, server, access=AccessControl("tok"), panels=())
        deadline = time.monotonic() + WAIT_S
        while len(server.get_clients()) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert len(server.get_clients()) == 2
        session = app.add_panel(SessionPanel)
        assert session is not None
        assert set(session.clients) == set(server.get_clients())
    finally:
        stop.set()
        for th in threads:
            th.join(5)
        server.stop()


class _WatchedWaiters(collections.deque):
    """A waiter deque that records which threads iterate it."""

    def __init__(self) -> None:
        super().__init__()
        self.iterated_by: set[int] = set()

    def __iter__(self):  # type: ignore[no-untyped-def]
        self.iterated_by.add(threading.get_ident())
        return super().__iter__()


def _loop_in_thread() -> tuple[asyncio.AbstractEventLoop, threading.Thread]:
    loop = asyncio.new_event_loop()
    th = threading.Thread(target=loop.run_forever, daemon=True)
    th.start()
    return loop, th


@pytest.mark.parametrize("event_kind", ["asyncio.Event", "LoopSafeEvent"])
def test_setting_the_message_event_from_another_thread(event_kind: str) -> None:
    """viser sets its buffers' events from our threads: only LoopSafeEvent leaves the waiter
    list to the loop's thread (a plain asyncio.Event iterates it from ours: the race)."""
    loop, th = _loop_in_thread()
    try:
        async def make() -> asyncio.Event:
            return asyncio.Event() if event_kind == "asyncio.Event" else LoopSafeEvent(loop)

        event = asyncio.run_coroutine_threadsafe(make(), loop).result(WAIT_S)
        event._waiters = _WatchedWaiters()  # type: ignore[attr-defined]
        woke = asyncio.run_coroutine_threadsafe(event.wait(), loop)
        deadline = time.monotonic() + WAIT_S
        while not event._waiters and time.monotonic() < deadline:  # type: ignore[attr-defined]
            time.sleep(0.005)
        assert event._waiters, "the waiter was never parked"  # type: ignore[attr-defined]
        event.set()  # from this (non-loop) thread, then through the loop: as viser's push()
        loop.call_soon_threadsafe(event.set)
        assert woke.result(WAIT_S) is True
        foreign = event._waiters.iterated_by - {th.ident}  # type: ignore[attr-defined]
        if event_kind == "asyncio.Event":
            assert foreign == {threading.get_ident()}  # the bug this module works around
        else:
            assert foreign == set()
    finally:
        loop.call_soon_threadsafe(loop.stop)
        th.join(5)


def test_console_servers_use_loop_safe_message_events() -> None:
    """Installed by console.web.install() (tests/conftest.py, as serve.py): the broadcast buffer
    and every client's buffer."""
    assert installed()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        ws_server = server._websock_server
        assert isinstance(ws_server._broadcast_buffer.message_event, LoopSafeEvent)
        stop = threading.Event()
        th = threading.Thread(target=_viewer, daemon=True,
                              args=(f"ws://127.0.0.1:{server.get_port()}", threading.Barrier(1),
                                    stop))
        th.start()
        deadline = time.monotonic() + WAIT_S
        while not ws_server._client_state_from_id and time.monotonic() < deadline:
            time.sleep(0.02)
        states = list(ws_server._client_state_from_id.values())
        assert states and all(isinstance(s.message_buffer.message_event, LoopSafeEvent)
                              for s in states)
        stop.set()
        th.join(5)
    finally:
        server.stop()
