"""The grasp layer of the 3D view, and the pure pieces behind it, for the grasp panels.

:class:`PlanScene` owns the scene nodes of grasp planning: table objects with their drag gizmos,
approach circles (green; a failed radius red; labelled with their radii), ghost arms of the
waypoints (the inspected one highlighted, a fading trail of the last few passed), numbered palm
points, the gripper's capture region at the final
waypoint and the reachability shading. Each line or point node has one colour, or a fixed size
(:class:`console.scene.line_nodes.FixedLines`), so a browser never holds a node's points and
colours at different lengths (drawn as white lines). Exactly one thread may draw into it: the
grasp layers (:class:`console.scene.grasp_layers.GraspSceneView`), told by the grasp session's
worker. The shading (where a grasp can be planned from the straight arm, :mod:`core.planning.reachability`) comes from a disk cache or a low-priority
child process (:func:`console.core.reach_job.start_reach_map`), so it never holds the GUI's threads
or the GIL; it is drawn smooth and clipped to the table (:mod:`console.scene.reach_shading`).

Geometry comes from pure functions (``plan_geometry``, ``ghost_segments``, ``object_mesh``,
``reach_mesh``, ``ray_to_table``: :mod:`console.scene.plan_geometry`, re-exported here), tested
without a server. The table objects themselves, their
checks and scene JSON are :mod:`console.core.table_scene` (obstacles are drawn by
:mod:`console.scene.obstacle_view`). :func:`outcome_html` / :func:`planning_html` are what the
planner panel shows of the session's :class:`console.core.grasp_state.Outcome`.
"""

from __future__ import annotations

import html
from typing import Any, Callable

import numpy as np

from console.core.grasp_state import Outcome
from console.core.table_scene import TableObject
from console.scene.line_nodes import FixedLines
from console.scene.plan_geometry import (  # noqa: F401 (re-exported: the plan layer's pure pieces)
    CIRCLE_COLOR, FAIL_COLOR, GHOST_COLOR, LABEL_GAP, TABLE_TINT, TRAIL_FADE, TRAIL_WAYPOINTS,
    Z_PLAN, Array, circle_segments, disk_mesh, ghost_segments, object_mesh, plan_geometry,
    plan_labels, ray_to_table, reach_mesh, trail_colors, trail_mask)
from core.planning.plan_types import GraspPlan
from console.scene.reach_shading import shading_meshes
from core.planning.reachability import FAILS, PLANNABLE, ReachMap
from core.units import fmt_mm

CIRCLE_SEL_COLOR, GHOST_SEL_COLOR = (10, 230, 60), (245, 120, 20)
PALM_COLOR, CAPTURE_COLOR = (200, 40, 60), (70, 140, 235)
OBJECT_COLOR, OBJECT_SEL_COLOR = (150, 95, 200), (205, 60, 160)
REACH_COLORS = {PLANNABLE: (80, 200, 110), FAILS: (235, 170, 60)}
DIM_COLOR = (170, 170, 170)  # the operator's next plan while the arm runs another


def _show_lines(handle: Any, segments: Array) -> None:
    """Show ``segments`` on a node of one colour (any number of them: its colour is one RGB,
    whatever the points' length), or hide it when there are none."""
    if len(segments):
        handle.points = segments
    handle.visible = len(segments) > 0


