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

import threading
from collections.abc import Iterator
from typing import Any

import pytest
import viser

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
