"""Issue 31 item 4: viewers see the operator's controls disabled, and one line saying who operates.

Raw websocket clients (``tests/ws_client.py``) read what each browser is sent. The expected
state of a widget in a browser is replayed from its messages in order (its creation message's
``props.disabled``, then every ``GuiUpdateMessage`` naming ``disabled``), as the browser's
client applies them. Expectations: the operator sees the panel's own ``disabled`` (the server
handle's value); a viewer sees operator-only widgets disabled whatever it is, and widgets marked
``allow_viewers`` as they are. With ``console.web.viewer_props`` undone (upstream viser 1.1.1) the
viewer is sent Execute enabled.
"""

from __future__ import annotations

from typing import Any, Iterator

import pytest
import viser

from console.core.access import AccessControl
from console.panels.soft_arm.objects import ObjectsPanel
from console.web.client_guard import ClientGuard
from core.robots import load
from fakes import console_app, upstream_viser
from tests.ws_client import RawClient, wait_for


def shown_disabled(client: RawClient, uuid: str) -> bool | None:
    """Whether ``client``'s browser shows widget ``uuid`` disabled (None: never sent)."""
    state: bool | None = None
    with client._lock:
        messages = list(client.messages)
    for m in messages:
        if m.get("uuid") != uuid:
            continue
        props = m.get("props")
        if isinstance(props, dict) and "disabled" in props:
            state = bool(props["disabled"])
        updates = m.get("updates")
        if m.get("type") == "GuiUpdateMessage" and isinstance(updates, dict) \
                and "disabled" in updates:
            state = bool(updates["disabled"])
    return state


def settles(client: RawClient, uuid: str, expected: bool, what: str) -> None:
    wait_for(lambda: shown_disabled(client, uuid) is expected, 20.0, what)


@pytest.fixture
def guarded() -> Iterator[tuple[viser.ViserServer, ClientGuard, dict[str, int | None], Any,
                                Any]]:
    """A server with a guard, an operator-only Execute and a viewers' STOP: (server, guard,
    {"operator": client id}, Execute, STOP)."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    role: dict[str, int | None] = {"operator": None}
    try:
        guard = ClientGuard(server, is_operator=lambda cid: cid == role["operator"],
                            refuse=lambda c, r, a: None)
        execute = server.gui.add_button("Execute")
        stop = server.gui.add_button("STOP")
        guard.allow_viewers(stop)
        yield server, guard, role, execute, stop
    finally:
        server.stop()


def test_viewers_get_operator_only_buttons_disabled_and_the_operator_enabled(guarded) -> None:
    server, guard, role, execute, stop = guarded
    op = RawClient(server)
    role["operator"] = op.client_id  # op takes control (the app resends on a change of holder)
    guard.viewer_props.resend()
    viewer = RawClient(server)
    try:
        exe, stp = execute._impl.uuid, stop._impl.uuid
        settles(viewer, exe, True, "Execute disabled for the viewer")
        settles(op, exe, False, "Execute enabled for the operator")
        settles(viewer, stp, False, "STOP enabled for the viewer")
        assert execute.disabled is False  # the server's truth is untouched
    finally:
        op.close()
        viewer.close()


def test_a_role_change_flips_what_each_browser_is_shown(guarded) -> None:
    server, guard, role, execute, _ = guarded
    a, b = RawClient(server), RawClient(server)
    role["operator"] = a.client_id
    guard.viewer_props.resend()
    try:
        exe = execute._impl.uuid
        settles(a, exe, False, "a (operator) sees Execute enabled")
        settles(b, exe, True, "b (viewer) sees Execute disabled")
        role["operator"] = b.client_id  # b takes control
        guard.viewer_props.resend()
        settles(a, exe, True, "a, now a viewer, sees Execute disabled")
        settles(b, exe, False, "b, now the operator, sees Execute enabled")
        role["operator"] = None  # released
        guard.viewer_props.resend()
        settles(b, exe, True, "nobody operates: b sees Execute disabled")
    finally:
        a.close()
        b.close()


def test_a_panels_own_disable_reaches_the_operator_and_viewers_stay_disabled(guarded) -> None:
    server, guard, role, execute, _ = guarded
    op = RawClient(server)
    role["operator"] = op.client_id  # op takes control (the app resends on a change of holder)
    guard.viewer_props.resend()
    viewer = RawClient(server)
    try:
        exe = execute._impl.uuid
        settles(op, exe, False, "operator: Execute enabled")
        execute.disabled = True  # e.g. busy
        settles(op, exe, True, "operator: Execute disabled while busy")
        settles(viewer, exe, True, "viewer: disabled while busy")
        execute.disabled = False
        settles(op, exe, False, "operator: Execute enabled again")
        viewer.clear()
        server.flush()
        op.clear()
        execute.disabled = True
        execute.disabled = False
        settles(op, exe, False, "operator: enabled after a busy spell")
        wait_for(lambda: viewer.received("GuiUpdateMessage", lambda m: m["uuid"] == exe),
                 20.0, "the viewer got the update")
        assert shown_disabled(viewer, exe) is True
    finally:
        op.close()
        viewer.close()


def test_upstream_viser_sends_a_viewer_execute_enabled(guarded) -> None:
    """The probe above on viser 1.1.1 without the patch: the viewer gets the shared props."""
    server, guard, role, execute, _ = guarded
    role["operator"] = -1
    with upstream_viser("window_generator"):
        viewer = RawClient(server)
        try:
            settles(viewer, execute._impl.uuid, False, "upstream: Execute enabled for a viewer")
        finally:
            viewer.close()
    viewer = RawClient(server)
    try:
        settles(viewer, execute._impl.uuid, True, "patched: Execute disabled for a viewer")
    finally:
        viewer.close()


def test_the_console_shows_viewers_who_operates_and_disables_add_object() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(load("soft-arm"), server, panels=(ObjectsPanel,),
                      access=AccessControl(token="secret"))
    try:
        objects = app.panel(ObjectsPanel)
        add, save = objects.add_button._impl.uuid, objects.save_button._impl.uuid
        op, viewer = RawClient(server), RawClient(server)
        wait_for(lambda: viewer.client_id in app.viewer_line._lines, 20.0, "lines built")
        assert "nobody operates" in app.viewer_line.text(viewer.client_id)
        app.access.take(op.client_id, "secret", "Olivia")
        wait_for(lambda: "Olivia operates" in app.viewer_line.text(viewer.client_id), 20.0,
                 "the viewer's line names the operator")
        assert "Take control in the Session tab with the operator token" in \
            app.viewer_line.text(viewer.client_id)
        assert app.viewer_line.text(op.client_id) == ""  # the operator's line is hidden
        wait_for(lambda: any("Olivia operates" in str(m.get("props", {}).get("content", ""))
                             or "Olivia operates" in str(m.get("updates", {}).get("content", ""))
                             for m in viewer.messages), 20.0, "the viewer's browser got it")
        settles(viewer, add, True, "Add object disabled for the viewer")
        settles(op, add, False, "Add object enabled for the operator")
        settles(viewer, save, False, "Save scene (viewers may) enabled for the viewer")
        app.access.release(op.client_id)
        settles(op, add, True, "released: Add object disabled for the former operator")
        wait_for(lambda: "nobody operates" in app.viewer_line.text(op.client_id), 20.0,
                 "the former operator's line is shown")
        op.close()
        viewer.close()
    finally:
        app.stop()
        server.stop()


# -- the 3D view's drag gizmos ---------------------------------------------------------------

HANDLES = ("disable_axes", "disable_sliders", "disable_rotations")


def gizmo_draggable(client: RawClient, name: str) -> bool | None:
    """Whether ``client``'s browser draws gizmo ``name`` with any handle to drag, replayed from
    its creation message's props and every later props update, in order (None: never sent)."""
    state: dict[str, bool] | None = None
    with client._lock:
        messages = list(client.messages)
    for m in messages:
        if m.get("name") != name:
            continue
        props = m.get("props")
        if m.get("type") == "TransformControlsMessage" and isinstance(props, dict):
            state = {h: bool(props[h]) for h in HANDLES}
        updates = m.get("updates")
        if state is not None and m.get("type") == "SceneNodeUpdateMessage" \
                and isinstance(updates, dict):
            state.update({h: bool(updates[h]) for h in HANDLES if h in updates})
    return None if state is None else not all(state.values())