class PlanScene:
    """The grasp layer of the 3D view. Build it once; then only one thread may call draw_*."""

    def __init__(self, server, robot) -> None:
        self.server, self.robot = server, robot
        scene = server.scene
        empty = np.zeros((1, 2, 3))
        # Every node has one colour (or a fixed size): a browser given a node's new points and
        # colours of another length in two messages may draw its lines white.
        self.circles = scene.add_line_segments("/grasp/plan/circles", empty, CIRCLE_COLOR,
                                               thickness=0.0025, visible=False)
        self.circles_failed = scene.add_line_segments("/grasp/plan/circles_failed", empty,
                                                      FAIL_COLOR, thickness=0.0025,
                                                      visible=False)
        self.circle_sel = scene.add_line_segments("/grasp/plan/circle_sel", empty,
                                                  CIRCLE_SEL_COLOR, thickness=0.006,
                                                  visible=False)
        arm = ghost_segments(robot, np.zeros((1, robot.n_segments)), 0.0).shape[1]
        self._ghosts = FixedLines(scene, "/grasp/plan/ghosts", GHOST_COLOR, 0.004,
                                  TRAIL_WAYPOINTS * arm)
        self.ghost_sel = scene.add_line_segments("/grasp/plan/ghost_sel", empty,
                                                 GHOST_SEL_COLOR, thickness=0.009,
                                                 visible=False)
        self.palms = scene.add_point_cloud("/grasp/plan/palms", np.zeros((1, 3)), PALM_COLOR,
                                           point_size=0.012, point_shape="circle",
                                           visible=False)
        self.palm_sel = scene.add_icosphere("/grasp/plan/palm_sel", radius=0.009,
                                            color=GHOST_SEL_COLOR, visible=False,
                                            cast_shadow=False)
        v, f = disk_mesh((0, 0), robot.capture.diameter / 2, 0.0012)
        self.capture = scene.add_mesh_simple("/grasp/plan/capture", v, f, color=CAPTURE_COLOR,
                                             opacity=0.35, visible=False, cast_shadow=False,
                                             receive_shadow=False, side="double")
        # The operator's next plan while the arm runs another: grey, thin, no numbers.
        self.dim_circles = scene.add_line_segments("/grasp/plan/next_circles", empty, DIM_COLOR,
                                                   thickness=0.0015, visible=False)
        self.dim_palms = scene.add_point_cloud("/grasp/plan/next_palms", np.zeros((1, 3)),
                                               DIM_COLOR, point_size=0.008,
                                               point_shape="circle", visible=False)
        self.dimmed = False  # whether the plan is drawn as the next one (apart, grey)
        self.labels: dict[str, list[Any]] = {"circles": [], "waypoints": []}
        self.reach: list = []
        self.objects: dict[str, tuple[Any, Any, float]] = {}   # name -> (gizmo, body, radius)
        self._made = 0

    @property
    def ghosts(self) -> Any:
        """The trail's ghost arms' node."""
        return self._ghosts.handle

    def draw_plan(self, plan: GraspPlan | None, index: int, trail: bool,
                  trail_from: int = 0, dim: bool = False) -> None:
        """Show ``plan`` (None hides the plan layer); the trail starts at ``trail_from``.
        ``dim``: the arm runs another plan, so this one (the operator's next) is drawn apart:
        grey circles and palm points only, no ghost arms or numbers."""
        with self.server.atomic():          # one change in the browser, where it can be
            self._draw_plan(plan, index, trail, trail_from, dim)

    def _draw_plan(self, plan: GraspPlan | None, index: int, trail: bool,
                   trail_from: int, dim: bool = False) -> None:
        handles = (self.circles, self.circles_failed, self.circle_sel, self.ghosts,
                   self.ghost_sel, self.palms, self.palm_sel, self.capture)
        self.dimmed = dim and plan is not None and plan.n > 0
        if self.dimmed:
            for h in handles:
                h.visible = False
            self._draw_labels({"circles": [], "waypoints": []})
            g = plan_geometry(self.robot, plan, index, False)
            _show_lines(self.dim_circles, g["circles"])
            self.dim_palms.points = g["palms"]
            self.dim_palms.visible = True
            return
        self.dim_circles.visible = self.dim_palms.visible = False
        if plan is None or plan.n == 0:
            for h in handles:
                h.visible = False
            self._draw_labels({"circles": [], "waypoints": []})
            return
        g = plan_geometry(self.robot, plan, index, trail, trail_from)
        _show_lines(self.circles, g["circles"][g["circle_ok"]])
        _show_lines(self.circles_failed, g["circles"][~g["circle_ok"]])
        self.circle_sel.points = g["circle_sel"]
        if len(g["ghosts"]):
            self._ghosts.show(g["ghosts"], g["ghost_colors"])
        else:
            self._ghosts.hide()
        self.ghost_sel.points = g["ghost_sel"]
        self.palms.points = g["palms"]
        self.palm_sel.position = tuple(g["palm_sel"])
        self.capture.vertices = g["capture"][0]
        self.capture.visible = g["capture_visible"]
        for h in (self.circle_sel, self.ghost_sel, self.palms, self.palm_sel):
            h.visible = True
        self._draw_labels(g["labels"])

    def _draw_labels(self, labels: dict[str, list[tuple[str, tuple[float, ...], str]]]) -> None:
        """Reuse, add or hide label nodes so each text sits at its position (screen-sized
        text, so it stays readable at any zoom; drawn over the scene)."""
        scene = self.server.scene
        for kind, wanted in labels.items():
            pool = self.labels[kind]
            for i, (text, pos, anchor) in enumerate(wanted):
                if i == len(pool):
                    pool.append(scene.add_label(
                        f"/grasp/plan/labels/{kind}_{i}", text, position=pos,
                        font_screen_scale=0.85 if kind == "circles" else 1.0, anchor=anchor))
                    continue
                h = pool[i]
                if h.text != text:
                    h.text = text
                if h.anchor != anchor:
                    h.anchor = anchor
                if np.any(np.abs(np.subtract(h.position, pos)) > 1e-6):
                    h.position = pos
                h.visible = True
            for h in pool[len(wanted):]:
                h.visible = False

    def draw_reach(self, reach: ReachMap, visible: bool,
                   extent: tuple[float, float, float, float] | None = None) -> None:
        """Shade where a grasp can be planned (green) or fails (amber), smooth and clipped to
        the table rectangle ``extent`` (x0, x1, y0, y1)."""
        if not self.reach:
            meshes = shading_meshes(reach, extent)
            for status, color in REACH_COLORS.items():
                mesh = meshes[status]
                if mesh is not None:
                    self.reach.append(self.server.scene.add_mesh_simple(
                        f"/grasp/reach/{status}", mesh[0], mesh[1], color=color, opacity=0.28,
                        cast_shadow=False, receive_shadow=False, side="front"))
        for h in self.reach:
            h.visible = visible

    def sync_objects(self, objects: list[TableObject], selected: str | None,
                     on_move: Callable[[str, Any], None]) -> None:
        """Create, move, recolour or remove the object nodes to match ``objects``."""
        scene = self.server.scene
        wanted = {o.name: o for o in objects}
        for name in list(self.objects):
            if name not in wanted:
                gizmo, body, _ = self.objects.pop(name)
                body.remove()
                gizmo.remove()
        for o in objects:
            color = OBJECT_SEL_COLOR if o.name == selected else OBJECT_COLOR
            entry = self.objects.get(o.name)
            if entry is None or abs(entry[2] - o.r) > 1e-12:
                if entry is not None:
                    entry[1].remove()
                    gizmo = entry[0]
                else:
                    self._made += 1
                    key = f"/grasp/objects/object_{self._made}"
                    gizmo = scene.add_transform_controls(
                        key, scale=0.08, disable_rotations=True, active_axes=(True, True, False),
                        depth_test=False, line_width=2.0, position=(o.x, o.y, 0.0))
                    gizmo.on_update(lambda ev, name=o.name: on_move(name, ev))
                v, f = object_mesh(o.r)
                body = scene.add_mesh_simple(f"{gizmo.name}/body", v, f, color=color,
                                             cast_shadow=False)
                self.objects[o.name] = (gizmo, body, o.r)
            gizmo, body, _ = self.objects[o.name]
            if np.hypot(gizmo.position[0] - o.x, gizmo.position[1] - o.y) > 1e-9:
                gizmo.position = (o.x, o.y, 0.0)
            body.color = color


