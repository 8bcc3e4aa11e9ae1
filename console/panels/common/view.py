"""View panel: a 3D view that explains itself -- camera presets, a legend, a measuring tool.

* **Camera**: the robot's presets (``console.scene.camera``: soft arm *Perspective* / *Top-down*;
  extensible arm *Perspective* / *Front* / *Side* / *Top-down*) and *Reset view* (the camera the
  console opens with). A preset moves only the camera of the browser that pressed it, fitted to
  that browser's window and to what is planned (a far object's approach circles), and keeps it
  framed so until the person turns or zooms it (``console.scene.window_fit``); viewers may use
  them (they move nothing but their own view).
* **Measure distance**: the presser's next two clicks on the table measure instead of doing
  anything else (no object is placed, no grasp starts: ``console.web.scene_clicks``); the line and
  its length ("123.4 mm") are drawn in the scene everyone sees. Viewers may measure. A click
  off the table is refused with the reason and draws nothing. *Clear measurement* removes it.
* **Clear trails** (operator only: the trails are the operator's inspection, which everyone
  watches): the grasp plan's waypoint trail and the extensible arm's measured path trace.
* **Legend**: what every colour in the scene is, for this robot (colours taken from the
  modules that draw them, so the legend cannot drift from the scene).
"""

from __future__ import annotations

import dataclasses
import html
import threading
from typing import Any

import numpy as np
import viser

from console.scene import camera
from console.scene.arm_view import (BACKBONE_COLOR, BODY_COLOR, GRIPPER_COLOR, PLATFORM_COLOR,
                              RACK_COLORS)
from console.scene.measure import Measurement, NotOnTable, table_hit
from console.panels.common.base import Panel, operator_only
from console.web.scene_clicks import ClickClaims

Rgb = tuple[int, int, int]
MEASURE_COLOR: Rgb = (30, 34, 40)
MEASURE_Z = 0.004                        # above the table grid and the reachability shading
RESET = "Reset view"


@dataclasses.dataclass(frozen=True)
class LegendEntry:
    """One legend row: swatch colours, the swatch's shape and what it means."""

    colors: tuple[Rgb, ...]
    shape: str   # "fill" (a solid part), "line", "dot", "ring", "area" (translucent)
    text: str


def _legend(kind: str) -> tuple[LegendEntry, ...]:
    """The legend rows for a robot kind (imports the drawing modules' colours)."""
    if kind == "planar":
        from console.panels.soft_arm import control
        from console.scene.plan_view import (CAPTURE_COLOR, CIRCLE_COLOR, FAIL_COLOR, GHOST_COLOR,
                                       GHOST_SEL_COLOR, OBJECT_COLOR, OBJECT_SEL_COLOR,
                                       PALM_COLOR, REACH_COLORS)
        from console.scene.carry_view import CARRY_COLOR, CARRY_GHOST_COLOR
        from console.core.table_bin import BIN_COLOR
        from core.planning.reachability import FAILS, PLANNABLE
        return (
            LegendEntry((BODY_COLOR, GRIPPER_COLOR), "fill", "Arm and its gripper"),
            LegendEntry((GHOST_SEL_COLOR,), "line",
                        "Ghost arm: the plan's inspected waypoint (preview, not the arm)"),
            LegendEntry((GHOST_COLOR,), "line",
                        "Trail: ghost arms of the last waypoints passed"),
            LegendEntry((PALM_COLOR,), "dot",
                        "Waypoints: where the palm goes, step by step (numbered)"),
            LegendEntry((CIRCLE_COLOR, FAIL_COLOR), "ring",
                        "Approach circles around the object (red: planning failed there)"),
            LegendEntry((OBJECT_COLOR, OBJECT_SEL_COLOR), "fill",
                        "Object to grasp (pink: selected)"),
            LegendEntry((CAPTURE_COLOR,), "area", "Capture region at the last waypoint"),
            LegendEntry((CARRY_COLOR, CARRY_GHOST_COLOR), "line",
                        "Carry to the bin around the obstacles: the palm's path (faint: "
                        "the arm at each via)"),
            LegendEntry((REACH_COLORS[PLANNABLE],), "area", "Table: a grasp can be planned"),
            LegendEntry((REACH_COLORS[FAILS],), "area", "Table: planning fails here"),
            LegendEntry((control.OBJECT_COLOR,), "fill", "Control's grasp-and-place object"),
            LegendEntry((BIN_COLOR,), "ring", "Bin: where 'Clear table into bin' takes them"),
            LegendEntry((MEASURE_COLOR,), "line", "Measurement (View → Measure distance)"),
        )
    from console.panels.extensible.path_scene import GHOST_COLOR as PATH_GHOST_COLOR
    from console.panels.extensible.path_scene import MEASURED_COLOR, TRACE_COLOR
    from console.panels.extensible.target import MISS_COLOR, TARGET_COLOR
    return (
        LegendEntry((BACKBONE_COLOR, PLATFORM_COLOR), "fill", "Backbone and platforms"),
        LegendEntry(tuple(RACK_COLORS), "fill", "Racks 1, 2, 3"),
        LegendEntry(((220, 50, 50), (50, 180, 60), (50, 90, 220)), "line",
                    "Tip frame: x, y, z axes"),
        LegendEntry((TARGET_COLOR,), "dot", "Tip target (drag its gizmo)"),
        LegendEntry((MISS_COLOR,), "line", "Target out of reach: nearest tip → target"),
        LegendEntry((TRACE_COLOR,), "line", "Path preview: planned tip trace and waypoints"),
        LegendEntry((PATH_GHOST_COLOR,), "area", "Path preview: ghost arms along it"),
        LegendEntry((MEASURED_COLOR,), "line", "Trail: measured tip of the last path run"),
        LegendEntry((MEASURE_COLOR,), "line", "Measurement (View → Measure distance)"),
    )


