"""Objects panel: place objects and obstacles on the table by clicking, typing or dragging; save
and load them.

"Table click places" says what a click on the table (the click ray meets z = 0) does: *Object*
selects the object under it or places a new one there, *Obstacle* the same for obstacles (the
panel's "Obstacles" folder, :mod:`console.panels.soft_arm.obstacle_editor`, lists and edits them), *Bin*
places the bin that "Clear table into bin" (Control panel) takes every object to, *Nothing*
leaves the table alone. The choice, the selected object and a line about the objects stay in
view; typing, adding, removing, saving and loading sit in the folder *Edit objects* and the
obstacles in *Obstacles*, both collapsed (a first demo places objects by clicking).
Objects: each object carries a transform gizmo in the 3D view
(:mod:`console.scene.grasp_layers`) to drag it in x and y (the planner re-plans live while it
moves, see ``console.panels.soft_arm.planner``). The number boxes show and
edit the selected object, in mm (SI inside: the session keeps metres); "Add object" places one
at the typed x, y, r. The scene (objects and obstacles) is saved as a JSON download and loaded
from an uploaded file (``console.core.table_scene.parse_scene``; a bad file is refused with its reason
and changes nothing; a file without obstacles loads with none).

Sharing: the objects and the selection are the same for every browser and drive the plan, so
every change -- a click on the table, a gizmo drag, typing x / y / r, selecting, adding,
removing, loading, the click-placement choice, and the same for obstacles -- is
:func:`~console.panels.common.base.operator_only`.
A viewer's edit snaps back (fields, selection, and a dragged object returns to its place);
"Save scene" (a download that changes nothing) works for everyone.

The bin (``console.core.table_bin``): the arm must be able to hold an object over the clicked point
and its box must not stand on an obstacle nor cover the arm's straight start pose, else the
click is refused with the reason; it is saved in the scene JSON (optional ``"bin"`` key).
"""

from __future__ import annotations

import html
from typing import Any

import viser

from console.panels.common.events import target_of
from console.core.grasp_state import SessionView
from console.panels.common.base import Panel, operator_only
from console.panels.common.typed_fields import TypedFields
from console.panels.soft_arm.obstacle_editor import ObstacleEditor
from console.scene.plan_view import ray_to_table
from console.core.table_bin import (BinLocator, TableBin, bin_on_arm, bin_overlap,
                               bin_point_from_scene_json, scene_json_with_bin)
from console.core.table_scene import parse_scene, scene_to_json

# What a click on free table places (dropdown options; a click on an object or obstacle
# selects it).
CLICK_MODES = ("Object", "Obstacle", "Bin", "Nothing")
CLICK_PLACE_ORDER = 1.0  # in the Operate tab: before the Grasp planner folder (2.0)


def mm(metres: float) -> float:
    """A length for a field people read: millimetres, to 0.1 mm."""
    return round(float(metres) * 1e3, 1)


