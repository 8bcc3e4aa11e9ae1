"""The grasp layer of the 3D view, and the pure pieces behind it, for the grasp panels.

:class:`PlanScene` owns the scene nodes of grasp planning: table objects with their drag gizmos,
approach circles (green; a failed radius red; labelled with their radii), ghost arms of the
waypoints (the inspected one highlighted, a fading trail of the last few passed), numbered palm
points, the gripper's capture region at the final
waypoint and the reachability shading. Exactly one thread may draw into it: the grasp session's
worker (``console.panels.planner.GraspSession``). The shading (where a grasp can be planned from
the straight arm, :mod:`core.planning.reachability`) comes from a disk cache or a low-priority
child process (:func:`console.reach_job.start_reach_map`), so it never holds the GUI's threads
or the GIL; it is drawn smooth and clipped to the table (:mod:`console.reach_shading`).

Geometry comes from pure functions (``plan_geometry``, ``ghost_segments``, ``object_mesh``,
``reach_mesh``, ``ray_to_table``), tested without a server. The table objects themselves, their
checks and scene JSON are :mod:`console.table_scene` (obstacles are drawn by
:mod:`console.obstacle_view`). :class:`Outcome` / :class:`SessionView` / :func:`outcome_html`
are what the panels show.
"""

from __future__ import annotations

import dataclasses
import html
import math
from typing import Any, Callable

import numpy as np
import numpy.typing as npt

from core.kinematics import planar as pk
from core.planning.obstacles import Obstacle
from core.planning.plan_types import GraspPlan
from console.reach_shading import shading_meshes
from console.table_scene import TableObject
from core.planning.reachability import FAILS, PLANNABLE, ReachMap
from core.units import fmt_mm

Array = npt.NDArray[np.float64]
LIVE_HZ = 20.0
Z_PLAN = 0.03                       # plan drawings float above the arm tube
CIRCLE_COLOR, CIRCLE_SEL_COLOR, FAIL_COLOR = (40, 170, 70), (10, 230, 60), (215, 45, 45)
GHOST_COLOR, GHOST_SEL_COLOR = (120, 140, 170), (245, 120, 20)
PALM_COLOR, CAPTURE_COLOR = (200, 40, 60), (70, 140, 235)
OBJECT_COLOR, OBJECT_SEL_COLOR = (150, 95, 200), (205, 60, 160)
REACH_COLORS = {PLANNABLE: (80, 200, 110), FAILS: (235, 170, 60)}
TRAIL_WAYPOINTS = 4                 # the trail shows at most this many passed waypoints
TRAIL_FADE = 0.45                   # the oldest of them is this far faded towards the table
TABLE_TINT = np.array([226, 222, 214], float)  # what a faded trail fades into
LABEL_GAP = 0.022                   # m between a waypoint's dot and its number


def ray_to_table(origin: npt.ArrayLike, direction: npt.ArrayLike) -> tuple[float, float] | None:
    """Where a click ray meets the table plane z = 0 (None if it points away)."""
    o, d = np.asarray(origin, float), np.asarray(direction, float)
    if d[2] >= -1e-9:
        return None
    t = -o[2] / d[2]
    return (float(o[0] + t * d[0]), float(o[1] + t * d[1])) if t > 0 else None


