"""Control lock: token, takeover, lease expiry, the central operator_only gate, STOP hooks, and
the share tunnel staying off even for a client that asks for it on the wire."""

from __future__ import annotations

import time

import numpy as np
import pytest
import viser

from console.core.access import AccessControl, NotOperator
from fakes import upstream_viser
from console.app import ConsoleApp
from console.panels.common.base import Panel, operator_only
from console.panels.common.jog import JogPanel
from core.robots import load
from fakes import FakeClient, FakeClock

SOFT = load("soft-arm")




def test_only_the_right_token_gives_control_and_refusals_name_the_holder() -> None:
    changes = []
    access = AccessControl("s3cret")
    access.add_listener(lambda new, prev, why: changes.append((new, prev, why)))
    with pytest.raises(NotOperator, match="nobody holds control"):
        access.check(7, "jog")
    with pytest.raises(NotOperator, match="Wrong operator token"):
        access.take(7, "guess")
    assert access.holder is None and changes == []
    alice = access.take(7, "s3cret", name="Alice")
    assert access.is_operator(7) and not access.is_operator(8) and alice.name == "Alice"
    access.check(7, "jog")  # no exception
    access.check(None, "jog")  # the server itself
    with pytest.raises(NotOperator) as info:
        access.check(8, "execute a plan")
    assert info.value.reason.startswith("Only the operator can execute a plan — Alice holds "
                                        "control; ask them or take control with the token")
    bob = access.take(8, " s3cret ", name="Bob")  # a pasted token with spaces still works
    assert access.holder == bob and not access.is_operator(7)
    assert changes[-1][1] == alice and "took control from Alice" in changes[-1][2]
    assert not access.release(7)  # Alice no longer holds it
    assert access.release(8) and access.holder is None


def test_wrong_tokens_are_throttled_across_clients_of_one_address() -> None:
    # Issue 20: the limit was global (one wrong token every 2 s kept the operator out); it is
    # now per client and per address, so guessing from many tabs of one machine still waits.
    clock = FakeClock()
    access = AccessControl("tok", max_failures=3, address_failures=3, failure_window=10.0,
                           clock=clock)
    for cid in range(3):
        with pytest.raises(NotOperator, match="Wrong"):
            access.take(cid, "nope", address="10.0.0.5")
    with pytest.raises(NotOperator, match="Too many"):
        access.take(9, "tok", address="10.0.0.5")  # even the right token waits
    assert access.take(10, "tok", address="10.0.0.6").client_id == 10  # another desk does not
    clock.t += 10.5
    assert access.take(9, "tok", address="10.0.0.5").client_id == 9


def test_wrong_tokens_from_one_client_do_not_lock_out_another() -> None:
    clock = FakeClock()
    access = AccessControl("tok", max_failures=3, failure_window=10.0, clock=clock)
    for _ in range(3):
        with pytest.raises(NotOperator, match="Wrong"):
            access.take(1, "nope", address="127.0.0.1")
    with pytest.raises(NotOperator, match="Too many"):
        access.take(1, "tok", address="127.0.0.1")  # this client waits, even with the token
    for _ in range(5):  # one wrong token every 2 s, as in the issue
        clock.t += 2.0
        with pytest.raises(NotOperator):
            access.take(1, "nope", address="127.0.0.1")
    assert access.take(2, "tok", address="127.0.0.1").client_id == 2  # the operator gets in


def test_lease_expires_after_two_silent_seconds_and_heartbeats_renew_it() -> None:
    clock = FakeClock()
    access = AccessControl(None, lease_s=2.0, clock=clock)
    lost = []
    access.add_listener(lambda new, prev, why: lost.append(why) if new is None else None)
    access.take(3)
    for _ in range(10):  # answering every 0.5 s keeps it for 5 s
        clock.t += 0.5
        assert access.heartbeat(3)
        assert access.expire_if_silent() is None
    assert not access.heartbeat(4)  # not the holder: no effect
    clock.t += 1.99
    assert access.expire_if_silent() is None and access.is_operator(3)
    clock.t += 0.02
    assert access.expire_if_silent() is not None
    assert access.holder is None and "silent for 2 s" in lost[-1]