class ObjectsPanel(Panel):
    """Table objects: click / type / drag, remove, save and load."""

    title = "Objects"
    order = 5.0  # below Plan (Grasp planner), Arm and Execute (Control) and the View folder
    kinds = ("planar",)

    def build(self) -> None:
        self.session = self.app.soft_arm_grasp()
        view = self.session.view()
        first = view.objects[0] if view.objects else None
        # What a click places is the table's mode, used before Plan and to put the bin before
        # "Clear table into bin": first in Operate, above the Grasp planner (in this folder, far
        # below, placing a bin needed scrolling at 1600 x 1000)
        with self.app.tabs.tab(self.tab):
            self.click_place = self.gui.add_dropdown(
                "Table click places", CLICK_MODES, initial_value=CLICK_MODES[0],
                order=CLICK_PLACE_ORDER,
                hint="What a click on free table places: an object, an obstacle, or the bin "
                     "that 'Clear table into bin' (Control panel) takes every object to; a "
                     "click on an object or obstacle selects it. Nothing: clicks leave the "
                     "table alone.")
        self.bins = BinLocator(self.app.robot)
        self.selected = self.gui.add_dropdown(
            "Selected", [o.name for o in view.objects] or ["(none)"],
            initial_value=view.selected or "(none)")
        self.info = self.gui.add_html("")
        # Typing, adding, removing, saving and loading are editing: folded (a first demo
        # places objects by clicking the table), as are the obstacles below.
        self.editing = self.gui.add_folder("Edit objects", expand_by_default=False)
        with self.editing:
            self.x = self.gui.add_number("x (mm)", mm(first.x) if first else -200.0, step=1.0)
            self.y = self.gui.add_number("y (mm)", mm(first.y) if first else 200.0, step=1.0)
            self.r = self.gui.add_number("radius (mm)", mm(first.r) if first else 16.5,
                                         min=2.0, max=200.0, step=0.5)
            self.add_button = self.gui.add_button("Add object",
                                                  hint="New object at the typed x, y, r.")
            self.remove_button = self.gui.add_button("Remove object", color="red")
            self.save_button = self.gui.add_button("Save scene",
                                                   hint="Download the objects as JSON.")
            self.load_button = self.gui.add_upload_button(
                "Load scene", mime_type="application/json", hint="Upload a scene JSON file.")
        self.obstacles = ObstacleEditor(self, self.session, self._error)
        self._click_mode = self.click_place.value
        self._fields = {id(h): h.value for h in (self.x, self.y, self.r)}
        self._typed = TypedFields((self.x, self.y, self.r))  # refresh skips a field just typed
        self.click_place.on_update(self._on_click_mode)
        self.selected.on_update(self._on_select)
        for handle in (self.x, self.y, self.r):
            handle.on_update(self._on_typed)
        self.add_button.on_click(self._on_add)
        self.remove_button.on_click(self._on_remove)
        self.save_button.on_click(self._on_save)
        self.allow_viewers(self.save_button)  # a download for the one who asks
        self.load_button.on_upload(self._on_load)
        self.app.server.scene.on_click()(self._on_scene_click)
        self.app.soft_arm_grasp_scene().gizmo_handler = self._on_gizmo  # drags, operator-only
        self.when_closed(self.session.add_listener(lambda view, _changed: self.refresh(view)))

    # -- callbacks (thin) ------------------------------------------------------------------
    def _error(self, event, message: str) -> None:
        self.app.show_refusal(event.client, "Objects", message)

    def _on_scene_click(self, event) -> None:
        mode = self.click_place.value
        if mode not in ("Object", "Obstacle", "Bin"):
            return
        hit = ray_to_table(event.ray_origin, event.ray_direction)
        if hit is None:
            return
        if mode == "Bin":
            self._place_bin_at(event, hit)
        elif mode == "Obstacle":
            self.obstacles.place_at(event, hit)
        else:
            self._place_at(event, hit)

    @operator_only(action="place or select an object")
    def _place_at(self, event, hit: tuple[float, float]) -> None:
        before = {o.name for o in self.session.view().objects}
        try:
            name = self.session.place(*hit, r=float(self.r.value) / 1e3)
        except ValueError as exc:
            self._error(event, str(exc))
            return
        self._recorded("selected" if name in before else "placed", name, event.client)

    def _recorded(self, verb: str, name: str, client: Any) -> None:
        """An ``/operator/actions`` entry for what ``client`` did to object ``name``: where it
        is now, in mm in the words and in m in the details."""
        found = [o for o in self.session.view().objects if o.name == name]
        if not found:
            self.app.recorder.action(f"{verb} object '{name}'", client, object=name)
            return
        o = found[0]
        self.app.recorder.action(
            f"{verb} object '{name}' at ({o.x * 1e3:.0f}, {o.y * 1e3:.0f}) mm, "
            f"r {o.r * 1e3:.1f} mm",
            client, object=name, x_m=o.x, y_m=o.y, r_m=o.r)

    @operator_only(action="place the bin")
    def _place_bin_at(self, event, hit: tuple[float, float]) -> None:
        self._find_bin(event.client, hit)

    def _find_bin(self, client: Any, point: tuple[float, float]) -> None:
        """Work out the bin at ``point`` off this thread; place it, or tell ``client`` why not."""
        def done(found: TableBin | None, error: str | None) -> None:
            if found is not None:
                self.session.set_bin(found)
                self.app.recorder.action(f"bin placed: {found.describe()}", client)
            else:
                self.app.show_refusal(client, "Bin", f"Not placed: {error}")
        half = self.app.robot.bin.drop_radius_m
        on = (bin_overlap(point[0], point[1], half, self.session.view().obstacles)
              or bin_on_arm(self.app.robot, point[0], point[1], half))
        if on is not None:
            done(None, on)
            return
        self.bins.request(point[0], point[1], done)

    @operator_only(action="move an object")
    def _on_gizmo(self, name: str, event: viser.TransformControlsEvent) -> None:
        if event.client is None:
            return
        x, y = (float(v) for v in event.target.position[:2])
        self.session.drag(name, x, y, live=event.phase != "end")
        if event.phase == "end":
            self._recorded("moved", name, event.client)

    def close(self) -> None:
        """Remove the panel's widgets, the table's click mode (outside the folder) too."""
        self.click_place.remove()
        super().close()

    @operator_only(action="change how clicks on the table act")
    def _on_click_mode(self, event) -> None:
        if self.click_place.value not in CLICK_MODES:
            self.click_place.value = self._click_mode
            return
        self._click_mode = self.click_place.value

    @operator_only(action="select an object")
    def _on_select(self, event) -> None:
        if event.client is None or self.selected.value == "(none)":
            return
        try:
            self.session.select(self.selected.value)
        except ValueError as exc:
            self._error(event, str(exc))

    @operator_only(action="edit an object")
    def _on_typed(self, event) -> None:
        self._fields[id(event.target)] = event.target.value  # accepted (or a mirror)
        if event.client is None:  # our own write (a refresh's echo, a put-back): a mirror
            return
        x, y, r = self._typed.read()  # every field as typed now (taken, selection or not)
        name = self.session.view().selected
        if name is None:
            return
        try:
            self.session.update(name, x=x / 1e3, y=y / 1e3, r=r / 1e3)
        except ValueError as exc:
            self._error(event, str(exc))
            return
        self._recorded("edited", name, event.client)

    @operator_only(action="add an object")
    def _on_add(self, event) -> None:
        view = self.session.view()
        x, y = float(self.x.value) / 1e3, float(self.y.value) / 1e3
        if any(((o.x - x) ** 2 + (o.y - y) ** 2) ** 0.5 <= o.r for o in view.objects):
            x += 0.06  # typed spot taken (it shows the selected object): place beside it
        before = {o.name for o in view.objects}
        try:
            name = self.session.place(x, y, r=float(self.r.value) / 1e3)
        except ValueError as exc:
            self._error(event, str(exc))
            return
        self._recorded("selected" if name in before else "added", name, event.client)

    @operator_only(action="remove an object")
    def _on_remove(self, event) -> None:
        name = self.session.view().selected
        if name is not None:
            self.session.remove(name)
            self.app.recorder.action(f"removed object '{name}'", event.client, object=name)

    def on_refused(self, event: Any) -> None:
        """Undo what a refused viewer's edit shows everyone."""
        target = target_of(event)
        if isinstance(event, viser.TransformControlsEvent):
            self.session.redraw_objects()  # the gizmo goes back to the object
        elif target is self.click_place:
            self.click_place.value = self._click_mode
        elif self.obstacles.owns(target):
            self.obstacles.restore(target)
        elif target is self.selected:
            self.selected.value = self.session.view().selected or "(none)"
        elif target is not None and id(target) in self._fields:
            self._typed.show([self._fields[id(target)]], [target], typed_too=True)

    def _on_save(self, event) -> None:
        if event.client is not None:
            view = self.session.view()
            text = scene_json_with_bin(scene_to_json(list(view.objects), list(view.obstacles)),
                                       view.bin)
            event.client.send_file_download("grasp_scene.json", text.encode())

    @operator_only(action="load a scene")
    def _on_load(self, event) -> None:
        upload = self.load_button.value
        try:
            text = upload.content.decode("utf-8")
            scene = parse_scene(text, self.app.robot)
            bin_point = bin_point_from_scene_json(text)  # None in files without a bin
        except (ValueError, UnicodeDecodeError) as exc:
            self._error(event, f"Could not load {upload.name}: {exc}")
            return
        self.session.set_scene(scene.objects, scene.obstacles)
        self.session.set_bin(None)  # the file's bin once its pose is found (if it has one)
        self.app.recorder.action(f"loaded the scene {upload.name} ({len(scene.objects)} objects, "
                                 f"{len(scene.obstacles)} obstacles)", event.client,
                                 file=upload.name)
        if bin_point is not None:
            self._find_bin(event.client, bin_point)

    # -- display (grasp worker thread) -----------------------------------------------------
    def refresh(self, view: SessionView) -> None:
        self.obstacles.refresh(view)
        names = [o.name for o in view.objects] or ["(none)"]
        if tuple(self.selected.options) != tuple(names):
            self.selected.options = names
        want = view.selected or "(none)"
        if self.selected.value != want:
            self.selected.value = want
        obj = next((o for o in view.objects if o.name == view.selected), None)
        if obj is not None:
            self._typed.show([mm(obj.x), mm(obj.y), mm(obj.r)])
        count = len(view.objects)
        obj = next((o for o in view.objects if o.name == view.selected), None)
        where = ("" if obj is None else
                 f" at ({mm(obj.x):.0f}, {mm(obj.y):.0f}) mm, r {mm(obj.r):.1f} mm")
        text = (f"{count} object{'s' if count != 1 else ''} on the table"
                + (f"; selected: <b>{html.escape(view.selected)}</b>{where}" if view.selected
                   else ""))
        table_bin = view.bin
        text += f"; {table_bin.describe()}" if table_bin is not None else "; no bin"
        sel = html.escape(view.selected or "", quote=True)
        where_bin = "" if table_bin is None else f"{mm(table_bin.x):.0f},{mm(table_bin.y):.0f}"
        self.info.content = (f'<small data-testid="objects-info" data-selected="{sel}" '
                             f'data-bin="{where_bin}">{text}</small>')