def disk_mesh(center: npt.ArrayLike, radius: float, z: float, n: int = 48) -> tuple[Array, Any]:
    """Triangle fan of a flat disk."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = np.zeros((n + 1, 3))
    v[0] = (center[0], center[1], z)
    v[1:, 0] = center[0] + radius * np.cos(a)
    v[1:, 1] = center[1] + radius * np.sin(a)
    v[:, 2] = z
    f = np.stack([np.zeros(n, int), 1 + np.arange(n), 1 + (np.arange(n) + 1) % n], -1)
    return v, f.astype(np.uint32)


def object_mesh(radius: float, height: float = 0.04, n: int = 32) -> tuple[Array, Any]:
    """Closed cylinder of ``radius`` standing on z = 0, in the object's own frame."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], -1)
    v = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, height)],
                        [[0, 0, 0], [0, 0, height]]])
    i, j = np.arange(n), (np.arange(n) + 1) % n
    side = np.concatenate([np.stack([i, j, n + j], -1), np.stack([i, n + j, n + i], -1)])
    caps = np.concatenate([np.stack([np.full(n, 2 * n), j, i], -1),
                           np.stack([np.full(n, 2 * n + 1), n + i, n + j], -1)])
    return v, np.concatenate([side, caps]).astype(np.uint32)


def circle_segments(center: npt.ArrayLike, radii: npt.ArrayLike, z: float, n: int = 72) -> Array:
    """Line segments (len(radii) * n, 2, 3) of circles around ``center``."""
    a = np.linspace(0, 2 * np.pi, n + 1)
    r = np.asarray(radii, float)[:, None]
    pts = np.stack([center[0] + r * np.cos(a), center[1] + r * np.sin(a),
                    np.full_like(r * a, z)], -1)                     # (k, n+1, 3)
    return np.stack([pts[:, :-1], pts[:, 1:]], 2).reshape(-1, 2, 3)


def ghost_segments(robot, kappas: Array, z: float, per_segment: int = 8) -> Array:
    """Backbone polyline plus straight gripper of each configuration: (k, S, 2, 3)."""
    kappas = np.asarray(kappas, float).reshape(-1, robot.n_segments)
    bb = pk.sample_backbone(kappas, robot.lengths, per_segment, robot.base_pose)  # (k, P, 3)
    tip = bb[:, -1]
    g_end = tip[:, :2] + robot.gripper.length * np.stack([np.cos(tip[:, 2]),
                                                           np.sin(tip[:, 2])], -1)
    pts = np.concatenate([bb[:, :, :2], g_end[:, None]], 1)             # (k, P+1, 2)
    pts = np.concatenate([pts, np.full(pts.shape[:2] + (1,), z)], -1)
    return np.stack([pts[:, :-1], pts[:, 1:]], 2)


def trail_mask(n: int, index: int, trail: bool, trail_from: int = 0) -> Array:
    """Which waypoints' ghost arms the trail shows: at most :data:`TRAIL_WAYPOINTS` of those
    passed before ``index``, none before ``trail_from`` ("Clear trails"), none if ``trail``
    is off."""
    i = np.arange(n)
    if not trail:
        return np.zeros(n, bool)
    return (i < index) & (i >= max(trail_from, index - TRAIL_WAYPOINTS))


def trail_colors(shown: Array, index: int) -> Array:
    """One colour per shown ghost arm: the newest in :data:`GHOST_COLOR`, older ones faded."""
    age = index - np.nonzero(shown)[0]                                  # 1 = the last passed
    fade = TRAIL_FADE * (age - 1) / max(TRAIL_WAYPOINTS - 1, 1)
    c = (1 - fade[:, None]) * np.array(GHOST_COLOR, float) + fade[:, None] * TABLE_TINT
    return np.round(c).astype(np.uint8)


def plan_labels(robot, plan: GraspPlan) -> dict[str, list[tuple[str, tuple[float, ...], str]]]:
    """Text, position and anchor of each label: every approach circle's radius just outside
    the circle on the side away from the arm's base (where no arm is drawn; the text runs
    outwards, off the circles), and every waypoint's number just outside its palm dot."""
    c = np.asarray(plan.center[:2], float)
    base = np.asarray(robot.base_pose[:2], float)
    away = c - base
    away = away / np.linalg.norm(away) if np.linalg.norm(away) > 1e-9 else np.array([0.0, 1.0])
    side = "center-right" if away[0] < 0 else "center-left"     # text extends away, not inwards
    circles = [(f"r{k + 1} {fmt_mm(r, 0)} mm", (*(c + (r + LABEL_GAP / 3) * away), Z_PLAN), side)
               for k, r in enumerate(np.asarray(plan.radii, float))]
    points = []
    for k, p in enumerate(np.asarray(plan.palm_poses)[:, :2]):
        out = p - c
        n = np.linalg.norm(out)
        out = out / n if n > 1e-9 else -away
        points.append((f"{k + 1}", (*(p + LABEL_GAP * out), Z_PLAN), "center-center"))
    return {"circles": circles, "waypoints": points}