def test_a_new_lease_waits_longer_for_the_first_answer_of_a_loading_tab() -> None:
    """Until the holder's tab answers once it has first_answer_s (a page still loading), then
    the 2 s rule; a new holder starts the grace again."""
    clock = FakeClock()
    access = AccessControl(None, lease_s=2.0, first_answer_s=10.0, clock=clock,
                           first_client_takes_control=True)
    lost = []
    access.add_listener(lambda new, prev, why: lost.append(why) if new is None else None)
    access.grant_if_free(3)  # desk mode: granted on connect, while the page loads
    assert access.lease_limit() == 10.0
    clock.t += 9.9
    assert access.expire_if_silent() is None and access.is_operator(3)
    assert access.heartbeat(3) and access.lease_limit() == 2.0  # answered: the 2 s rule
    clock.t += 2.01
    assert access.expire_if_silent() is not None and "silent for 2 s" in lost[-1]
    access.take(4)  # a new holder that never answers loses control after 10 s
    clock.t += 10.01
    assert access.expire_if_silent() is not None and "did not answer within 10 s" in lost[-1]
    with pytest.raises(ValueError, match="first_answer_s"):
        AccessControl(None, lease_s=2.0, first_answer_s=1.0)


def test_desk_mode_gives_a_lapsed_lease_back_only_to_its_own_tab() -> None:
    clock = FakeClock()
    desk = AccessControl(None, lease_s=2.0, first_client_takes_control=True, clock=clock)
    lab = AccessControl(None, lease_s=2.0, clock=clock)
    for access in (desk, lab):
        access.take(5)
        access.heartbeat(5)
        clock.t += 2.5
        assert access.expire_if_silent() is not None and access.holder is None
    assert lab.lapsed is None and lab.regrant(5) is None  # never outside desk mode
    assert desk.lapsed == 5
    assert desk.regrant(6) is None and desk.holder is None  # another tab: no
    assert desk.regrant(5).client_id == 5 and desk.lapsed is None
    desk.release(5)  # a voluntary release is not a lapse
    assert desk.lapsed is None and desk.regrant(5) is None
    desk.take(5)
    desk.heartbeat(5)
    clock.t += 2.5
    desk.expire_if_silent()
    desk.forget(5)  # the tab closed: nothing to give back
    assert desk.lapsed is None


def test_desk_mode_grants_only_when_enabled_and_free() -> None:
    assert AccessControl(None).grant_if_free(1) is None
    desk = AccessControl("tok", first_client_takes_control=True)
    assert desk.grant_if_free(1).client_id == 1
    assert desk.grant_if_free(2) is None and desk.is_operator(1)


def test_last_heard_is_the_holders_latest_answer() -> None:
    t = {"now": 5.0}
    access = AccessControl(None, clock=lambda: t["now"])
    assert access.last_heard(1) is None
    access.take(1)
    assert access.last_heard(1) == 5.0 and access.last_heard(2) is None
    t["now"] = 7.5
    assert not access.heartbeat(2) and access.last_heard(1) == 5.0
    assert access.heartbeat(1) and access.last_heard(1) == 7.5
    access.release(1)
    assert access.last_heard(1) is None


def test_names_are_cleaned() -> None:
    access = AccessControl(None)
    assert access.set_name(5, "  <b>Eve</b>\n") == "bEveb"  # no markup, no line breaks
    assert access.name_of(5) == "bEveb"
    assert access.set_name(5, "x" * 100) == "x" * 32
    assert access.set_name(5, "   ") == "client 5"


def event(client: FakeClient | None, target: object) -> viser.GuiEvent:
    return viser.GuiEvent(client=client, client_id=None if client is None else client.client_id,
                          target=target)  # type: ignore[arg-type]


