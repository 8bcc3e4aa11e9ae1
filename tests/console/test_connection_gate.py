"""Connection limits before viser builds a client (console.web.connection_gate), through raw
websocket clients from several local addresses (127.0.0.2 and .3 look like two other machines).

Independent expectations: the limits given (3 per address, 5 in all), the close code 1008 with
a reason naming the limit, viser's own list of clients (``server.get_clients()``: a refused
socket never appears there, so none of viser's or the console's per-client set-up ran), and one
log line per address however many were refused.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

import pytest
import viser
from websockets.exceptions import ConnectionClosed

import console.app as app_module
from console.web.connection_gate import ConnectionGate, ConnectionLimits, is_loopback
from core.robots import load
from fakes import console_app
from tests.ws_client import CAMERA, RawClient, encode, open_socket, wait_for

SOFT = load("soft-arm")

THIS_MACHINE = "127.0.0.9"  # the only address the test counts as loopback


@pytest.fixture
def gated(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, viser.ViserServer]]:
    monkeypatch.setattr(app_module, "is_loopback", lambda address: address == THIS_MACHINE)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(SOFT, server, panels=(),
                      connection_limits=ConnectionLimits(per_address=3, total=5))
    try:
        yield app, server
    finally:
        server.stop()


def refused(server: viser.ViserServer, source: str) -> ConnectionClosed:
    """Open a socket from ``source``, say hello, and return how the server closed it."""
    ws = open_socket(server.get_port(), source)
    try:
        ws.send(encode(CAMERA))
        while True:
            ws.recv(timeout=10)
    except ConnectionClosed as exc:
        return exc
    finally:
        ws.close()


def test_connections_over_the_limits_are_refused_before_viser_builds_a_client(
        gated: tuple[Any, viser.ViserServer], caplog: pytest.LogCaptureFixture) -> None:
    app, server = gated
    caplog.set_level(logging.WARNING, logger="console.web.connection_gate")
    clients: list[RawClient] = []
    try:
        clients += [RawClient(server, source="127.0.0.2") for _ in range(3)]
        assert len(server.get_clients()) == 3
        for _ in range(4):  # a fourth from .2, and again
            closed = refused(server, "127.0.0.2")
            assert closed.rcvd is not None and closed.rcvd.code == 1008
            assert "too many connections from 127.0.0.2 (limit 3 per address)" in closed.rcvd.reason
        clients += [RawClient(server, source="127.0.0.3") for _ in range(2)]  # 5 in all
        closed = refused(server, "127.0.0.3")
        assert closed.rcvd.code == 1008 and "at most 5 connections" in closed.rcvd.reason
        assert len(server.get_clients()) == 5 and app.connections.refused == 5
        assert app.connections.counted() == 5 and app.connections.counted("127.0.0.2") == 3
        # One line per address and minute, saying how many.
        lines = [r.getMessage() for r in caplog.records]
        assert len([x for x in lines if "127.0.0.2" in x]) == 1, lines
        assert len([x for x in lines if "at most 5" in x]) == 1, lines

        # This machine's browser and the operator's address are never refused.
        clients.append(RawClient(server, source=THIS_MACHINE))
        app.access.take(clients[0].client_id, None, name="Alice")  # from 127.0.0.2
        clients.append(RawClient(server, source="127.0.0.2"))
        assert len(server.get_clients()) == 7 and app.connections.counted() == 5

        # A closed connection frees its place.
        clients.pop(3).close()  # one of .3's
        wait_for(lambda: app.connections.counted("127.0.0.3") == 1, what="the slot freed")
        clients.append(RawClient(server, source="127.0.0.3"))
        assert app.connections.counted() == 5
    finally:
        for c in clients:
            c.close()
    wait_for(lambda: not server.get_clients() and app.connections.admitted == 0,
             what="every client gone")
    assert app.connections.counted() == 0


def test_loopback_is_never_refused_and_a_second_gate_takes_the_first_ones_clients_over() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        app = console_app(SOFT, server, panels=(),
                          connection_limits=ConnectionLimits(per_address=1, total=1))
        clients = [RawClient(server) for _ in range(3)]  # 127.0.0.1: this machine's
        gate = app.connections
        assert len(server.get_clients()) == 3 and gate.counted() == 0 and gate.admitted == 3
        again = ConnectionGate(server, ConnectionLimits(per_address=1, total=1),
                               privileged=lambda address: False)
        assert again.admitted == 3  # (the same clients, counted as before)
        clients.append(RawClient(server))  # the first counted one
        closed = refused(server, "127.0.0.1")
        assert closed.rcvd.code == 1008 and "limit 1 per address" in closed.rcvd.reason
        assert len(server.get_clients()) == 4
        for c in clients:
            c.close()
        wait_for(lambda: again.admitted == 0 and not server.get_clients(), what="all closed")
    finally:
        server.stop()


@pytest.mark.parametrize("address, expected", [
    ("127.0.0.1", True), ("127.8.9.10", True), ("::1", True), ("::ffff:127.0.0.1", True),
    ("10.0.0.5", False), ("::ffff:10.0.0.5", False), ("fe80::1%eth0", False), ("", False),
    (None, False), ("not an address", False)])
def test_loopback_addresses(address: str | None, expected: bool) -> None:
    assert is_loopback(address) is expected


def test_limits_below_one_are_refused() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        ConnectionLimits(per_address=0)
