"""A browser that leaves leaves nothing behind, even when it leaves while its widgets are built.

viser runs the console's per-browser set-up (the Session panel's widgets and replay session,
the viewer line) in its thread pool, after the browser's first camera message; a browser that
leaves meanwhile has its disconnect callbacks run first, which find nothing yet to drop. The
set-up then looked for the browser in viser's client list (``console.panels.common.events
.connected``) and builds nothing for one that left (before: entries kept for ever, and a
traceback per browser when viser had removed its containers; a flood of 1000 connections left
37 tracebacks in the log). The replay player's thread ends with the last browser's session.
Connection floods as a whole: ``benchmarks/connection_flood.py``.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from typing import Any

import pytest
import viser

from console.panels.common import session as session_mod
from console.panels.common.session import SessionPanel
from console.playback.replay import ReplayPlayer
from core.robots import load
from fakes import console_app
from tests.ws_client import RawClient, wait_for

SOFT = load("soft-arm")


@pytest.fixture
def app() -> Iterator[Any]:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    built = console_app(SOFT, server, panels=(SessionPanel,))
    try:
        yield built
    finally:
        server.stop()


def test_a_browser_that_left_before_its_set_up_ran_gets_nothing_built(app: Any) -> None:
    server, session = app.server, app.panel(SessionPanel)
    browser = RawClient(server)
    handle = server.get_clients()[browser.client_id]
    wait_for(lambda: browser.client_id in session.clients, what="its widgets")
    browser.close()
    wait_for(lambda: browser.client_id not in server.get_clients()
             and browser.client_id not in session.clients
             and browser.client_id not in app.viewer_line._lines, what="its teardown")
    # Its set-up runs late (as from viser's thread pool after the disconnect callbacks):
    session._on_connect(handle)
    session.build_due(math.inf)  # (its widgets were due at once)
    app.viewer_line._on_connect(handle)
    assert browser.client_id not in session.clients and len(session.player) == 0
    assert browser.client_id not in app.viewer_line._lines


class _Session:
    playing = False

    def __init__(self) -> None:
        self.closed = False

    def close(self) -> None:
        self.closed = True


def test_the_replay_players_thread_ends_with_the_last_session_and_starts_with_a_new_one() -> None:
    player = ReplayPlayer(rate_hz=200.0)
    replay_threads = lambda: {t for t in threading.enumerate()  # noqa: E731
                              if t.name == "console-replay" and t.is_alive()}
    others = replay_threads()  # (other tests' players in this process)
    try:
        first, second = _Session(), _Session()
        player.add(1, first)
        player.add(2, second)
        ours = replay_threads() - others
        assert len(ours) == 1
        player.remove(1)
        assert first.closed and all(t.is_alive() for t in ours)  # 2 still has one
        player.remove(2)
        wait_for(lambda: not any(t.is_alive() for t in ours), timeout=5.0,
                 what="the thread ended")
        player.add(3, _Session())
        assert len(replay_threads() - others - ours) == 1
    finally:
        player.stop()


def stop_builder(session: SessionPanel) -> None:
    """End the Session panel's builder thread (a test then calls ``build_due`` itself)."""
    session._quit.set()
    session._wake.set()
    assert session._builder is not None
    session._builder.join(2.0)


def test_a_socket_that_leaves_before_build_after_s_costs_no_widgets_and_one_that_stays_gets_them(
        app: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 32: a connection flood's sockets (open, hello, close) each got the Session panel's
    per-browser widgets built, after they had left (viser warned for each). Now a browser's
    widgets are due BUILD_AFTER_S after it connected (the panel's clock, frozen here), and a
    batch of them refreshes the role lines once."""
    server, session = app.server, app.panel(SessionPanel)
    stop_builder(session)  # the test builds by hand
    clock = [session.clock()]
    session.clock = lambda: clock[0]
    built: list[int] = []
    build = session._build_client
    monkeypatch.setattr(session, "_build_client",
                        lambda client, access: (built.append(client.client_id),
                                                build(client, access)))
    refreshes: list[int] = []
    refresh, me = session.refresh, threading.current_thread()
    monkeypatch.setattr(session, "refresh", lambda: (  # (this thread's: build_due's)
        refreshes.append(1) if threading.current_thread() is me else None, refresh()))
    flood = [RawClient(server) for _ in range(5)]
    stays = [RawClient(server) for _ in range(3)]
    for browser in flood:
        browser.close()
    wait_for(lambda: not any(b.client_id in server.get_clients() or b.client_id in
                             session._pending for b in flood),
             what="the flood's sockets dropped (their disconnect callbacks ran)")
    assert session.build_due(clock[0] + session_mod.BUILD_AFTER_S - 0.01) is not None
    assert built == [] and session.clients == {}  # not due yet
    clock[0] += session_mod.BUILD_AFTER_S
    assert session.build_due(clock[0]) is None  # nobody waits any more
    assert sorted(built) == sorted(b.client_id for b in stays)  # the flood: nothing built
    assert set(session.clients) == {b.client_id for b in stays} and len(refreshes) == 1
    for browser in stays:
        browser.close()


def test_a_browser_whose_widgets_fail_to_build_costs_the_others_of_its_batch_nothing(
        app: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    server, session = app.server, app.panel(SessionPanel)
    stop_builder(session)  # the test builds by hand
    browsers = [RawClient(server) for _ in range(3)]
    wait_for(lambda: all(b.client_id in session._pending for b in browsers),
             what="three browsers waiting")
    bad = browsers[1].client_id
    build = session._build_client

    def build_or_fail(client: Any, access: Any) -> None:
        if client.client_id == bad:
            raise RuntimeError("a widget could not be built")
        build(client, access)

    monkeypatch.setattr(session, "_build_client", build_or_fail)
    assert session.build_due(math.inf) is None
    assert set(session.clients) == {browsers[0].client_id, browsers[2].client_id}
    assert any("building the Session widgets of browser" in r.getMessage()
               for r in caplog.records)
    for browser in browsers:
        browser.close()