def test_jog_from_a_viewer_is_refused_with_the_reason_and_moves_nothing(server) -> None:
    clock = FakeClock()  # the lease and hold-to-run on a simulated clock: no sleeps
    app = ConsoleApp(SOFT, server, access=AccessControl("tok", clock=clock), clock=clock)
    jog = app.panel(JogPanel)
    coord = app.model.coordinates[1]
    slider = jog.sliders[coord.key]
    viewer, operator = FakeClient(11), FakeClient(12)
    app.access.take(operator.client_id, "tok", name="Alice")
    before = app.store.command
    slider.value = 6.0  # what viser does with the viewer's drag before calling back
    jog._on_slider(coord, event(viewer, slider))
    assert viewer.notes and viewer.notes[0][0] == "Not allowed"
    assert "Only the operator can jog — Alice holds control" in viewer.notes[0][1]
    assert app.store.command is before and app.hold.target() is None and not app.hold.active
    assert slider.value == 0.0  # snapped back for everyone
    # The same callback for the operator sets a target the jog thread moves to.
    slider.value = 6.0
    jog._on_slider(coord, event(operator, slider))
    assert operator.notes == []
    np.testing.assert_allclose(app.hold.target(), [0, 6.0, 0, 0, 0, 0])
    clock.t += 0.35  # no answer from the operator's tab for 300 ms: the move holds
    q = app.store.command.q.copy()
    assert app.hold.tick() is None and app.hold.active and np.array_equal(app.store.command.q, q)
    steps = 0
    while app.hold.active and steps < 500:  # at the 250 mm/s cap it takes about 0.45 s
        app.access.heartbeat(operator.client_id)  # the lease probe's answers keep it moving
        clock.t += 0.02
        app.hold.tick()
        steps += 1
    assert not app.hold.active and steps < 100, steps
    np.testing.assert_allclose(app.store.command.q, [0, 6.0, 0, 0, 0, 0], atol=1e-9)


class GatedPanel(Panel):
    title = "Gated"

    def build(self) -> None:
        self.calls: list[str] = []
        self.button = self.gui.add_button("Arm")
        self.button.on_click(operator_only(lambda e: self.calls.append("lambda"), panel=self,
                                           action="arm the robot"))

    @operator_only
    def _on_execute(self, event: viser.GuiEvent) -> None:
        self.calls.append("method")

    @operator_only(action="do it async")
    async def _on_async(self, event: viser.GuiEvent) -> None:
        self.calls.append("async")


def test_operator_only_gates_methods_lambdas_and_coroutines(server) -> None:
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    def run_async(coro) -> None:  # its own thread: Playwright may own this thread's loop
        with ThreadPoolExecutor(1) as pool:
            pool.submit(asyncio.run, coro).result()

    app = ConsoleApp(SOFT, server, panels=[GatedPanel], access=AccessControl(None))
    panel = app.panel(GatedPanel)
    viewer, operator = FakeClient(1), FakeClient(2)
    app.access.take(operator.client_id)
    wrapped_lambda = panel.button._impl.update_cb[0]
    for client in (viewer, operator):
        wrapped_lambda(event(client, panel.button))
        panel._on_execute(event(client, panel.button))
        run_async(panel._on_async(event(client, panel.button)))
    assert panel.calls == ["lambda", "method", "async"]  # the operator's only
    assert [body.split(" — ")[0] for _, body in viewer.notes] == [
        "Only the operator can arm the robot", "Only the operator can execute",
        "Only the operator can do it async"]
    panel._on_execute(event(None, panel.button))  # a server-side mirror passes through
    assert panel.calls[-1] == "method"
    assert app.refusals == 3


