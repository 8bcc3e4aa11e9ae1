"""client_of / target_of: who sent an event and which handle it is about, for every event kind a
refused callback passes on (and none at all)."""

from __future__ import annotations

import viser

from console.panels.common.events import client_of, target_of
from tests.fakes import FakeClient


def test_client_and_target_of_gui_gizmo_click_and_no_event(server) -> None:
    client = FakeClient(7)
    slider = server.gui.add_slider("s", 0.0, 1.0, 0.1, 0.5)
    gui = viser.GuiEvent(client=client, client_id=7, target=slider)  # type: ignore[arg-type]
    assert client_of(gui) is client and target_of(gui) is slider
    gizmo = server.scene.add_transform_controls("/g")
    drag = viser.TransformControlsEvent(client=None, client_id=None, target=gizmo, phase="end")
    assert client_of(drag) is None and target_of(drag) is gizmo
    click = viser.SceneClickEvent(client, 7, (0.0, 0.0, 1.0),  # type: ignore[arg-type]
                                  (0.0, 0.0, -1.0), (0.5, 0.5), None)
    assert client_of(click) is client and target_of(click) is None
    assert client_of(None) is None and target_of(None) is None