def plan_geometry(robot, plan: GraspPlan, index: int, trail: bool,
                  trail_from: int = 0) -> dict[str, Any]:
    """Everything the plan layer draws for ``plan`` with waypoint ``index`` (0-based) inspected."""
    ok = np.array([s == "ok" for s in plan.status])
    circles = circle_segments(plan.center, plan.radii, Z_PLAN - 0.002)
    per = len(circles) // max(plan.n, 1)
    circle_colors = np.repeat(np.where(ok[:, None], [CIRCLE_COLOR], [FAIL_COLOR]), per, 0)
    ghosts = ghost_segments(robot, plan.kappas, Z_PLAN)
    shown = trail_mask(plan.n, index, trail, trail_from)
    palm = np.c_[plan.palm_poses[:, :2], np.full(plan.n, Z_PLAN)]
    final = plan.palm_poses[-1]
    # The capture region is on the closing finger's side: the gripper's left, or its right
    # for a plan of the right finger (core.planning.sides).
    side = -1.0 if getattr(plan, "side", "left") == "right" else 1.0
    left = np.array([-math.sin(final[2]), math.cos(final[2])])
    aim = final[:2] + side * left * (robot.gripper.g_off + robot.capture.nominal_object_radius)
    ghost_colors = np.repeat(trail_colors(shown, index), ghosts.shape[1], 0)
    return {
        "circles": circles, "circle_colors": np.repeat(circle_colors[:, None], 2, 1),
        "circle_sel": circle_segments(plan.center, plan.radii[index:index + 1], Z_PLAN - 0.001),
        "ghosts": ghosts[shown].reshape(-1, 2, 3),
        "ghost_colors": np.repeat(ghost_colors[:, None], 2, 1),
        "ghost_sel": ghosts[index],
        "palms": palm, "palm_sel": palm[index],
        "capture": disk_mesh(aim, robot.capture.diameter / 2, 0.0012),
        "capture_visible": bool(ok.all()) and index == plan.n - 1,
        "labels": plan_labels(robot, plan),
    }


def reach_mesh(reach: ReachMap, status: int, z: float = 0.0007) -> tuple[Array, Any] | None:
    """Quads of the cells with ``status`` as one mesh (None if there are none)."""
    iy, ix = np.nonzero(reach.status == status)
    if len(ix) == 0:
        return None
    h = reach.step / 2
    cx, cy = reach.xs[ix], reach.ys[iy]
    corners = np.stack([np.c_[cx - h, cy - h], np.c_[cx + h, cy - h], np.c_[cx + h, cy + h],
                        np.c_[cx - h, cy + h]], 1)                       # (k, 4, 2)
    v = np.concatenate([corners, np.full(corners.shape[:2] + (1,), z)], -1).reshape(-1, 3)
    b = 4 * np.arange(len(ix))[:, None]
    f = np.concatenate([b + [0, 1, 2], b + [0, 2, 3]]).astype(np.uint32)
    return v, f


def _set_lines(handle, points: Array, colors) -> None:
    """Assign points with colours of the same length (viser keeps them as parallel arrays)."""
    colors = np.asarray(colors, np.uint8)
    if colors.ndim == 1:
        colors = np.broadcast_to(colors, points.shape).copy()
    handle.points = points
    handle.colors = colors