def test_stop_stops_the_arm_even_after_a_failing_step_and_lease_loss_stops(server) -> None:
    import concurrent.futures as cf

    from console.core.services import ConsoleServices

    class BrokenDemo:
        def stop(self, reason: str = "") -> None:
            raise RuntimeError("boom")

    class Loop:  # the soft arm's control process as the core uses it
        alive, failure, view = True, None, None

        def __init__(self) -> None:
            self.stops: list[str] = []

        def stop_arm(self, reason: str = "") -> cf.Future:
            self.stops.append(reason)
            fut: cf.Future = cf.Future()
            fut.set_result(None)
            return fut

    loop = Loop()
    app = ConsoleApp(SOFT, server, access=AccessControl(None),
                     services=ConsoleServices(soft_control=loop, demo=BrokenDemo()))  # type: ignore[arg-type]
    app.stop_motion("STOP pressed by Bob", FakeClient(3))
    assert loop.stops == ["STOP pressed by Bob"]  # the demo's failure did not keep it
    assert app.last_stop.who == "client 3" and app.stops == 1
    app.access.take(4, name="Alice")
    app.access.revoke("Alice's tab went silent for 2 s", 4)
    assert "silent" in loop.stops[-1] and app.access.holder is None
    app.access.take(5, name="Carol")
    app.access.take(6, name="Dan")  # takeover: the arm stops before Dan moves it
    assert "Carol" in loop.stops[-1] and "Dan" in loop.stops[-1] and len(loop.stops) == 3


def test_share_tunnel_request_from_the_wire_is_ignored(monkeypatch, server) -> None:
    import msgspec
    from websockets.sync.client import connect

    import viser._viser as vv

    created: list[object] = []

    class SpyTunnel:
        def __init__(self, *args: object) -> None:
            created.append(args)
            raise RuntimeError("no tunnels in tests")

    monkeypatch.setattr(vv, "ViserTunnel", SpyTunnel)
    request = msgspec.msgpack.encode({"type": "ShareUrlRequest"})

    def ask(srv: viser.ViserServer) -> None:
        with connect(f"ws://127.0.0.1:{srv.get_port()}",
                     subprotocols=[f"viser-v{viser.__version__}"]) as ws:  # type: ignore[list-item]
            ws.send(request)
            time.sleep(0.5)

    with upstream_viser("client guard"):  # upstream viser reads every browser's messages
        ask(server)  # a plain viser server opens the tunnel: the probe works
        deadline = time.monotonic() + 30  # generous: 2 busy cores
        while not created and time.monotonic() < deadline:
            time.sleep(0.05)
    assert created, "control: a plain viser server should have tried to open a tunnel"
    created.clear()
    guarded = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        ConsoleApp(SOFT, guarded)
        ask(guarded)
        time.sleep(0.5)
        assert created == [] and guarded._share_tunnel is None
        assert guarded.request_share_url() is None
    finally:
        guarded.stop()


def test_every_callback_of_the_shared_scene_panels_is_operator_only(server, monkeypatch) -> None:
    """Objects, Grasp planner, Waypoints and Hardware: every widget callback that changes what
    everyone sees or drives the hardware is gated (only "Save scene", a download, is not)."""
    from console.panels.soft_arm import panel_set, planner
    from console.panels.common.hardware import HardwarePanel

    monkeypatch.setattr(planner.GraspSession, "compute_reach", False)
    app = ConsoleApp(SOFT, server, panels=(*panel_set.grasp_panels(), HardwarePanel),
                     access=AccessControl("tok"))
    try:
        objects = app.panels[0]
        allowed = {id(objects.save_button)}
        checked = 0
        for panel in app.panels:
            for handle in vars(panel).values():
                callbacks = getattr(getattr(handle, "_impl", None), "update_cb", None)
                if not callbacks or id(handle) in allowed:
                    continue
                for cb in callbacks:
                    assert getattr(cb, "operator_only", None), (type(panel).__name__, handle)
                    checked += 1
        assert checked >= 25
        assert app.grasp_scene.gizmo_handler.operator_only == "move an object"
        assert objects._place_at.operator_only == "place or select an object"
    finally:
        app.panel(HardwarePanel).close()
        app.grasp_session.close()  # type: ignore[attr-defined]
