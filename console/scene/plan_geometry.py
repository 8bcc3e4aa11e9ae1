"""What the grasp layer of the 3D view draws, as pure geometry, so it is tested without a server.

Approach circles and their colours, ghost arms of the waypoints with the fading trail, palm
points and their labels, the gripper's capture region, object cylinders, reachability quads
and where a click ray meets the table. :class:`console.scene.plan_view.PlanScene` puts them on
scene nodes (and re-exports every name here).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.kinematics import planar as pk
from core.planning.plan_types import GraspPlan
from core.planning.reachability import ReachMap
from core.units import fmt_mm

Array = npt.NDArray[np.float64]
Z_PLAN = 0.03                       # plan drawings float above the arm tube
CIRCLE_COLOR, FAIL_COLOR = (40, 170, 70), (215, 45, 45)
GHOST_COLOR = (120, 140, 170)
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
    side = -1.0 if plan.side == "right" else 1.0
    left = np.array([-math.sin(final[2]), math.cos(final[2])])
    aim = final[:2] + side * left * (robot.gripper.g_off + robot.capture.nominal_object_radius)
    ghost_colors = np.repeat(trail_colors(shown, index), ghosts.shape[1], 0)
    return {
        "circles": circles, "circle_colors": np.repeat(circle_colors[:, None], 2, 1),
        "circle_ok": np.repeat(ok, per),                # which segments' circle is not failed
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
