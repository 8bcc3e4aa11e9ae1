"""Issue 27.4: viser's patches are installed on purpose, on the tested viser, and fail closed.

Each patch of ``console.web`` is checked twice with the same behaviour probe: with the patch
undone, the probe observes upstream viser 1.1.1's behaviour (so the probe would fail on an
unpatched viser), and with it installed, the fixed one. The receive guard is also checked for
failing closed: a connection it cannot trace to a guard (viser's closure names changed, or a
server without a guard) has every message refused, never handed to viser unguarded.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from typing import Any, Callable, Iterator

import msgspec
import pytest
import viser
import websockets.exceptions
from viser import _messages
from viser.infra import _infra
from viser.infra._async_message_buffer import AsyncMessageBuffer

from fakes import upstream_viser as upstream
from console import web
from console.web import patches, receive_guard
from console.web.client_guard import ClientGuard
from console.web.share_tunnel import disable_share_tunnel, share_handlers
from console.web.shared_sends import LoopSafeEvent

GUARD_LOG = "console.web.client_guard"


def test_install_is_explicit_idempotent_and_reversible() -> None:
    assert web.installed()  # (tests/conftest.py installs for the session, as serve.py does)
    again = web.install()
    assert again.applied == () and again.tested and again.viser_version == viser.__version__
    assert web.TESTED_VISER_VERSION == "1.1.1" == viser.__version__
    with upstream():
        assert not web.installed()
        assert not getattr(_infra._message_consumer, "_client_guard", False)
    assert web.installed()


def test_another_viser_version_is_refused_naming_both(monkeypatch) -> None:
    with upstream(), monkeypatch.context() as m:
        m.setattr(viser, "__version__", "1.2.0")
        with pytest.raises(web.UntestedViser, match=r"viser 1\.2\.0 .*viser 1\.1\.1"):
            web.install()
        assert not web.installed()  # refused before anything was patched
        report = web.install(allow_untested=True)
        assert not report.tested and report.viser_version == "1.2.0"
        assert len(report.applied) == len(patches.PATCHES) and web.installed()


def test_a_console_is_not_built_on_an_unpatched_viser() -> None:
    from console.app import ConsoleApp
    from core.robots import load

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        with upstream("client guard"):
            with pytest.raises(RuntimeError, match=r"call console\.web\.install\(\) first"):
                ConsoleApp(load("soft-arm"), server, panels=())
    finally:
        server.stop()


# -- the receive guard ----------------------------------------------------------------------------


class FakeSocket:
    """The receiving end of a websocket: hands out ``frames``, then is closed."""

    def __init__(self, frames: list[bytes]) -> None:
        self.frames = list(frames)
        self.closed: tuple[int, str] | None = None

    async def recv(self) -> bytes:
        if self.frames and self.closed is None:
            return self.frames.pop(0)
        raise websockets.exceptions.ConnectionClosed(None, None)

    async def close(self, code: int, reason: str) -> None:
        self.closed = (code, reason)


def viser_handle_incoming(websock_server: Any, client: int,
                          applied: list[Any]) -> Callable[[Any], None]:
    """A stand-in for viser 1.1.1's per-connection ``handle_incoming`` closure (the names it
    closes over are the ones ``receive_guard.ROUTE_NAMES`` reads)."""
    self = websock_server
    client_id = client

    def handle_incoming(message: Any) -> None:
        applied.append((self, client_id, message))

    return handle_incoming


def renamed_handle_incoming(websock_server: Any, client: int,
                            applied: list[Any]) -> Callable[[Any], None]:
    """The same closure as a later viser might name it."""
    server = websock_server
    connection_id = client

    def handle_incoming(message: Any) -> None:
        applied.append((server, connection_id, message))

    return handle_incoming


def receive(frames: list[bytes], handle: Callable[[Any], None]) -> FakeSocket:
    """Run viser's receive loop (whatever ``_infra._message_consumer`` is now) over ``frames``."""
    socket = FakeSocket(frames)

    async def run() -> None:
        with contextlib.suppress(websockets.exceptions.ConnectionClosed):
            await _infra._message_consumer(socket, handle, _messages.Message)

    asyncio.run(run())
    return socket