class PlanScene:
    """The grasp layer of the 3D view. Build it once; then only one thread may call draw_*."""

    def __init__(self, server, robot) -> None:
        self.server, self.robot = server, robot
        scene = server.scene
        empty = np.zeros((1, 2, 3))
        self.circles = scene.add_line_segments("/grasp/plan/circles", empty, CIRCLE_COLOR,
                                               thickness=0.0025, visible=False)
        self.circle_sel = scene.add_line_segments("/grasp/plan/circle_sel", empty,
                                                  CIRCLE_SEL_COLOR, thickness=0.006,
                                                  visible=False)
        self.ghosts = scene.add_line_segments("/grasp/plan/ghosts", empty, GHOST_COLOR,
                                              thickness=0.004, visible=False)
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
        self.labels: dict[str, list[Any]] = {"circles": [], "waypoints": []}
        self.reach: list = []
        self.objects: dict[str, tuple[Any, Any, float]] = {}   # name -> (gizmo, body, radius)
        self._made = 0

    def draw_plan(self, plan: GraspPlan | None, index: int, trail: bool,
                  trail_from: int = 0) -> None:
        """Show ``plan`` (None hides the plan layer); the trail starts at ``trail_from``."""
        handles = (self.circles, self.circle_sel, self.ghosts, self.ghost_sel, self.palms,
                   self.palm_sel, self.capture)
        if plan is None or plan.n == 0:
            for h in handles:
                h.visible = False
            self._draw_labels({"circles": [], "waypoints": []})
            return
        g = plan_geometry(self.robot, plan, index, trail, trail_from)
        _set_lines(self.circles, g["circles"], g["circle_colors"])
        _set_lines(self.circle_sel, g["circle_sel"], CIRCLE_SEL_COLOR)
        if len(g["ghosts"]):
            _set_lines(self.ghosts, g["ghosts"], g["ghost_colors"])
        self.ghosts.visible = len(g["ghosts"]) > 0
        _set_lines(self.ghost_sel, g["ghost_sel"], GHOST_SEL_COLOR)
        self.palms.points = g["palms"]
        self.palms.colors = np.tile(np.array(PALM_COLOR, np.uint8), (len(g["palms"]), 1))
        self.palm_sel.position = tuple(g["palm_sel"])
        self.capture.vertices = g["capture"][0]
        self.capture.visible = g["capture_visible"]
        for h in (self.circles, self.circle_sel, self.ghost_sel, self.palms, self.palm_sel):
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


@dataclasses.dataclass(frozen=True)
class Outcome:
    """Result of the newest planning request: a plan, or the refusal in words."""

    obj: TableObject | None
    plan: GraspPlan | None
    refusal: str | None
    seq: int
    carry_note: str | None = None   # why the plan has no carry to the bin (console.carry_view)


@dataclasses.dataclass(frozen=True)
class SessionView:
    """Consistent snapshot of a session for the panels."""

    objects: tuple[TableObject, ...]
    selected: str | None
    outcome: Outcome | None
    index: int
    playing: bool
    speed: float
    trail: bool
    reach: ReachMap | str | None
    reach_note: str = ""
    trail_from: int = 0     # the trail shows no waypoint before this one ("Clear trails")
    bin: Any = None         # console.table_bin.TableBin: where a row takes the objects, or None
    obstacles: tuple[Obstacle, ...] = ()
    obstacle_selected: str | None = None
    clearance: float = 0.0  # m, the planner keeps the arm this far from every obstacle
    planning_s: float | None = None  # s the running plan has taken so far (None: idle)


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
            body, state = f"<b>{plan.n} waypoints, {plan.total_ms:.1f} ms</b>", "ok"
            if plan.obstacles and plan.obstacle_path_clearance is not None:
                gap = float(np.min(plan.obstacle_path_clearance))
                body += (f"; the arm keeps ≥ {fmt_mm(gap, 0)} mm from the obstacles "
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
