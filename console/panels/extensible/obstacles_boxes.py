"""Obstacles panel of the extensible arm: box obstacles (shelves, drawer walls) the arm keeps clear of.

The operator places axis-aligned boxes -- typed centre x, y, z and size in mm, or a click on the
table that drops a box of the typed size there (standing on the table) -- selects, updates and
removes them, sets the clearance the arm's surface keeps from every box, and saves / loads
them as a scene file (:mod:`core.planning.box_scene`). The boxes are drawn semi-transparent in
the 3D view (the selected one stronger). The tip target (``console.panels.extensible.target``) and the
paths (``console.panels.extensible.paths``) read them through :func:`box_scene_of`: the IK and the path
planner keep the arm's body (the robot file's ``body_radius`` around the backbone: racks and
platforms) the clearance away from every box, and refuse with the reason when they cannot. Every change is recorded (record kind ``boxes``, channel
``/console/boxes``; the whole scene again when a recording starts).

Bad input (NaN, a size <= 0, a box that contains the arm's base or leaves the body there less
than the clearance, a name in use, a bad file) is refused with a message and changes nothing.

Sharing: the boxes drive every plan, so every change -- add, update, remove, select, the
clearance, a table click, the click toggle, loading a file -- is
:func:`~console.panels.common.base.operator_only` (like the target and path panels); a viewer's edit
snaps back. "Save scene" (a download) works for everyone.
"""

from __future__ import annotations

import html
import threading
from typing import Any

import numpy as np
import viser

from console.panels.common.base import Panel, operator_only
from console.panels.extensible.status import extensible_arm
from console.scene.plan_view import ray_to_table
from console.panels.common.events import target_of
from core.kinematics import box_clearance as bc
from core.planning.box_scene import (
    BoxScene,
    scene_from_json,
    scene_to_dict,
    scene_to_json,
)
from core.units import fmt_mm, mm_value

BOX_COLOR = (225, 150, 40)       # amber: not the arm's blue, the target's orange or paths' violet
BOX_SEL_COLOR = (230, 80, 30)
BOX_OPACITY, BOX_SEL_OPACITY = 0.35, 0.55
NONE = "(none)"
DEFAULT_SIZE_MM = (200.0, 300.0, 20.0)   # a shelf board
DEFAULT_CENTRE_MM = (200.0, 0.0, 250.0)


def box_scene_of(app: Any) -> tuple[BoxScene, int]:
    """The console's box scene and its version (bumped by every change); an empty scene when
    the console has no obstacles panel."""
    for panel in app.panels:
        if isinstance(panel, BoxObstaclesPanel):
            return panel.current()
    return BoxScene(), 0


