"""The table and plan of a recording as they were at a time, so a replay shows what was run.

A recording holds the table as ``objects`` records (objects, the selected one, obstacles with
the clearance, the bin: :func:`console.recording.lab_feed.feed_grasp`, logged on every change
and when a recording starts) and the planner's newest result as ``plan`` records (approach
circles, waypoints with their curvatures and palm poses; or a refusal). :class:`RecordedScene`
draws the newest of each at a time under its root -- the objects in the Objects panel's
colours, obstacles with their clearance rings, the bin (an open box labelled "Bin"), the
approach circles, the numbered palm points and the arm at the grasp -- and redraws a part only
when its record changes. The live replay (:mod:`console.playback.replay`, into one browser's
scene) and the exported run (:mod:`console.playback.export`) both use it. Bad entries are skipped.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from console.core.table_bin import BIN_COLOR, BIN_HEIGHT, open_box_mesh
from console.recording.timeline import Recording
from console.scene.obstacle_view import draw_recorded_obstacles, recorded_disk
from console.scene.plan_geometry import (CIRCLE_COLOR, GHOST_COLOR, LABEL_GAP, Z_PLAN,
                                         circle_segments, ghost_segments, object_mesh)
from console.scene.plan_view import OBJECT_COLOR, OBJECT_SEL_COLOR, PALM_COLOR
from core.robots import Robot

PATH_COLOR = (235, 130, 30)  # the line through a path's tip points (extensible arm)


def draw_recorded_table(scene: viser.SceneApi, data: dict[str, Any] | None,
                        root: str = "/recorded") -> list[Any]:
    """Draw a recorded ``objects`` record's table under ``root``: the objects (cylinders in the
    Objects panel's colours), the obstacles (``console.scene.obstacle_view``'s look, clearance
    rings included) and the bin (an open box with its label). Returns the nodes."""
    if not data:
        return []
    nodes = draw_recorded_obstacles(scene, data, f"{root}/obstacles")
    for i, o in enumerate(data.get("objects") or []):
        disk = recorded_disk(o)
        if disk is None:
            continue
        x, y, r = disk
        v, f = object_mesh(r)
        color = OBJECT_SEL_COLOR if o.get("name") == data.get("selected") else OBJECT_COLOR
        nodes.append(scene.add_mesh_simple(f"{root}/objects/body_{i}", v, f, color=color,
                                           position=(x, y, 0.0), cast_shadow=False))
    disk = recorded_disk(data.get("bin"))
    if disk is not None:
        x, y, r = disk
        v, f = open_box_mesh(r)
        nodes.append(scene.add_mesh_simple(f"{root}/bin/box", v, f, color=BIN_COLOR,
                                           side="double", position=(x, y, 0.0),
                                           cast_shadow=False))
        nodes.append(scene.add_label(f"{root}/bin/label", "Bin",
                                     position=(x, y, BIN_HEIGHT + 0.01), anchor="bottom-center"))
    return nodes


def _finite(values: Any, n: int) -> np.ndarray | None:
    try:
        a = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    return a if len(a) == n and np.all(np.isfinite(a)) else None


def recorded_palms(data: dict[str, Any]) -> np.ndarray:
    """The plan's palm points (k, 3) at the plan's drawing height (a soft-arm plan: its
    waypoints' palm poses) or its tip points (an extensible path); bad waypoints skipped."""
    pts = []
    for w in data.get("waypoints") or []:
        if not isinstance(w, dict):
            continue
        palm = _finite(w.get("palm"), 3)
        point = _finite(w.get("point"), 3)
        if palm is not None:
            pts.append((palm[0], palm[1], Z_PLAN))
        elif point is not None:
            pts.append(tuple(point))
    return np.array(pts, dtype=float).reshape(-1, 3)


def draw_recorded_plan(scene: viser.SceneApi, robot: Robot, data: dict[str, Any] | None,
                       root: str = "/recorded") -> list[Any]:
    """Draw a recorded ``plan`` record under ``root``/plan: its approach circles, the palm
    points numbered 1..n (the line through them for a path), and the arm at the last
    waypoint (the grasp) when the record has its curvatures. A refusal draws nothing."""
    if not data or data.get("refusal"):
        return []
    nodes: list[Any] = []
    circles = [d for d in (recorded_disk(c) for c in data.get("circles") or []) if d]
    if circles:
        segs = np.concatenate([circle_segments((x, y), [r], Z_PLAN - 0.002)
                               for x, y, r in circles])
        nodes.append(scene.add_line_segments(f"{root}/plan/circles", segs, CIRCLE_COLOR,
                                             thickness=0.0025))
    pts = recorded_palms(data)
    if len(pts):
        nodes.append(scene.add_point_cloud(f"{root}/plan/palms", pts, PALM_COLOR,
                                           point_size=0.012, point_shape="circle"))
        centre = _finite(data.get("center"), 2)
        for k, p in enumerate(pts):
            out = p[:2] - (centre if centre is not None else pts[:, :2].mean(axis=0))
            n = float(np.linalg.norm(out))
            off = out / n * LABEL_GAP if n > 1e-9 else np.zeros(2)
            nodes.append(scene.add_label(f"{root}/plan/label_{k}", f"{k + 1}",
                                         position=(p[0] + off[0], p[1] + off[1], p[2]),
                                         anchor="center-center"))
        if not circles and len(pts) >= 2:
            nodes.append(scene.add_line_segments(
                f"{root}/plan/path", np.stack([pts[:-1], pts[1:]], axis=1), PATH_COLOR,
                thickness=0.003))
    n_seg = getattr(robot, "n_segments", None)
    ways = data.get("waypoints") or []
    last = ways[-1] if ways and isinstance(ways[-1], dict) else {}
    kappa = _finite(last.get("kappa"), n_seg) if isinstance(n_seg, int) else None
    if kappa is not None and hasattr(robot, "gripper"):
        arm = ghost_segments(robot, kappa[None], Z_PLAN)[0]
        nodes.append(scene.add_line_segments(f"{root}/plan/grasp_arm", arm, GHOST_COLOR,
                                             thickness=0.004))
    return nodes


class RecordedScene:
    """The recorded table and plan at a time, drawn under ``root`` of ``scene`` (see the
    module docstring); one thread at a time calls :meth:`show`."""

    def __init__(self, scene: viser.SceneApi, robot: Robot, root: str = "/recorded") -> None:
        self.scene, self.robot, self.root = scene, robot, root
        self.table: dict[str, Any] | None = None
        self.plan: dict[str, Any] | None = None
        self.table_nodes: list[Any] = []
        self.plan_nodes: list[Any] = []

    def changes_at(self, rec: Recording, t: float) -> bool:
        """Whether :meth:`show` at ``t`` would draw something new."""
        return rec.latest("objects", t) is not self.table or rec.latest("plan", t) is not self.plan

    def show(self, rec: Recording, t: float) -> bool:
        """Draw the table and plan recorded at or before ``t``; True if anything changed."""
        table, plan = rec.latest("objects", t), rec.latest("plan", t)
        changed = False
        if table is not self.table:
            for node in self.table_nodes:
                node.remove()
            self.table, self.table_nodes = table, draw_recorded_table(self.scene, table,
                                                                      self.root)
            changed = True
        if plan is not self.plan:
            for node in self.plan_nodes:
                node.remove()
            self.plan, self.plan_nodes = plan, draw_recorded_plan(self.scene, self.robot, plan,
                                                                  self.root)
            changed = True
        return changed

    def clear(self) -> None:
        """Remove every node (another recording is loaded)."""
        for node in self.table_nodes + self.plan_nodes:
            node.remove()
        self.table = self.plan = None
        self.table_nodes, self.plan_nodes = [], []
