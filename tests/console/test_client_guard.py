"""Issues 14 and 20: every value a browser sends is checked before viser stores or broadcasts it.

A full console (as ``serve.py --lab --hardware mock`` builds it) for each robot, and raw
websocket clients speaking viser's protocol (``tests/ws_client.py``): an operator who took
control with the token (and answers the lease probes like a tab), a viewer who sends what a
hostile client can, and a watcher who must keep receiving and see nothing of it. The expected
values are the widgets' own state before the attack: nothing may change.
"""

from __future__ import annotations

import dataclasses
import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Iterator

import numpy as np
import pytest
from viser import _messages

from console.panels.soft_arm.control import ControlPanel
from console.panels.common.hardware import HardwarePanel
from console.panels.common.session import SessionPanel
from fakes import FakeClient
from tests.ws_client import RawClient
from tests.ws_client import wait_for as _wait_for

PACE = 1.0 / 80  # below the guard's 100 messages/s per client: every message is judged
BULK_RATE = 1000.0  # messages/s the bulk attack test lifts the limit to
BULK_PACE = 1.0 / 400  # and its pace, below it
VIEWER_ALLOWED = {"STOP  (Esc)", "Save scene", "Save boxes", "Export scene (HTML)",
                  # the View panel: each browser's own camera; a measurement moves nothing
                  "Perspective", "Top-down", "Front", "Side", "Reset view", "Measure distance",
                  "Clear measurement",
                  # the Design study panel: reading a study and drawing a variant move nothing
                  "Study", "Refresh list", "Or folder", "Open folder", "Metric", "Over key",
                  "Variant", "Show variant", "Hide variant"}


@pytest.fixture(scope="module", params=["soft-arm", "extensible"])
def console(request: Any, serve_module: Any, tmp_path_factory: Any) -> Iterator[tuple]:
    from core.robots import load

    data = tmp_path_factory.mktemp("runs")
    args = serve_module.parse_args(["--robot", request.param, "--hardware", "mock", "--port",
                                    "0", "--lab", "--rt-cpu", "none", "--data-dir", str(data)])
    server, app, token = serve_module.build(args, load(request.param), "guard test")
    app.start()
    try:
        yield server, app, token
    finally:
        app.stop_motion("test over")
        app.services.close()
        app.stop()
        server.stop()


@pytest.fixture
def trio(console: tuple) -> Iterator[tuple[RawClient, RawClient, RawClient]]:
    """(operator holding control, viewer, watcher) connected to ``console``."""
    server, app, token = console
    op, viewer, watcher = RawClient(server), RawClient(server), RawClient(server)
    session = app.panel(SessionPanel)
    wait_for(lambda: {c.client_id for c in (op, viewer, watcher)} <= set(session.clients),
             what="per-browser widgets built")
    app.access.take(op.client_id, token, "Olivia")
    try:
        yield op, viewer, watcher
    finally:
        for c in (op, viewer, watcher):
            c.close()
        wait_for(lambda: app.access.holder is None, what="control released on close")


def wait_for(predicate: Any, timeout: float = 60.0, what: str = "condition") -> Any:
    """``tests.ws_client.wait_for`` with a deadline generous enough for two busy cores (these
    tests run beside others): each wait is for something that takes well under a second."""
    return _wait_for(predicate, timeout, what)


def _inputs(server: Any) -> dict[str, Any]:
    return dict(server.gui._gui_input_handle_from_uuid)


def _own_inputs(server: Any, client: RawClient) -> dict[str, Any]:
    return dict(server.get_clients()[client.client_id].gui._gui_input_handle_from_uuid)


def _snapshot(handle: Any) -> tuple:
    impl = handle._impl
    p = impl.props
    value = impl.value
    if type(handle).__name__ == "GuiUploadButtonHandle":
        value = (value.name, value.content)
    return (repr(value), impl.removed, getattr(p, "disabled", None), getattr(p, "visible", None),
            getattr(p, "label", None), len(impl.update_cb), impl.is_button)


def _started(app: Any) -> None:
    """Wait for the console's one-time start-up changes: the loop process's first view (the
    soft arm's Disarm follows it), its link configured and the port it uses filled in."""
    loop = app.services.soft_control or app.services.extensible_runner
    if loop is not None:
        wait_for(lambda: loop.view is not None and loop.view_age() < 0.5,
                 what="the loop process's first fresh view")
    hardware = app.panel(HardwarePanel)
    ctl = hardware.controls()
    if ctl is not None:
        wait_for(lambda: ctl.health() is not None and ctl.health().state != "unconfigured"
                 and str(hardware.port_text.value).strip() != "",
                 what="the hardware link configured and its port shown")