def draggable(client: RawClient, name: str, expected: bool, what: str) -> None:
    wait_for(lambda: gizmo_draggable(client, name) is expected, 20.0, what)


def test_viewers_get_the_gizmos_without_handles_and_a_holder_change_flips_them(guarded) -> None:
    server, guard, role, _, _ = guarded
    gizmo = server.scene.add_transform_controls("/objects/gizmo", disable_rotations=True,
                                                disable_sliders=True)
    a, b = RawClient(server), RawClient(server)
    role["operator"] = a.client_id
    guard.viewer_props.resend()
    try:
        draggable(a, "/objects/gizmo", True, "a (operator) can drag the gizmo")
        draggable(b, "/objects/gizmo", False, "b (viewer) has no handle to drag")
        gizmo.disable_axes = True   # the panel's own: nothing to drag for anyone
        draggable(a, "/objects/gizmo", False, "the operator: disabled by the panel")
        gizmo.disable_axes = False
        draggable(a, "/objects/gizmo", True, "the operator: enabled again")
        draggable(b, "/objects/gizmo", False, "the viewer: still nothing to drag")
        role["operator"] = b.client_id  # b takes control
        guard.viewer_props.resend()
        draggable(a, "/objects/gizmo", False, "a, now a viewer: nothing to drag")
        draggable(b, "/objects/gizmo", True, "b, now the operator, can drag")
        assert gizmo.disable_axes is False  # the server's truth is untouched
    finally:
        a.close()
        b.close()


def test_upstream_viser_sends_a_viewer_a_draggable_gizmo(guarded) -> None:
    server, _, role, _, _ = guarded
    server.scene.add_transform_controls("/bin/gizmo")
    role["operator"] = -1
    with upstream_viser("window_generator"):
        viewer = RawClient(server)
        try:
            draggable(viewer, "/bin/gizmo", True, "upstream: the viewer can drag the gizmo")
        finally:
            viewer.close()
    viewer = RawClient(server)
    try:
        draggable(viewer, "/bin/gizmo", False, "patched: nothing to drag for the viewer")
    finally:
        viewer.close()