def _swatch(color: Rgb, shape: str) -> str:
    rgb = f"rgb{tuple(int(c) for c in color)}"
    base = "display:inline-block;vertical-align:middle;margin-right:2px;"
    if shape == "line":
        return f'<span style="{base}width:12px;height:4px;border-radius:2px;background:{rgb}">' \
               "</span>"
    if shape == "dot":
        return f'<span style="{base}width:9px;height:9px;border-radius:50%;background:{rgb}">' \
               "</span>"
    if shape == "ring":
        return (f'<span style="{base}width:10px;height:10px;border-radius:50%;'
                f'border:2px solid {rgb}"></span>')
    if shape == "area":
        return (f'<span style="{base}width:12px;height:10px;border-radius:2px;background:{rgb};'
                f'opacity:.55;outline:1px solid {rgb}"></span>')
    return f'<span style="{base}width:12px;height:10px;border-radius:2px;background:{rgb}"></span>'


def legend_html(kind: str) -> str:
    """The legend for a robot kind (``data-testid="view-legend"``, one ``li`` per entry)."""
    rows = "".join(
        f'<li style="margin:2px 0;list-style:none;display:flex;align-items:flex-start">'
        f'<span style="flex:0 0 50px;padding-top:1px">'
        f'{"".join(_swatch(c, e.shape) for c in e.colors)}</span>'
        f'<span>{html.escape(e.text)}</span></li>'
        for e in _legend(kind))
    return (f'<div data-testid="view-legend" style="font-size:0.8em;line-height:1.3">'
            f'<b>Legend</b><ul style="padding:0;margin:2px 0 0 0">{rows}</ul></div>')


