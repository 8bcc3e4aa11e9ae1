"""Issues 14 and 20: the server survives anything one client sends, and only that client pays.

Bursts (5 000 camera messages, 10 000 STOP clicks), a 10 MB message, frames that do not decode,
unknown ids and message types, wrong tokens -- each from a raw websocket client speaking viser's
protocol (``tests/ws_client.py``), while the operator (answering the lease probes like a tab)
keeps control and a second client keeps receiving.

Time: the app's refusal and notification coalescing runs on a simulated clock that stands still
(a burst is coalesced to one note whatever the machine's speed), and a burst is sent while the
guard's own clock is stopped (:class:`StoppableClock`), so its token bucket admits exactly
``burst`` messages; only the lease (7 s) and the probes run on real time.
"""

from __future__ import annotations

import logging
import secrets
import time
from typing import Any, Iterator

import msgspec
import pytest
import viser
from viser import _messages

from console.core.access import AccessControl
from console.app import ConsoleApp
from console.panel_sets import DEFAULT_PANELS
from console.panels.common.jog import JogPanel
from console.panels.common.session import SessionPanel
from console.web.client_guard import GuardLimits
from core.robots import load
from fakes import FakeClock
from tests.ws_client import CAMERA, RawClient
from tests.ws_client import wait_for as _wait_for

SOFT = load("soft-arm")


def wait_for(predicate: Any, timeout: float = 60.0, what: str = "condition") -> Any:
    """``tests.ws_client.wait_for`` with a deadline generous enough for two busy cores (these
    tests run beside others): each wait is for something that takes well under a second."""
    return _wait_for(predicate, timeout, what)


class StoppableClock:
    """``time.monotonic`` that a test can stop (it then reads the instant it stopped at) and
    start again: while stopped, the guard's token buckets do not refill."""

    def __init__(self) -> None:
        self.stopped_at: float | None = None

    def __call__(self) -> float:
        return time.monotonic() if self.stopped_at is None else self.stopped_at

    def stop(self) -> None:
        self.stopped_at = time.monotonic()

    def start(self) -> None:
        self.stopped_at = None


@pytest.fixture
def lab(tmp_path: Any) -> Iterator[tuple[viser.ViserServer, ConsoleApp, str]]:
    """A lab console whose core clock is a :class:`FakeClock` (``app.core.clock``) and whose
    guard's clock is a :class:`StoppableClock` (``app.guard.clock``)."""
    token = secrets.token_urlsafe(9)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = ConsoleApp(SOFT, server, panels=(*DEFAULT_PANELS, SessionPanel),
                     access=AccessControl(token), data_dir=tmp_path / "runs", clock=FakeClock())
    app.guard.clock = StoppableClock()
    app.lease.busy = lambda: True  # probed every 0.1 s, as while jogging: a flood must not starve it
    app.start()
    try:
        yield server, app, token
    finally:
        app.stop()
        server.stop()


def _ready(app: ConsoleApp, *clients: RawClient) -> None:
    session = app.panel(SessionPanel)
    wait_for(lambda: {c.client_id for c in clients} <= set(session.clients),
             what="per-browser widgets built")


def _operator(server: viser.ViserServer, app: ConsoleApp, token: str) -> RawClient:
    op = RawClient(server)
    _ready(app, op)
    probes = app.lease.probes  # before take(): its first probe may be answered at once,
    app.access.take(op.client_id, token, "Olivia")  # and a still console probes no more
    wait_for(lambda: app.lease.probes > probes and app.access.status().answered,
             what="the operator's tab answers the lease")
    return op


def _close_code(client: RawClient) -> int | None:
    exc = client.wait_closed(60.0)
    assert exc is not None, "the client was not disconnected"
    frame = exc.rcvd or exc.sent
    return None if frame is None else frame.code


def _stop_uuid(app: ConsoleApp) -> str:
    return app.header.stop_btn._impl.uuid