def _settled(app: Any, handles: dict[str, Any], timeout: float = 60.0) -> dict[str, tuple]:
    """The widgets' state once the console has finished starting (:func:`_started`; then the
    planner enables the waypoint slider ...): unchanged for two seconds."""
    _started(app)
    deadline = time.monotonic() + timeout
    snap = {u: _snapshot(h) for u, h in handles.items()}
    while time.monotonic() < deadline:
        time.sleep(2.0)
        again = {u: _snapshot(h) for u, h in handles.items()}
        if again == snap:
            return snap
        snap = again
    raise AssertionError("the console's widgets never settled")


def _unchanged(before: dict[str, tuple], handles: dict[str, Any],
               timeout: float = 30.0) -> dict[str, tuple]:
    """What still differs from ``before`` after up to ``timeout``: the console itself disables
    buttons while its loop's view is stale (a loaded box) and enables them again; what an attack
    stored would stay."""
    deadline = time.monotonic() + timeout
    while True:
        changed = _changed(before, {u: _snapshot(h) for u, h in handles.items()})
        if not changed or time.monotonic() > deadline:
            return changed
        time.sleep(0.5)


def _hostile(updates: dict[str, Any]) -> bool:
    """Whether a broadcast update carries what only the attack sent (the console itself changes
    ``max``, ``disabled`` or a value now and then, never to these)."""
    if set(updates) & {"removed", "update_cb", "props", "is_button", "label"}:
        return True
    value = updates.get("value")
    flat = value if isinstance(value, (list, tuple)) else [value]
    return any((isinstance(v, float) and (not math.isfinite(v) or abs(v) > 1e12))
               or (isinstance(v, str) and len(v) > 256) or isinstance(v, dict) or v is None
               for v in flat) if "value" in updates else False


def _changed(before: dict[str, tuple], after: dict[str, tuple]) -> dict[str, tuple]:
    """Widgets whose state differs, except one the console itself enabled meanwhile (e.g. the
    waypoint slider once the first plan is in): `disabled` going True -> False is the server's
    doing, never an attack's."""
    def same_but_enabled(b: tuple, a: tuple) -> bool:
        return b[2] and not a[2] and b[:2] + b[3:] == a[:2] + a[3:]
    return {u: (before[u], after[u]) for u in before
            if before[u] != after[u] and not same_but_enabled(before[u], after[u])}


def _kind(handle: Any) -> str:
    return type(handle).__name__.removeprefix("Gui").removesuffix("Handle")


def _bad_values(handle: Any) -> list[Any]:
    """Values the widget must refuse, from its own type and bounds."""
    kind, impl = _kind(handle), handle._impl
    bad: list[Any] = [1e308, -1e308, math.nan, math.inf, -math.inf, None, {"a": 1}, [1e308]]
    if kind != "Text":
        bad += ["str", "x" * 5000]
    else:
        bad += ["x" * 5000, 7]
    if kind in ("Number", "Slider"):
        p = impl.props
        if p.max is not None:
            bad.append(p.max + 1)
        if p.min is not None:
            bad.append(p.min - 1)
        if isinstance(impl.value, int):
            bad.append(impl.value + 0.5)
        bad.append(True)
    if kind == "Checkbox":
        bad += [1, "true"]
    if kind in ("Dropdown", "ButtonGroup"):
        bad.append("not one of the options")
    if kind in ("Vector2", "Vector3", "MultiSlider"):
        bad += [[math.nan] * len(impl.value), [0.0] * (len(impl.value) + 1)]
    return bad


def _other_valid(handle: Any) -> Any:
    """A value the widget accepts that differs from its current one (None: there is none)."""
    kind, impl = _kind(handle), handle._impl
    p, v = impl.props, impl.value
    if impl.is_button:
        return True
    if kind in ("Number", "Slider"):
        for cand in (p.max, p.min, v + (p.step or 1)):
            if cand is not None and cand != v and (p.max is None or cand <= p.max) and (
                    p.min is None or cand >= p.min):
                return int(cand) if isinstance(v, int) else float(cand)
        return None
    if kind == "Checkbox":
        return not v
    if kind == "Text":
        return v + "x"
    if kind in ("Dropdown", "ButtonGroup"):
        others = [o for o in p.options if o != v]
        return others[0] if others else None
    if kind in ("Vector2", "Vector3"):
        lo = p.min if p.min is not None else tuple(c - 1.0 for c in v)
        return tuple(float(c) for c in lo) if tuple(lo) != tuple(v) else None
    return None


