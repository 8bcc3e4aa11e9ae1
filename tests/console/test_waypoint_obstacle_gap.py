"""The Waypoints panel tells each waypoint's gap to the obstacles: seen in a walk through the
console, a plan passing 12 mm from an obstacle listed only "clearance 78.9 mm (path >= 75.4 mm)",
which is the gap to the object, next to the Grasp planner's obstacle *Clearance (mm)*."""

from __future__ import annotations

import numpy as np

from console.panels.soft_arm.waypoints import waypoint_html
from console.core.grasp_state import Outcome, SessionView
from console.core.table_scene import TableObject
from core.kinematics import planar
from core.planning.obstacles import Obstacle
from core.planning.sides import plan_grasp_sided
from core.robots import load

ROBOT = load("soft-arm")


def view_of(plan, index: int) -> SessionView:
    obj = TableObject("Object 1", -0.2, 0.2, 0.0165)
    return SessionView((obj,), "Object 1", Outcome(obj, plan, None, 1), index, False, 1.0, True,
                       None)


def test_each_waypoint_lists_its_gap_to_the_obstacles() -> None:
    post = Obstacle("Obstacle 1", -0.062, 0.188, 0.02)
    plan = plan_grasp_sided(ROBOT, np.zeros(6), (-0.2, 0.2), 0.0165, obstacles=(post,),
                            clearance=0.01)
    k = plan.n - 1
    html = waypoint_html(view_of(plan, k))
    # Independent: the arm's backbone (half-width) at the waypoint, densely sampled.
    bb = planar.sample_backbone(plan.kappas[k], ROBOT.lengths, 400, ROBOT.base_pose)
    body = np.hypot(bb[:, 0] - post.x, bb[:, 1] - post.y).min() - ROBOT.half_width - post.r
    gap = plan.obstacle_clearance[k]
    assert gap <= body + 1e-6  # the gripper may come closer than the body
    assert f"<td style='padding-right:6px'>to obstacles</td><td>{gap * 1e3:.1f} mm (path ≥ " \
        f"{plan.obstacle_path_clearance[k] * 1e3:.1f} mm; keeps 10 mm)</td>" in html, html
    assert "<td style='padding-right:6px'>to the object</td>" in html
    plain = plan_grasp_sided(ROBOT, np.zeros(6), (-0.2, 0.2), 0.0165)
    assert "to obstacles" not in waypoint_html(view_of(plain, 0))  # no obstacles: no row