@pytest.mark.parametrize("burst", ["10000 STOP clicks", "5000 camera messages"])
def test_a_burst_disconnects_only_the_sender_and_the_operator_keeps_control(
        lab: tuple, burst: str, caplog: pytest.LogCaptureFixture) -> None:
    server, app, token = lab
    app.lease.needed = lambda: True  # as while the arm moves: the tab must go on answering
    op = _operator(server, app, token)
    watcher, viewer = RawClient(server), RawClient(server)
    _ready(app, watcher, viewer)
    stops0, probes0 = app.stops, app.lease.probes
    if burst.endswith("STOP clicks"):
        frame = msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": _stop_uuid(app),
                                        "updates": {"value": True}})
        count = 10_000
    else:
        frame = msgspec.msgpack.encode(CAMERA.as_serializable_dict())
        count = 5_000
    lim = GuardLimits()
    caplog.set_level(logging.WARNING, logger="console.web.client_guard")
    app.guard.clock.stop()  # no refill during the burst: exactly `burst` messages get through
    try:
        for _ in range(count):
            if not viewer.send(frame):
                break
        assert _close_code(viewer) == 1008
        # the operator's tab goes on answering (its bucket holds far more than these answers)
        wait_for(lambda: app.lease.probes >= probes0 + 5, what="probes answered after a burst")
    finally:
        app.guard.clock.start()
    assert app.access.holder is not None and app.access.holder.client_id == op.client_id
    assert op.alive() and watcher.alive()
    assert app.stops - stops0 <= lim.burst  # the rest was dropped
    notes = watcher.received("NotificationShowMessage", lambda m: m["props"]["title"] == "STOP")
    assert len(notes) <= 1  # coalesced: one per few seconds (of the app's clock), not per click
    wait_for(lambda: any("disconnected" in r.getMessage() and str(viewer.client_id)
                         in r.getMessage() for r in caplog.records), what="a log line")
    assert len(caplog.records) < 20  # coalesced log lines, not one per message
    stops = app.stops
    watcher.update(_stop_uuid(app), value=True)  # STOP still works for everyone else
    wait_for(lambda: app.stops == stops + 1, what="the watcher's STOP")
    mine = f"client {watcher.client_id} stopped the arm."
    wait_for(lambda: watcher.received("NotificationShowMessage",
                                      lambda m: m["props"]["body"] == mine),
             what="the watcher still receiving")