def _judged(app: Any, *clients: RawClient) -> None:
    """Wait until the guard has judged everything each client sent: a client's messages are
    judged and stored in order, so once a marker sent last to its own token field (a widget
    without a callback) is stored, all before it were judged. The field is put back."""
    session = app.panel(SessionPanel)
    for client in clients:
        field = session.clients[client.client_id].token
        assert field is not None, "a lab console has a token field"
        old = field.value
        for value in (f"marker-{client.client_id}", old):
            assert client.update(field._impl.uuid, value=value)
            wait_for(lambda: field.value == value, what="the client's messages judged")


def _paced(client: RawClient, sends: list[tuple[str, dict[str, Any]]],
           pace: float = PACE) -> None:
    """Send each (uuid, updates) at ``pace``, below the guard's rate limit for one client."""
    for uuid, updates in sends:
        assert client.update(uuid, **updates)
        time.sleep(pace)


def test_non_value_keys_and_bad_values_are_refused_for_every_widget(console: tuple,
                                                                    trio: tuple) -> None:
    """Issue 20.1 (``removed`` on STOP) and 14 (1e308, NaN, inf, strings): for every input of
    the full console and every per-browser input, nothing is stored, nobody is disconnected, the
    arm does not move, and STOP still works afterwards."""
    server, app, token = console
    op, viewer, watcher = trio
    shared, own = _inputs(server), _own_inputs(server, viewer)
    op_own = _own_inputs(server, op)
    everything = {**shared, **own, **op_own}
    assert len(shared) >= 20 and len(own) >= 5
    before = _settled(app, everything)
    q0, seq0 = np.array(app.store.command.q), app.store.command.seq
    stops0 = app.stops
    watcher.clear()
    attacks = [{"removed": True}, {"value": True, "removed": True}, {"update_cb": []},
               {"disabled": True}, {"visible": False}, {"label": "pwned"}, {"props": None},
               {"is_button": False}, {}]
    # The viewer names other attributes, sends bad values to the shared inputs (1e308, -1e308,
    # NaN, inf, -inf) and to its own; meanwhile the operator sends bad values to every input it
    # may use. The two send at once, each at PACE (the guard limits each client's rate).
    viewer_sends = [(uuid, updates) for uuid in [*shared, *own] for updates in attacks]
    viewer_sends += [(uuid, {"value": value}) for uuid, handle in shared.items()
                     for value in _bad_values(handle)[:5]]
    viewer_sends += [(uuid, {"value": value}) for uuid, handle in own.items()
                     for value in _bad_values(handle)]
    op_sends = [(uuid, {"value": value}) for uuid, handle in [*shared.items(), *op_own.items()]
                for value in _bad_values(handle)]
    # Every message is to be judged: the rate limit and the flood disconnect (their own tests:
    # test_client_guard_flood.py) are lifted for this bulk.
    limits = app.guard.limits
    app.guard.limits = dataclasses.replace(limits, rate=BULK_RATE, burst=BULK_RATE,
                                           flood_drops=10**6)
    try:
        with ThreadPoolExecutor(1) as pool:
            viewer_done = pool.submit(_paced, viewer, viewer_sends, BULK_PACE)
            _paced(op, op_sends, BULK_PACE)
            viewer_done.result()
        _judged(app, viewer, op)  # all of it under the lifted limits (a busy box lags behind)
    finally:
        app.guard.limits = limits
    assert app.guard.counts["rate"] == 0
    # Settled again: on a loaded machine the loop's view can go stale meanwhile, and the Control
    # panel then rightly disables Arm / Disarm / Execute until it is fresh (a loaded run caught
    # Disarm so); what an attack left would stay.
    changed = _unchanged(before, everything)
    assert changed == {}, "\n".join(f"{b} -> {a}" for b, a in changed.values())
    assert op.alive() and viewer.alive() and watcher.alive()
    assert app.access.holder is not None and app.access.holder.client_id == op.client_id
    assert np.array_equal(app.store.command.q, q0) and app.store.command.seq == seq0
    assert app.stops == stops0  # no button ran: STOP takes `true` only
    broadcast = watcher.received("GuiUpdateMessage",
                                 lambda m: m["uuid"] in everything and _hostile(m["updates"]))
    assert broadcast == []
    assert app.guard.counts["invalid"] >= len(shared) * len(attacks)
    # A browser arriving now gets the console (upstream: closed with 1011 on every reconnect).
    late = RawClient(server)
    wait_for(lambda: late.frames > 0, what="the late browser receiving the console")
    assert late.alive()
    late.close()
    # STOP still works, from the viewer.
    stop = next(h for h in shared.values() if getattr(h._impl.props, "label", None) == "STOP  (Esc)")
    viewer.update(stop._impl.uuid, value=True)
    wait_for(lambda: app.stops == stops0 + 1, what="STOP ran")