class BoxObstaclesPanel(Panel):
    """Box obstacles: add / select / update / remove, clearance, table clicks, save and load."""

    title = "Obstacles (boxes)"
    order = 8.0  # editing: below the task's panels and View, folded
    expand_by_default = False
    kinds = ("delta",)

    def build(self) -> None:
        gui = self.gui
        self._lock = threading.Lock()
        self._scene = BoxScene(body_radius=self.app.robot.body_radius)
        self._version = 0
        self._selected: str | None = None
        self.selected = gui.add_dropdown("Box", [NONE], initial_value=NONE,
                                         hint="The box the fields show; Update / Remove act on it.")
        self.name = gui.add_text("Box name", "Shelf", hint="Name of a new (or the selected) box.")
        self.centre = [gui.add_number(f"Centre {a} (mm)", v, step=1.0)
                       for a, v in zip("xyz", DEFAULT_CENTRE_MM)]
        self.size = [gui.add_number(f"Size {a} (mm)", v, min=0.0, step=1.0,
                                    hint="Full edge length, > 0.")
                     for a, v in zip("xyz", DEFAULT_SIZE_MM)]
        self.add_button = gui.add_button("Add box", hint="A new box at the typed centre and size.")
        self.update_button = gui.add_button("Update selected",
                                            hint="Give the selected box the typed name, centre, size.")
        self.remove_button = gui.add_button("Remove box", color="red")
        self.clearance = gui.add_number(
            "Clearance (mm)", mm_value(self._scene.clearance), min=0.0, max=1000.0, step=1.0,
            hint="The arm's surface (racks and platforms: the robot file's body radius around "
                 "the backbone) keeps this far from every box.")
        self.click_place = gui.add_checkbox(
            "Click on table drops a box", False,
            hint="A click on the table places a box of the typed size standing there.")
        self.save_button = gui.add_button("Save boxes", hint="Download the boxes as JSON.")
        self.load_button = gui.add_upload_button("Load boxes", mime_type="application/json",
                                                 hint="Upload a box scene JSON file.")
        self.info = gui.add_html(self._info_html())
        self._handles: list[viser.BoxHandle] = []
        self._click_mode = False
        self._fields = {id(h): h.value for h in (*self.centre, *self.size, self.name,
                                                self.clearance)}
        self._recording: object = None
        self.selected.on_update(self._on_select)
        self.add_button.on_click(self._on_add)
        self.update_button.on_click(self._on_update)
        self.remove_button.on_click(self._on_remove)
        self.clearance.on_update(self._on_clearance)
        self.click_place.on_update(self._on_click_mode)
        for handle in (*self.centre, *self.size, self.name):
            handle.on_update(self._on_field)
        self.save_button.on_click(self._on_save)
        self.allow_viewers(self.save_button)
        self.load_button.on_upload(self._on_load)
        self.app.server.scene.on_click()(self._on_scene_click)
        self._log()  # the recorder keeps the newest (Recorder.latched): recordings start with it

    # -- the shared scene ------------------------------------------------------------------
    def current(self) -> tuple[BoxScene, int]:
        """The scene and its version (any thread)."""
        with self._lock:
            return self._scene, self._version

    def set_scene(self, scene: BoxScene, selected: str | None, client: Any = None,
                  what: str = "changed the boxes") -> None:
        """Replace the scene (already checked), redraw, record."""
        with self._lock:
            self._scene = scene
            self._version += 1
            self._selected = selected if selected in scene.names() else None
        self.app.recorder.action(what, client)
        self._log()
        self.refresh()

    def _log(self) -> None:
        scene, version = self.current()
        self.app.recorder.log("boxes", {**scene_to_dict(scene), "selected": self._selected,
                                        "version": version})

    # -- callbacks (thin) ------------------------------------------------------------------
    def _error(self, event: Any, message: str) -> None:
        self._say(f"⚠ {message}", "error")
        if event is not None and event.client is not None:
            event.client.add_notification("Obstacles", message, color="red",
                                          auto_close_seconds=6)

    def _typed_box(self, name: str | None = None) -> bc.Box:
        centre = [float(h.value) / 1e3 for h in self.centre]
        size = [float(h.value) / 1e3 for h in self.size]
        return bc.make_box(name if name is not None else str(self.name.value), centre, size)

    @operator_only(action="add a box")
    def _on_add(self, event: viser.GuiEvent) -> None:
        scene, _ = self.current()
        name = str(self.name.value).strip() or scene.free_name()
        if name in scene.names():
            name = scene.free_name(name)
        try:
            box = self._typed_box(name)
            self.set_scene(scene.with_box(box), box.name, event.client, f"added box '{box.name}'")
        except ValueError as exc:
            self._error(event, f"Box not added: {exc}")

    @operator_only(action="change a box")
    def _on_update(self, event: viser.GuiEvent) -> None:
        scene, _ = self.current()
        if self._selected is None:
            self._error(event, "No box selected.")
            return
        try:
            box = self._typed_box()
            self.set_scene(scene.replaced(self._selected, box), box.name, event.client,
                           f"changed box '{box.name}'")
        except ValueError as exc:
            self._error(event, f"Box not changed: {exc}")

    @operator_only(action="remove a box")
    def _on_remove(self, event: viser.GuiEvent) -> None:
        scene, _ = self.current()
        if self._selected is None:
            self._error(event, "No box selected.")
            return
        name = self._selected
        self.set_scene(scene.without(name), None, event.client, f"removed box '{name}'")

    @operator_only(action="select a box")
    def _on_select(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        value = str(self.selected.value)
        with self._lock:
            self._selected = None if value == NONE else value
        self.refresh()

    @operator_only(action="change the clearance")
    def _on_clearance(self, event: viser.GuiEvent) -> None:
        self._fields[id(self.clearance)] = self.clearance.value
        if event.client is None:
            return
        scene, _ = self.current()
        try:
            new = scene.with_clearance(float(self.clearance.value) / 1e3)
        except ValueError as exc:
            self.clearance.value = mm_value(scene.clearance)
            self._error(event, f"Clearance not changed: {exc}")
            return
        self.set_scene(new, self._selected, event.client,
                       f"set the box clearance to {fmt_mm(new.clearance, 1)} mm")

    @operator_only(action="change how clicks on the table act")
    def _on_click_mode(self, event: viser.GuiEvent) -> None:
        self._click_mode = bool(self.click_place.value)

    @operator_only(action="edit a box")
    def _on_field(self, event: viser.GuiEvent) -> None:
        self._fields[id(event.target)] = event.target.value  # accepted (or our own mirror)

    def _on_scene_click(self, event: viser.SceneClickEvent) -> None:
        if not self.click_place.value:
            return
        hit = ray_to_table(event.ray_origin, event.ray_direction)
        if hit is not None:
            self._drop_at(event, hit)

    @operator_only(action="place a box")
    def _drop_at(self, event: Any, hit: tuple[float, float]) -> None:
        scene, _ = self.current()
        size = [float(h.value) / 1e3 for h in self.size]
        centre = (hit[0], hit[1], 0.5 * size[2])  # standing on the table
        name = scene.free_name(str(self.name.value).strip() or "Box")
        try:
            box = bc.make_box(name, centre, size)
            self.set_scene(scene.with_box(box), box.name, event.client, f"placed box '{name}'")
        except ValueError as exc:
            self._error(event, f"Box not placed: {exc}")

    def on_refused(self, event: Any) -> None:
        """Undo what a refused viewer's edit shows everyone."""
        target = target_of(event)
        if target is self.click_place:
            self.click_place.value = self._click_mode
        elif target is self.selected:
            self.selected.value = self._selected or NONE
        elif target is not None and id(target) in self._fields:
            target.value = self._fields[id(target)]

    def _on_save(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            scene, _ = self.current()
            event.client.send_file_download("box_scene.json", scene_to_json(scene).encode())

    @operator_only(action="load a box scene")
    def _on_load(self, event: viser.GuiEvent) -> None:
        upload = self.load_button.value
        try:
            scene = scene_from_json(upload.content.decode("utf-8"), self.app.robot.body_radius)
        except (ValueError, UnicodeDecodeError) as exc:
            self._error(event, f"Could not load {upload.name}: {exc}")
            return
        self.set_scene(scene, scene.names()[0] if scene.boxes else None, event.client,
                       f"loaded the boxes of {upload.name}")

    # -- display ---------------------------------------------------------------------------
    def refresh(self) -> None:
        """Widgets, 3D boxes and the info line from the scene (any thread)."""
        scene, _ = self.current()
        selected = self._selected
        names = scene.names() or [NONE]
        if tuple(self.selected.options) != tuple(names):
            self.selected.options = names
        if self.selected.value != (selected or NONE):
            self.selected.value = selected or NONE
        if selected is not None:
            box = scene.get(selected)
            self.name.value = box.name
            for handle, v in zip((*self.centre, *self.size), (*box.centre, *box.size)):
                self._fields[id(handle)] = mm_value(v)  # (not handle.value: a browser's
                handle.value = mm_value(v)              # value may wait there for its callback)
            self._fields[id(self.name)] = box.name
        if abs(float(self.clearance.value) - mm_value(scene.clearance)) > 0.05:
            self.clearance.value = mm_value(scene.clearance)
        self._draw(scene, selected)
        self._say(self._summary(scene, selected), "ok")

    def _draw(self, scene: BoxScene, selected: str | None) -> None:
        for handle in self._handles:
            handle.remove()
        self._handles = []
        for i, box in enumerate(scene.boxes):
            sel = box.name == selected
            self._handles.append(self.app.server.scene.add_box(
                f"/obstacles/box_{i}", color=BOX_SEL_COLOR if sel else BOX_COLOR,
                dimensions=box.size, position=box.centre,
                opacity=BOX_SEL_OPACITY if sel else BOX_OPACITY, cast_shadow=False,
                receive_shadow=False))

    def _summary(self, scene: BoxScene, selected: str | None) -> str:
        count = len(scene.boxes)
        text = (f"{count} box{'es' if count != 1 else ''}; the arm keeps "
                f"{fmt_mm(scene.clearance, 0)} mm from each")
        if selected is not None:
            b = scene.get(selected)
            text += (f"; selected: <b>{html.escape(b.name)}</b> at "
                     f"({', '.join(fmt_mm(v, 0) for v in b.centre)}) mm, "
                     f"{' × '.join(fmt_mm(v, 0) for v in b.size)} mm")
        if scene.boxes:
            q = np.asarray(self.app.store.command.q, dtype=float)
            near = bc.clearance_of(extensible_arm(self.app), q, scene.boxes)
            if not near.clear_of(scene.clearance):
                text += (f"<br><b style='color:#c92a2a'>⚠ The arm's posture is too close: "
                         f"{html.escape(near.describe())}</b> (move it away: motions must keep "
                         "clear)")
        return text

    def _say(self, body: str, state: str) -> None:
        scene, version = self.current()
        self.info.content = self._info_html(body, state, scene, version)

    def _info_html(self, body: str = "No boxes: the arm moves freely.", state: str = "ok",
                   scene: BoxScene | None = None, version: int = 0) -> str:
        scene = scene or BoxScene()
        sel = html.escape(self._selected or "", quote=True) if hasattr(self, "_selected") else ""
        names = html.escape("|".join(scene.names()), quote=True)
        return (f'<div data-testid="boxes-info" data-state="{state}" data-count='
                f'"{len(scene.boxes)}" data-names="{names}" data-selected="{sel}" '
                f'data-clearance-mm="{mm_value(scene.clearance)}" data-version="{version}" '
                f'style="font-size:0.85em">{body}</div>')