class ViewPanel(Panel):
    """Camera presets, measuring tool, trails and the legend (see the module docstring)."""

    title = "View"
    order = 4.0  # right below the task's panels (Control; Paths), one click to open
    expand_by_default = False

    def build(self) -> None:
        app, gui = self.app, self.gui
        self.kind = app.model.kind
        self.span = app.arm_reach()
        self.table = app.table_rectangle()
        names = [p.name for p in camera.presets(self.kind, self.span, self.table)]
        # One button per preset (a button group's value is refused by console.web.client_values,
        # which takes every button-like widget for a plain button).
        self.cameras = {name: gui.add_button(name, icon=viser.Icon.CAMERA,
                                             hint=f"Your camera (only yours) to the {name} view.")
                        for name in names}
        self.reset = gui.add_button(RESET, icon=viser.Icon.HOME,
                                    hint="Your camera back to the first view, framed for your window.")
        self.measure = gui.add_button(
            "Measure distance", icon=viser.Icon.RULER_MEASURE,
            hint="Then click two points on the table: the distance is shown to everyone. "
                 "Those two clicks place nothing.")
        self.clear_measure = gui.add_button("Clear measurement", icon=viser.Icon.ERASER)
        self.clear_trails = gui.add_button(
            "Clear trails", icon=viser.Icon.TRASH,
            hint="Hide the plan's waypoint trail and the last path run's measured tip trace.")
        self.status = gui.add_html(self._status_html("", "idle"))
        self.legend = gui.add_html(legend_html(self.kind))
        self._lock = threading.Lock()
        self._first: dict[int, tuple[float, float]] = {}     # client id -> first point
        self.measurement: Measurement | None = None
        scene = app.server.scene
        self.line = scene.add_line_segments("/view/measure/line", np.zeros((1, 2, 3)),
                                            MEASURE_COLOR, thickness=4.0,
                                            thickness_units="screen", visible=False)
        self.ends = scene.add_point_cloud("/view/measure/ends", np.zeros((1, 3)), MEASURE_COLOR,
                                          point_size=0.012, point_shape="circle",
                                          visible=False)
        self.label = scene.add_label("/view/measure/label", "", position=(0.0, 0.0, MEASURE_Z),
                                     font_screen_scale=1.3, anchor="bottom-center",
                                     visible=False)
        self.claims = ClickClaims(app.server, self._on_measure_click)
        for name, button in self.cameras.items():
            button.on_click(lambda e, name=name: self._on_camera(e, name))
        self.reset.on_click(self._on_reset)
        self.measure.on_click(self._on_measure)
        self.clear_measure.on_click(self._on_clear_measure)
        self.clear_trails.on_click(self._on_clear_trails)
        # Cameras and measurements move nothing: viewers may use them too.
        self.allow_viewers(*self.cameras.values(), self.reset, self.measure, self.clear_measure)

    # -- camera ------------------------------------------------------------------------------
    def pose_for(self, client: Any, name: str) -> camera.CameraPose:
        """The preset ``name`` (or Reset's, the first) fitted to ``client``'s window (its
        canvas's aspect) and to what is planned (``console.scene.window_fit``)."""
        return self.app.window_fit.pose_for(client, None if name == RESET else name)

    def move_camera(self, client: Any, name: str) -> camera.CameraPose:
        """Move ``client``'s camera (theirs only) to the preset ``name``; the console keeps it
        framed for that preset (a new plan, another window size) until the person moves it."""
        return self.app.window_fit.put(client, None if name == RESET else name)

    def _on_camera(self, event: viser.GuiEvent, name: str) -> None:
        if event.client is not None:
            self.move_camera(event.client, name)

    def _on_reset(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.move_camera(event.client, RESET)

    # -- measuring ---------------------------------------------------------------------------
    def _on_measure(self, event: viser.GuiEvent) -> None:
        client = event.client
        if client is None:
            return
        with self._lock:
            self._first.pop(client.client_id, None)
        self.claims.claim(client.client_id)
        self._set_status("Click the first point on the table.", "first")
        client.add_notification("Measure distance", "Click two points on the table. Those "
                                "clicks place nothing.", color="blue", auto_close_seconds=5.0)

    def start_measuring(self, client_id: int) -> None:
        """Programmatic twin of the button (tests): ``client_id``'s next two clicks measure."""
        with self._lock:
            self._first.pop(client_id, None)
        self.claims.claim(client_id)

    def _on_measure_click(self, event: viser.SceneClickEvent) -> None:
        """A claimed browser's click (a viser worker thread): first point, then the second."""
        try:
            point = table_hit(event.ray_origin, event.ray_direction, self.table)
        except NotOnTable as exc:
            if event.client is not None:
                event.client.add_notification("Not on the table", f"Not measured: {exc}.",
                                              color="yellow", auto_close_seconds=5.0)
            return
        cid = event.client_id
        with self._lock:
            first = self._first.pop(cid, None)
            if first is None:
                self._first[cid] = point
        if first is None:
            with self.app.server.atomic():
                self.ends.points = np.array([[point[0], point[1], MEASURE_Z]])
                self.ends.visible = True
                self.line.visible = self.label.visible = False
            self._set_status("Click the second point on the table.", "second")
            return
        self.claims.release(cid)
        self.show(Measurement(first, point))
        self.app.recorder.action(f"measured {self.measurement.label}", event.client)

    def show(self, m: Measurement) -> None:
        """Draw ``m`` for everyone (replaces the previous measurement)."""
        self.measurement = m
        mid = m.midpoint
        with self.app.server.atomic():
            self.line.points = m.segment(MEASURE_Z)
            self.ends.points = m.segment(MEASURE_Z)[0]
            self.label.text = m.label
            self.label.position = (mid[0], mid[1], MEASURE_Z)
            for h in (self.line, self.ends, self.label):
                h.visible = True
        self._set_status(f"{m.label} between ({m.a[0] * 1e3:.0f}, {m.a[1] * 1e3:.0f}) and "
                         f"({m.b[0] * 1e3:.0f}, {m.b[1] * 1e3:.0f}) mm.", "done",
                         mm=m.distance * 1e3)

    def _on_clear_measure(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.claims.release(event.client.client_id)
            with self._lock:
                self._first.pop(event.client.client_id, None)
        self.measurement = None
        with self.app.server.atomic():
            for h in (self.line, self.ends, self.label):
                h.visible = False
        self._set_status("", "idle")

    def _set_status(self, text: str, state: str, mm: float | None = None) -> None:
        self.status.content = self._status_html(text, state, mm)

    @staticmethod
    def _status_html(text: str, state: str, mm: float | None = None) -> str:
        value = "" if mm is None else f"{mm:.3f}"
        return (f'<div data-testid="measure-status" data-state="{state}" data-mm="{value}" '
                f'style="font-size:0.85em">{html.escape(text)}</div>')

    # -- trails ------------------------------------------------------------------------------
    @operator_only(action="clear the trails")
    def _on_clear_trails(self, event: viser.GuiEvent) -> None:
        self.clear_all_trails()

    def clear_all_trails(self) -> None:
        """Hide the grasp plan's waypoint trail and the extensible arm's measured path trace."""
        session = self.app.grasp_session
        if session is not None:
            session.clear_trail()
        from console.panels.extensible.paths import PathsPanel
        for panel in self.app.panels:
            if isinstance(panel, PathsPanel):
                panel.clear_trails()