def test_viewer_edits_of_shared_inputs_are_refused_before_they_are_stored(console: tuple,
                                                                          trio: tuple) -> None:
    """Issue 20.2: every shared input is the operator's unless marked (STOP, Save scene,
    exports); a viewer's valid edit is refused before it is stored, only the viewer gets its
    old value back, with a notification; the operator's same edit is accepted."""
    server, app, token = console
    op, viewer, watcher = trio
    shared = _inputs(server)
    allowed = {getattr(h._impl.props, "label", None) for h in shared.values()
               if app.guard.viewer_allowed(h)}
    assert allowed <= VIEWER_ALLOWED and "STOP  (Esc)" in allowed
    # (a hidden input, e.g. Restart control loop while the loop runs, cannot be used by
    # anyone: the guard drops it as inactive, not as a viewer's refused edit. Restart is
    # shown while the loop's view is stale, which a loaded machine makes it for a moment:
    # left out, or it was shown here and hidden again before its edit; fresh64)
    restart = app.panel(HardwarePanel).restart_btn
    targets = {u: h for u, h in shared.items()
               if not app.guard.viewer_allowed(h) and _other_valid(h) is not None
               and not getattr(h._impl.props, "disabled", False)
               and getattr(h._impl.props, "visible", True) and h is not restart}
    assert len(targets) >= 15
    _settled(app, shared)
    targets = {u: h for u, h in targets.items() if not getattr(h._impl.props, "disabled", 0)}
    before = _settled(app, shared)
    q0, seq0 = np.array(app.store.command.q), app.store.command.seq
    refused0 = app.guard.counts["refused"]
    watcher.clear()
    viewer.clear()
    for uuid, handle in targets.items():
        viewer.update(uuid, value=_other_valid(handle))
        time.sleep(PACE)
    wait_for(lambda: app.guard.counts["refused"] == refused0 + len(targets),
             what="every edit refused")

    def restored() -> set[str]:
        return {m["uuid"] for m in viewer.received(
            "GuiUpdateMessage", lambda m: m["uuid"] in targets and "value" in m["updates"])}

    inputs = {u for u, h in targets.items() if not h._impl.is_button}
    # (the viewer's copy of its old values and the notes arrive after the refusals are counted)
    wait_for(lambda: restored() >= inputs, what="every refused input given back to the viewer")
    notes = wait_for(lambda: viewer.received("NotificationShowMessage"), what="a refusal note")
    assert _unchanged(before, shared) == {}
    assert np.array_equal(app.store.command.q, q0) and app.store.command.seq == seq0
    # (value updates: a panel may disable or enable a button meanwhile, e.g. while the loop
    # is slow to answer, and viewers are sent operator-only buttons disabled, issue 31.4)
    assert watcher.received("GuiUpdateMessage", lambda m: m["uuid"] in targets
                            and "value" in m["updates"]) == []
    assert restored() == inputs
    notes = viewer.received("NotificationShowMessage")
    assert notes and all("operator" in m["props"]["body"] for m in notes)
    assert len(notes) <= len(targets)
    assert watcher.received("NotificationShowMessage") == []
    # The operator's edit of the same kind of field is stored and shown to everyone.
    field = next(h for h in targets.values() if _kind(h) == "Checkbox")
    old = field.value
    op.update(field._impl.uuid, value=not old)
    wait_for(lambda: field.value == (not old), what="operator's edit stored")
    wait_for(lambda: watcher.received("GuiUpdateMessage",
                                      lambda m: m["uuid"] == field._impl.uuid),
             what="operator's edit broadcast")
    op.update(field._impl.uuid, value=old)
    wait_for(lambda: field.value == old)