@pytest.fixture
def guarded() -> Iterator[tuple[viser.ViserServer, Any, str]]:
    """A server with a client guard (nobody is the operator) and a checkbox: (server, its
    WebsockServer, a frame that sets the checkbox's ``removed``)."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        box = server.gui.add_checkbox("Armed", False)
        ClientGuard(server, is_operator=lambda cid: False, refuse=lambda c, r, a: None)
        frame = msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": box._impl.uuid,
                                        "updates": {"removed": True}})
        yield server, server._websock_server, frame
    finally:
        server.stop()


def test_the_receive_guard_refuses_what_upstream_applies(guarded) -> None:
    """Upstream ``_message_consumer`` hands a browser's ``removed`` update to viser, which
    ``setattr``s it; with the patch the guard drops it before viser sees it."""
    _, ws_server, frame = guarded
    applied: list[Any] = []
    with upstream("client guard"):
        receive([frame], viser_handle_incoming(ws_server, 7, applied))
    assert [m.updates for _, _, m in applied] == [{"removed": True}]  # upstream: applied
    applied.clear()
    receive([frame], viser_handle_incoming(ws_server, 7, applied))
    assert applied == []


def test_a_valid_message_passes_the_guard_to_viser(guarded) -> None:
    _, ws_server, _ = guarded
    camera = msgspec.msgpack.encode(_messages.ViewerCameraMessage(
        (1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0, 480, 640, (0.0, 0.0, 0.0),
        (0.0, 0.0, 1.0)).as_serializable_dict())
    applied: list[Any] = []
    receive([camera], viser_handle_incoming(ws_server, 3, applied))
    assert [(s, cid, type(m).__name__) for s, cid, m in applied] == \
        [(ws_server, 3, "ViewerCameraMessage")]


def test_renamed_closure_names_make_every_message_refused_not_applied(guarded,
                                                                      caplog) -> None:
    _, ws_server, frame = guarded
    camera = msgspec.msgpack.encode(_messages.ViewerCameraMessage(
        (1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0, 480, 640, (0.0, 0.0, 0.0),
        (0.0, 0.0, 1.0)).as_serializable_dict())
    caplog.set_level(logging.ERROR, logger=GUARD_LOG)
    applied: list[Any] = []
    receive([camera, frame, camera], renamed_handle_incoming(ws_server, 7, applied))
    assert applied == []  # not even the harmless camera: nothing unguarded reaches viser
    said = [r.getMessage() for r in caplog.records if r.name == GUARD_LOG]
    assert len(said) == 1 and "cannot be traced" in said[0] \
        and "every message it sends is refused" in said[0]


def test_a_server_without_a_guard_reads_nothing_until_one_is_attached(caplog) -> None:
    """A browser may connect before the console (and its guard) exists: its frames wait unread,
    then go through the guard; upstream viser takes them from anyone at once."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        box = server.gui.add_checkbox("Armed", False)
        removed = msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": box._impl.uuid,
                                          "updates": {"removed": True}})
        camera = msgspec.msgpack.encode(_messages.ViewerCameraMessage(
            (1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0, 480, 640,
            (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)).as_serializable_dict())
        caplog.set_level(logging.WARNING, logger=GUARD_LOG)
        applied: list[Any] = []
        handle = viser_handle_incoming(server._websock_server, 1, applied)
        socket = FakeSocket([removed, camera])

        async def run() -> tuple[int, int]:
            task = asyncio.ensure_future(_infra._message_consumer(socket, handle,
                                                                  _messages.Message))
            for _ in range(5):  # a few of its looks for a guard
                await asyncio.sleep(receive_guard.GUARD_POLL_S)
            unread, seen = len(socket.frames), len(applied)
            ClientGuard(server, is_operator=lambda cid: True, refuse=lambda c, r, a: None)
            with contextlib.suppress(websockets.exceptions.ConnectionClosed):
                await asyncio.wait_for(task, 10.0)
            return unread, seen

        assert asyncio.run(run()) == (2, 0)  # nothing read, nothing applied while unguarded
        assert [type(m).__name__ for _, _, m in applied] == ["ViewerCameraMessage"]
        said = [r.getMessage() for r in caplog.records if r.name == GUARD_LOG]
        assert len(said) == 2 and "no client guard attached" in said[0]  # once; then the
        assert "removed" in said[1]  # guard's own line about the refused update
        applied.clear()
        with upstream("client guard"):
            receive([removed], viser_handle_incoming(server._websock_server, 1, applied))
        assert [m.updates for _, _, m in applied] == [{"removed": True}]
    finally:
        server.stop()


def test_a_browser_leaving_while_waiting_for_a_guard_ends_its_receive_loop() -> None:
    """Waiting for a guard ends when the connection closes (ConnectionClosed, as viser's own loop
    ends), and leaves no task behind."""
    class ClosingSocket(FakeSocket):
        def __init__(self) -> None:
            super().__init__([b"never read"])
            self.gone = asyncio.Event()

        async def wait_closed(self) -> None:
            await self.gone.wait()

        async def recv(self) -> bytes:
            if self.gone.is_set():
                raise websockets.exceptions.ConnectionClosed(None, None)
            return await super().recv()

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        applied: list[Any] = []
        handle = viser_handle_incoming(server._websock_server, 4, applied)

        async def run() -> tuple[int, str, int]:
            socket = ClosingSocket()
            task = asyncio.ensure_future(_infra._message_consumer(socket, handle,
                                                                  _messages.Message))
            await asyncio.sleep(5 * receive_guard.GUARD_POLL_S)
            waiting = len(asyncio.all_tasks()) - 2  # (this one and the receive loop)
            socket.gone.set()
            try:
                await asyncio.wait_for(task, 10.0)
                ended = "returned"
            except websockets.exceptions.ConnectionClosed:
                ended = "ConnectionClosed"
            await asyncio.sleep(0)
            return waiting, ended, len(asyncio.all_tasks()) - 1

        assert asyncio.run(run()) == (1, "ConnectionClosed", 0)  # one waiter, not one a look
        assert applied == []
    finally:
        server.stop()


def test_install_refuses_a_viser_whose_receive_route_changed(monkeypatch) -> None:
    """viser's ``handle_incoming`` as a later version might name it: the patch is not applied
    (rather than applied and then unable to find any guard)."""
    with upstream(), monkeypatch.context() as m:
        m.setattr(receive_guard, "ROUTE_NAMES", ("self", "connection_id"))
        upstream_consumer = _infra._message_consumer
        with pytest.raises(web.IncompatibleViser, match="connection_id"):
            web.install()
        assert _infra._message_consumer is upstream_consumer
        assert not web.installed()


def test_the_route_check_reads_viser_1_1_1_and_rejects_other_shapes() -> None:
    receive_guard.check_route()  # viser 1.1.1 as installed

    class Renamed:
        def _background_worker(self) -> None:
            connection_id = 0

            def handle_incoming(message: Any) -> None:
                print(self, connection_id, message)

    with pytest.raises(web.IncompatibleViser, match=r"\['client_id'\]"):
        receive_guard.check_route(owner=Renamed)

    async def consumer(socket: Any, handler: Any, cls: Any) -> None:
        pass

    with pytest.raises(web.IncompatibleViser, match="_message_consumer takes"):
        receive_guard.check_route(consumer=consumer)


# -- the sending side ------------------------------------------------------------------------------


def test_message_events_set_off_the_loop_are_handed_to_the_loop() -> None:
    """Upstream ``AsyncMessageBuffer.__init__`` makes a plain ``asyncio.Event``, which another
    thread's ``set()`` sets at once (iterating the loop's waiters from that thread); patched,
    the set is scheduled on the buffer's loop."""
    def probe() -> tuple[bool, bool, int]:
        loop = asyncio.new_event_loop()
        try:
            buffer = AsyncMessageBuffer(loop, persistent_messages=True)
            t = threading.Thread(target=buffer.message_event.set)
            t.start()
            t.join()
            at_once = buffer.message_event.is_set()
            loop.run_until_complete(asyncio.sleep(0))
            return at_once, buffer.message_event.is_set(), buffer.max_window_size
        finally:
            loop.close()

    with upstream("loop-safe"):
        assert probe() == (True, True, 128)
    assert probe() == (False, True, 512)
    loop = asyncio.new_event_loop()
    try:
        assert isinstance(AsyncMessageBuffer(loop, False).message_event, LoopSafeEvent)
    finally:
        loop.close()


def test_a_message_is_serialised_once_for_all_clients() -> None:
    """Upstream ``Message.as_serializable_dict`` builds a new dict per client."""
    def probe() -> bool:
        m = _messages.SetBonePositionMessage("/arm/body", 3, (0.1, 0.2, 0.3))
        return m.as_serializable_dict([]) is m.as_serializable_dict([])

    with upstream("as_serializable_dict"):
        assert probe() is False
    assert probe() is True


def _two_viewers() -> tuple[list[Any], list[bytes]]:
    """Two clients' first windows and first websocket frames from one broadcast buffer."""
    async def run() -> tuple[list[Any], list[bytes]]:
        loop = asyncio.get_running_loop()
        buffer = AsyncMessageBuffer(loop, persistent_messages=True)
        for i in range(5):
            buffer.push(_messages.SetBonePositionMessage("/arm/body", i, (0.0, 0.01 * i, 0.0)))
        generators = [buffer.window_generator(cid) for cid in (1, 2)]
        windows = [await g.__anext__() for g in generators]
        for g in generators:
            await g.aclose()
        sent: list[list[bytes]] = [[], []]

        class Socket:
            def __init__(self, out: list[bytes]) -> None:
                self.out = out

            async def send(self, frame: bytes) -> None:
                self.out.append(frame)

        tasks = [loop.create_task(_infra._message_producer(Socket(out), buffer, cid))
                 for cid, out in zip((1, 2), sent)]
        for _ in range(500):
            if all(sent):
                break
            await asyncio.sleep(0.001)
        buffer.set_done()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        return windows, [out[0] for out in sent]

    return asyncio.run(run())


def test_a_broadcast_window_is_walked_once_for_all_clients() -> None:
    """Upstream ``AsyncMessageBuffer._window_loop`` walks the buffer per client: equal windows,
    two lists."""
    with upstream("_window_loop"):
        (a, b), _ = _two_viewers()
    assert a == b and a is not b
    (a, b), _ = _two_viewers()
    assert a is b


def test_a_websocket_frame_is_encoded_once_for_all_clients() -> None:
    """Upstream ``_message_producer`` encodes and compresses the window per client."""
    with upstream("_message_producer"):
        _, (a, b) = _two_viewers()
    assert a is not b
    _, (a, b) = _two_viewers()
    assert a is b


def test_the_share_tunnel_is_closed_where_upstream_leaves_it_open() -> None:
    """Upstream ``ViserServer`` answers a browser's ``ShareUrlRequest``."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        assert share_handlers(server) == 2  # upstream: a message away from a public tunnel
        disable_share_tunnel(server)
        assert share_handlers(server) == 0
        assert server.request_share_url() is None
    finally:
        server.stop()


# -- serve.py --------------------------------------------------------------------------------------


def test_serve_exits_2_on_another_viser_naming_both_versions(serve_module, monkeypatch,
                                                             capsys) -> None:
    with upstream(), monkeypatch.context() as m:
        m.setattr(viser, "__version__", "1.2.0")
        assert serve_module.main(["--port", "70000"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "1.2.0" in err[0] and "1.1.1" in err[0] \
            and "--allow-untested-viser" in err[0]  # refused before the port was even read
        assert not web.installed()


def test_serve_goes_on_with_a_loud_warning_when_told_to(serve_module, monkeypatch,
                                                        capsys) -> None:
    with upstream(), monkeypatch.context() as m:
        m.setattr(viser, "__version__", "1.2.0")
        assert serve_module.main(["--allow-untested-viser", "--port", "70000"]) == 2
        err = capsys.readouterr().err
        assert "WARNING: UNTESTED VISER 1.2.0 (tested: 1.1.1)" in err
        assert "--port must be in 1..65535" in err  # went on to the next check
        assert web.installed()
