"""The carry to the bin in the plan view, so the operator sees where the held object will go.

With obstacles and a bin on the table, a final plan (Plan grasp, a release after a drag) also
gets its certified carry (:func:`console.core.grasp_carry.plan_carry`,
:func:`core.control.carry.with_carry`: via shapes
from the grasp pose to the bin pose that keep the arm, gripper and held object clear). Live
plans while dragging skip it (up to :data:`core.control.carry.CARRY_BUDGET_S` of search).

:class:`CarryLayer` draws it in :data:`CARRY_COLOR` (teal, the bin's family): the palm's path,
sampled along the certified straight lines in curvature (one line-segments node), a dot at the
palm of each carry target (vias, then the bin pose) and faint ghost arms at those targets. A
straight carry (no vias) shows the straight path and the arm over the bin; no carry (no
obstacles or no bin) shows nothing. All nodes are made once and updated in place.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from console.scene.line_nodes import FixedLines
from console.scene.plan_view import Z_PLAN, ghost_segments
from core.control.carry import plan_side
from core.planning.plan_types import GraspPlan
from core.kinematics import planar as pk

Array = npt.NDArray[np.float64]
CARRY_COLOR = (0, 135, 145)          # teal: where the object goes, like the bin
CARRY_GHOST_COLOR = (95, 180, 180)   # lighter and thin: the arm at each carry target
Z_CARRY = Z_PLAN + 0.002             # over the approach's ghost arms where they cross
PATH_SAMPLES = 12                    # palm points per certified line of the carry


def palm_points(robot: Any, plan: GraspPlan, kappas: npt.ArrayLike) -> Array:
    """Palm points (k, 2) of configurations ``kappas`` (k, N) with the gripper straight, on
    the plan's closing side (the point the plan's ``palm_poses`` hold)."""
    k = np.atleast_2d(np.asarray(kappas, float))
    tip = pk.forward_kinematics(k, robot.lengths, robot.base_pose)[:, -1]
    g = robot.gripper
    side = -1.0 if plan_side(plan, plan.center) == "right" else 1.0
    return pk.point_in_frame(tip, (g.w_off_along, side * g.g_off))


def carry_geometry(robot: Any, plan: GraspPlan | None) -> dict[str, Array] | None:
    """What :class:`CarryLayer` draws for ``plan`` (None: no carry): ``targets`` (m, 3) the
    palm at each carry target, ``path`` (S, 2, 3) the palm's path from the grasp pose along
    the certified lines, ``ghosts`` (G, 2, 3) the arm at each target."""
    if plan is None or plan.carry is None or len(plan.carry) == 0:
        return None
    carry = plan.carry
    carry = np.atleast_2d(np.asarray(carry, float))
    shapes = np.vstack([np.asarray(plan.kappas, float)[-1:], carry])      # grasp, then targets
    t = np.linspace(0.0, 1.0, PATH_SAMPLES + 1)[1:, None, None]
    legs = shapes[:-1][None] + t * (shapes[1:] - shapes[:-1])[None]       # (S, m, N)
    along = np.vstack([shapes[:1], legs.transpose(1, 0, 2).reshape(-1, shapes.shape[1])])
    path = np.c_[palm_points(robot, plan, along), np.full(len(along), Z_CARRY)]
    return {
        "targets": np.c_[palm_points(robot, plan, carry), np.full(len(carry), Z_CARRY)],
        "path": np.stack([path[:-1], path[1:]], 1),
        "ghosts": ghost_segments(robot, carry, Z_PLAN - 0.001).reshape(-1, 2, 3),
    }


class CarryLayer:
    """The carry's scene nodes (``/grasp/plan/carry_*``); only the grasp layers
    (:class:`console.scene.grasp_layers.GraspSceneView`) draw into it."""

    def __init__(self, server: Any, robot: Any) -> None:
        self.robot = robot
        scene = server.scene
        arm = ghost_segments(robot, np.zeros((1, robot.n_segments)), 0.0).shape[1]
        self._ghosts = FixedLines(scene, "/grasp/plan/carry_ghosts", CARRY_GHOST_COLOR, 0.0025,
                                  4 * arm)
        self._path = FixedLines(scene, "/grasp/plan/carry_path", CARRY_COLOR, 0.008,
                                4 * PATH_SAMPLES)
        self.targets = scene.add_point_cloud("/grasp/plan/carry_targets", np.zeros((1, 3)),
                                             CARRY_COLOR, point_size=0.012,
                                             point_shape="circle", visible=False)

    @property
    def ghosts(self) -> Any:
        return self._ghosts.handle

    @property
    def path(self) -> Any:
        return self._path.handle

    def draw(self, plan: GraspPlan | None) -> None:
        """Show ``plan``'s carry; hide the layer when it has none (or ``plan`` is None)."""
        g = carry_geometry(self.robot, plan)
        if g is None:
            for h in (self.ghosts, self.path, self.targets):
                h.visible = False
            return
        self._ghosts.show(g["ghosts"])
        self._path.show(g["path"])
        self.targets.points = g["targets"]
        self.targets.visible = True