def _carry_words(plan: GraspPlan, note: str | None) -> str:
    """The carry to the bin in words (empty without obstacles or a bin)."""
    if note:
        note = note.removeprefix("Carry to the bin: ")
        return f"; <b style='color:#c92a2a'>no carry to the bin:</b> {html.escape(note)}"
    if plan.carry is None:
        return ""
    vias = len(plan.carry) - 1
    return ("; carry to the bin: straight" if vias == 0 else
            f"; carry to the bin: {vias} via shape{'s' if vias > 1 else ''} (teal)")


def _kept_from(n_obstacles: int, others: tuple[str, ...]) -> str:
    """What a plan kept its clearance from, in words: the obstacles placed and the other
    objects on the table (each an obstacle too)."""
    placed = n_obstacles - len(others)
    if not others:
        return "the obstacles"
    named = html.escape(", ".join(others))
    objects = f"the other object{'s' if len(others) > 1 else ''} ({named})"
    return f"the obstacles and {objects}" if placed > 0 else objects


def planning_html(seconds: float) -> str:
    """What the planner summary shows while a plan takes longer than a moment."""
    return (f'<div data-testid="plan-summary" data-state="planning" data-waypoints="" '
            f'data-ms="" data-obstacle-mm="" style="font-size:0.85em"><b>Planning… '
            f'({seconds:.1f} s)</b></div>')


def outcome_html(outcome: Outcome | None) -> str:
    """The planner summary the operator reads (with test ids and a machine-readable state)."""
    if outcome is None:
        body, state, n, ms = "Place an object and press <b>Plan grasp</b>.", "idle", "", ""
    elif outcome.refusal is not None:
        body = f"<b style='color:#c92a2a'>Refused:</b> {html.escape(outcome.refusal)}"
        state, n, ms = "refused", "", ""
    else:
        plan = outcome.plan
        n, ms = str(plan.n), f"{plan.total_ms:.1f}"
        if plan.success:
            body, state = (f"<b>{plan.n} waypoint{'s' if plan.n != 1 else ''}, "
                           f"{plan.total_ms:.1f} ms</b>"), "ok"
            if plan.obstacles and plan.obstacle_path_clearance is not None:
                gap = float(np.min(plan.obstacle_path_clearance))
                body += (f"; the arm keeps ≥ {fmt_mm(gap, 0)} mm from "
                         f"{_kept_from(len(plan.obstacles), outcome.others)} "
                         f"(clearance {fmt_mm(plan.obstacle_margin, 0)} mm)")
            body += _carry_words(plan, outcome.carry_note)
        else:
            f = plan.failures[0]
            body = (f"<b style='color:#c92a2a'>Failed</b> at approach circle {f.index} "
                    f"(r_a = {f.radius * 1e3:.0f} mm, {f.reason.replace('_', ' ')}): "
                    f"{html.escape(f.detail)}. {plan.n} waypoints, {plan.total_ms:.1f} ms.")
            state = "failed"
    plan = outcome.plan if outcome is not None else None
    gap = ("" if plan is None or not plan.obstacles or plan.obstacle_path_clearance is None
           else f"{float(np.min(plan.obstacle_path_clearance)) * 1e3:.2f}")
    return (f'<div data-testid="plan-summary" data-state="{state}" data-waypoints="{n}" '
            f'data-ms="{ms}" data-obstacle-mm="{gap}" style="font-size:0.85em">{body}</div>')