def test_a_10_mb_message_disconnects_only_the_sender(lab: tuple,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    server, app, token = lab
    op = _operator(server, app, token)
    watcher, viewer = RawClient(server), RawClient(server)
    _ready(app, watcher, viewer)
    token_field = app.panel(SessionPanel).clients[viewer.client_id].token
    assert token_field is not None
    caplog.set_level(logging.WARNING, logger="console.web.client_guard")
    # 300 kB of text fits a frame but not a text field: refused, the viewer stays.
    viewer.update(token_field._impl.uuid, value="x" * 300_000)
    wait_for(lambda: viewer.received("GuiUpdateMessage",
                                     lambda m: m["uuid"] == token_field._impl.uuid),
             what="the field given back")
    assert token_field.value == "" and viewer.alive()
    # 10 MB: the connection is closed (1009, message too big); nothing is stored.
    viewer.update(token_field._impl.uuid, value="x" * 10_000_000)
    assert _close_code(viewer) == 1009
    assert token_field.value == ""
    wait_for(lambda: any("disconnected" in r.getMessage() for r in caplog.records),
             what="a log line")
    assert all(len(r.getMessage()) < 400 for r in caplog.records)  # no 21 MB log lines
    time.sleep(0.5)  # (a disconnect of the others would have come with the sender's)
    assert op.alive() and watcher.alive()
    assert app.access.holder is not None and app.access.holder.client_id == op.client_id


@pytest.mark.parametrize("frame", [b"\xc1\xc1 not msgpack", "a text frame",
                                   msgspec.msgpack.encode({"type": "NoSuchMessage"}),
                                   msgspec.msgpack.encode([1, 2, 3]),
                                   msgspec.msgpack.encode({"type": "GuiUpdateMessage"})],
                         ids=["garbage", "text", "unknown-type-name", "not-a-map",
                              "missing-fields"])
def test_frames_that_do_not_decode_disconnect_only_the_sender(lab: tuple, frame: Any) -> None:
    server, app, token = lab
    watcher, viewer = RawClient(server), RawClient(server)
    _ready(app, watcher, viewer)
    viewer.send(frame)
    assert _close_code(viewer) in (1003, 1008)
    time.sleep(0.3)
    assert watcher.alive()
    stops = app.stops
    watcher.update(_stop_uuid(app), value=True)
    wait_for(lambda: app.stops == stops + 1, what="STOP after the bad frame")


def test_unknown_ids_and_message_types_are_dropped(lab: tuple) -> None:
    """Messages a browser never sends (a server's GuiRemoveMessage, the share tunnel, forms),
    unknown uuids and malformed fields: dropped and logged; STOP stays."""
    server, app, token = lab
    watcher, viewer = RawClient(server), RawClient(server)
    _ready(app, watcher, viewer)
    stop = app.header.stop_btn
    bad = [
        _messages.GuiRemoveMessage(stop._impl.uuid),
        _messages.ShareUrlRequest(),
        _messages.GuiFormSubmitMessage(stop._impl.uuid),
        _messages.GetRenderResponseMessage(b"\x00" * 10, "no-such-render"),
        _messages.CommandTriggerMessage("no-such-command"),
        _messages.GuiButtonHoldMessage(stop._impl.uuid, 1e308),
        {"type": "GuiUpdateMessage", "uuid": "no-such-widget", "updates": {"value": 1}},
        {"type": "GuiUpdateMessage", "uuid": stop._impl.uuid, "updates": [["removed", True]]},
        {"type": "GuiUpdateMessage", "uuid": [1, 2], "updates": {"value": True}},
        {"type": "GuiUpdateMessage", "uuid": stop._impl.uuid, "updates": {"value": True,
                                                                         "removed": True}},
    ]
    dropped0 = app.guard.counts["type"] + app.guard.counts["invalid"]
    for message in bad:
        assert viewer.send(message)
    wait_for(lambda: app.guard.counts["type"] + app.guard.counts["invalid"]
             >= dropped0 + len(bad), what="every message dropped")
    assert viewer.alive() and watcher.alive()
    assert not stop._impl.removed and stop._impl.uuid in server.gui._gui_input_handle_from_uuid
    assert app.stops == 0
    viewer.update(stop._impl.uuid, value=True)
    wait_for(lambda: app.stops == 1, what="STOP")
    time.sleep(0.2)
    viewer.send(_messages.CommandTriggerMessage(app.header.stop_cmd._impl.uuid))
    wait_for(lambda: app.stops == 2, what="STOP from the command palette (Esc)")


def test_a_short_burst_is_rate_limited_without_a_disconnect(lab: tuple) -> None:
    server, app, token = lab
    viewer = RawClient(server)
    _ready(app, viewer)
    frame = msgspec.msgpack.encode(CAMERA.as_serializable_dict())
    rate0, accepted0 = app.guard.counts["rate"], app.guard.counts["accepted"]
    over = 400 - int(GuardLimits().burst)  # fewer than the flood's drops: no disconnect
    app.guard.clock.stop()  # all 400 at one instant of the guard's clock, however slow the box
    try:
        for _ in range(400):
            viewer.send(frame)
        wait_for(lambda: app.guard.counts["rate"] - rate0 == over,
                 what="the messages over the burst dropped")
    finally:
        app.guard.clock.start()
    assert app.guard.counts["accepted"] - accepted0 == 400 - over
    assert viewer.alive()
    viewer.send(frame)  # and the viewer is still heard once its bucket refills
    wait_for(lambda: app.guard.counts["accepted"] - accepted0 == 400 - over + 1,
             what="a later message accepted")
    assert viewer.alive() and app.guard.counts["rate"] - rate0 == over


def test_wrong_tokens_from_one_browser_do_not_lock_out_another(lab: tuple) -> None:
    """Issue 20.4: the wrong-token limit was global; one guesser kept the operator out."""
    server, app, token = lab
    guesser, operator = RawClient(server), RawClient(server)
    _ready(app, guesser, operator)
    session = app.panel(SessionPanel)
    g, o = session.clients[guesser.client_id], session.clients[operator.client_id]
    assert g.token is not None and o.token is not None
    clock: FakeClock = app.core.clock  # type: ignore[assignment]
    for i in range(app.access.max_failures + 2):
        guesser.update(g.token._impl.uuid, value=f"guess-{i}")
        wait_for(lambda: g.token.value == f"guess-{i}", what="the guess stored")
        refusals = app.refusals
        clock.t += 3.0  # past the refusal notes' coalescing: each refusal is counted
        guesser.update(g.take._impl.uuid, value=True)
        wait_for(lambda: app.refusals == refusals + 1, what="the guess refused")
    with pytest.raises(Exception, match="Too many"):
        app.access.take(guesser.client_id, token, address="127.0.0.1")
    operator.update(o.token._impl.uuid, value=token)
    wait_for(lambda: o.token.value == token, what="the operator's token stored")
    operator.update(o.take._impl.uuid, value=True)
    wait_for(lambda: app.access.holder is not None
             and app.access.holder.client_id == operator.client_id, what="operator in")


def test_a_viewers_jog_is_refused_in_the_panels_own_words(lab: tuple) -> None:
    """The guard names the action the panel gave ``operator_only`` ("jog"), as before."""
    server, app, token = lab
    op = _operator(server, app, token)
    viewer = RawClient(server)
    _ready(app, viewer)
    plus = app.panel(JogPanel).jog_buttons[("kappa1", 1)]  # the "+" beside κ₁'s slider
    before = app.store.command
    refused0 = app.guard.counts["refused"]
    for _ in range(5):
        viewer.send(_messages.GuiButtonHoldMessage(plus._impl.uuid, 20.0))
        time.sleep(0.05)
    viewer.update(plus._impl.uuid, value=True)
    note = wait_for(lambda: viewer.received("NotificationShowMessage"), what="a refusal")
    assert "Only the operator can jog — Olivia holds control" in note[0]["props"]["body"]
    wait_for(lambda: app.guard.counts["refused"] >= refused0 + 6, what="all six refused")
    time.sleep(0.3)  # (a second note would have been sent by now)
    assert len(viewer.received("NotificationShowMessage")) == 1  # coalesced
    assert app.store.command is before
    assert op.alive()
