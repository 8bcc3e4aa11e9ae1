"""The carry to the bin of a final grasp plan, planned headless so the session owns it and the
3D view (:mod:`console.scene.carry_view`) only draws it.

With obstacles and a bin on the table, a final plan (Plan grasp, a release after a drag) also
gets its certified carry (:func:`core.control.carry.with_carry`: via shapes from the grasp pose
to the bin pose that keep the arm, gripper and held object clear). Live plans while dragging
skip it (up to :data:`core.control.carry.CARRY_BUDGET_S` of search).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from console.core.table_bin import TableBin
from console.core.table_scene import TableObject
from core.control.carry import with_carry
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import Obstacle


class _CarryRequest:
    """What :func:`core.control.carry.with_carry` reads of a ``PlanRequest``."""

    def __init__(self, center: Sequence[float], radius: float, obstacles: Sequence[Obstacle],
                 clearance: float, table_bin: TableBin) -> None:
        self.center = np.asarray(center, float)
        self.radius = float(radius)
        self.obstacles = tuple(obstacles)
        self.clearance = float(clearance)
        self.bin = table_bin.params()


def plan_carry(robot: Any, plan: Any, obj: TableObject, table_bin: TableBin | None,
               obstacles: Sequence[Obstacle], clearance: float) -> tuple[Any, str | None]:
    """A plan with its carry to the bin.

    Args:
        robot: The soft arm (``core.robots.SoftArm``).
        plan: The grasp plan (``core.planning.plan_types.GraspPlan``) or None.
        obj: The object the plan grasps.
        table_bin: Where the carry ends (None: no carry).
        obstacles: What the carry keeps ``clearance`` (m) from.
        clearance: The clearance, m.

    Returns:
        ``(plan with its carry, None)``; or ``(plan unchanged, why there is no carry)`` (the
        grasp itself stays valid). No obstacles, no bin or a failed plan: ``(plan, None)``.
    """
    if not obstacles or table_bin is None or plan is None or not plan.success:
        return plan, None
    try:
        return with_carry(robot, plan, _CarryRequest((obj.x, obj.y), obj.r, obstacles,
                                                     clearance, table_bin)), None
    except GraspRefused as exc:
        return plan, str(exc)