def test_a_viewer_cannot_tick_click_to_grasp(console: tuple, trio: tuple) -> None:
    """Issue 20.2 as reported: a viewer ticked 'Click to grasp' and the operator's next table
    click ran a grasp."""
    server, app, _ = console
    if app.robot.kind != "planar":
        pytest.skip("the Control panel is the soft arm's")
    op, viewer, watcher = trio
    box = app.panel(ControlPanel).execute.click_mode
    # (value updates only: viewers are also sent the box disabled, issue 31.4)
    def values(client: RawClient) -> list[dict[str, Any]]:
        return client.received("GuiUpdateMessage", lambda m: m["uuid"] == box._impl.uuid
                               and "value" in m["updates"])

    viewer.update(box._impl.uuid, value=True)
    wait_for(lambda: values(viewer), what="the viewer's box unticked again")
    assert box.value is False
    assert values(viewer)[-1]["updates"] == {"value": False}
    assert values(watcher) == []


def test_a_radius_of_1e308_never_reaches_the_arm(console: tuple, trio: tuple) -> None:
    """Issue 20.8: the object's radius has bounds; 1e308 is refused by the guard (for the
    operator too) and, should a bad radius get into the objects some other way, by the Control
    panel before it sends. (Issue 18: the radius is the Objects panel's, in mm; the Control
    panel has no object fields of its own.)"""
    import dataclasses

    from console.panels.soft_arm.objects import ObjectsPanel

    server, app, _ = console
    if app.robot.kind != "planar":
        pytest.skip("the Control panel is the soft arm's")
    op, viewer, watcher = trio
    objects, panel, session = app.panel(ObjectsPanel), app.panel(ControlPanel), app.grasp_session
    r0 = objects.r.value
    op.update(objects.r._impl.uuid, value=1e308)
    wait_for(lambda: op.received("GuiUpdateMessage",
                                 lambda m: m["uuid"] == objects.r._impl.uuid))
    assert objects.r.value == r0
    sent: list[tuple] = []
    real = panel.ctl.grasp_at, panel.ctl.execute
    panel.ctl.grasp_at = lambda *a, **k: sent.append(a)  # type: ignore[method-assign]
    panel.ctl.execute = lambda *a, **k: sent.append(a)  # type: ignore[method-assign]
    panel.is_disarmed = lambda: False  # type: ignore[method-assign]  # as if armed
    client = FakeClient(op.client_id)
    event = type("E", (), {"client": client, "client_id": op.client_id})()
    first = session.view().objects[0]
    try:
        for r in (1e308, math.nan, 0.5):
            with session._cond:  # past the session's own checks, as a bug might
                session._objects[0] = dataclasses.replace(first, r=r)
                session._selected = first.name
            panel.execute._execute(event)
        assert sent == []
        assert len(client.notes) == 3 and all(t == "Refused" for t, _ in client.notes)
        assert "radius" in client.notes[0][1] or "finite" in client.notes[0][1]
    finally:
        panel.ctl.grasp_at, panel.ctl.execute = real  # type: ignore[method-assign]
        del panel.is_disarmed
        with session._cond:
            session._objects[0] = first


def test_uploads_and_gizmos_are_the_operators(console: tuple, trio: tuple) -> None:
    """A viewer cannot upload a scene (Load scene) nor drag a shared transform control; parts of
    an upload it did not start are dropped."""
    server, app, _ = console
    op, viewer, watcher = trio
    uploads = [h for h in _inputs(server).values() if _kind(h) == "UploadButton"]
    states = server.gui._current_file_upload_states
    refused0 = app.guard.counts["refused"]
    for h in uploads:
        viewer.send(_messages.FileTransferStartUpload(h._impl.uuid, "t-1", "s.json",
                                                      "application/json", 1, 10))
        viewer.send(_messages.FileTransferPart(h._impl.uuid, "t-1", 0, b"{}"))
    gizmos = dict(server.scene._handle_from_transform_controls_name)
    assert gizmos and len(uploads) == 1  # Load scene (soft arm), Load boxes (extensible arm)
    poses = {n: (tuple(g.position), tuple(g.wxyz)) for n, g in gizmos.items()}
    for name in gizmos:
        viewer.send(_messages.TransformControlsUpdateMessage(name, (1.0, 0.0, 0.0, 0.0),
                                                             (0.3, 0.3, 0.0)))
    wait_for(lambda: app.guard.counts["refused"] >= refused0 + len(uploads) + len(gizmos),
             what="the viewer's uploads and gizmo drags refused")
    time.sleep(0.5)  # (anything that did get through would have been stored by now)
    assert "t-1" not in states
    assert {n: (tuple(g.position), tuple(g.wxyz)) for n, g in gizmos.items()} == poses
    assert viewer.alive()
