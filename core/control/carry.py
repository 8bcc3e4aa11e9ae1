"""The carry to the bin keeps the obstacles' clearance, like the approach: planned with the grasp
(in the planning process, never in the 100 Hz loop) and followed target by target.

* :func:`with_carry` -- a plan with its ``carry`` filled in: the certified targets from the
  grasp pose to the bin pose (:func:`core.planning.clear_path.clear_path`) for the arm, the
  gripper and the held object (a disk of the grasped radius at the closing finger). Raises
  :class:`~core.planning.clear_path.ClearPathRefused` (a ``GraspRefused``) when the bin pose
  is too close to an obstacle or no clear motion is found, so the task stops before it moves.
* :class:`CarryFollower` -- ``move_to_bin``'s targets one after another: the next is sent
  once the reference rests at the current one (ruckig, phase-synchronised: straight lines in
  kappa, the lines that were certified) and the arm is within ``tolerance`` of it.
* :func:`bin_refusal`, :func:`check_bin` -- why a bin pose is too close to the obstacles, for
  a refusal before a task or a row starts.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel
from core.planning.clear_path import (ClearPathProblem, ClearPathRefused, HeldObject, clear_path,
                                      too_close)
from core.planning.obstacles import GripperShape

Array = npt.NDArray[np.float64]

CARRY_BUDGET_S = 1.5    # s of search for a carry that cannot go straight
CARRY_PAD = 0.003       # m the plan keeps beyond the clearance, for the arm's tracking error


def _model(robot: Any) -> tuple[ArmModel, GripperShape]:
    return ArmModel.from_robot(robot), GripperShape.from_robot(robot)


def plan_side(plan: Any, center: npt.ArrayLike | None) -> str:
    """The finger a plan grasps with: its ``side``, else read from its final palm pose (the
    object centre lies on the closing finger's side of it)."""
    side = getattr(plan, "side", None)
    if side is None and plan is not None and center is not None:
        pose = np.asarray(plan.palm_poses, dtype=float)[-1]
        d = np.asarray(center, float) - pose[:2]
        return "right" if math.cos(pose[2]) * d[1] - math.sin(pose[2]) * d[0] < 0 else "left"
    return "right" if side == "right" else "left"


def with_carry(robot: Any, plan: Any, req: Any) -> Any:
    """``plan`` with ``carry`` = the certified targets from its grasp pose to ``req.bin``'s
    pose for its finger, around ``req.obstacles`` keeping ``req.clearance`` (the held object
    of ``req.radius`` included). The approach, backwards, is tried first as vias."""
    model, gripper = _model(robot)
    side = plan_side(plan, req.center)
    kappas = np.asarray(plan.kappas, float)
    start, goal = kappas[-1], np.asarray(req.bin.kappa_for(side), float)
    problem = ClearPathProblem(model, gripper, req.obstacles, req.clearance, CARRY_PAD,
                               HeldObject.at_finger(robot, req.radius, side), start)
    back = list(kappas[-2::-1])
    meas = getattr(plan, "kappa_meas", None)
    if meas is not None:
        back.append(np.asarray(meas, float))
    try:
        path = clear_path(problem, start, goal, budget_s=CARRY_BUDGET_S,
                          goal_name="the bin pose", hints=back)
    except ClearPathRefused as exc:
        raise ClearPathRefused(f"Carry to the bin: {exc}", exc.obstacle) from None
    return dataclasses.replace(plan, carry=path.vias.copy())


def bin_refusal(robot: Any, bin_kappa: npt.ArrayLike, obstacles: Any,
                clearance: float) -> str | None:
    """Why the arm and gripper at the bin pose ``bin_kappa`` are closer than ``clearance``
    to an obstacle (None when they are not, or without obstacles)."""
    if not obstacles:
        return None
    model, gripper = _model(robot)
    problem = ClearPathProblem(model, gripper, tuple(obstacles), float(clearance))
    why = too_close(problem, np.asarray(bin_kappa, float), "the bin pose")
    return None if why is None else why[0]


def check_bin(robot: Any, bin_params: Any, obstacles: Any, clearance: float) -> None:
    """Raise ValueError with :func:`bin_refusal`'s reason when either finger's bin pose of
    ``bin_params`` (``BinParams``) is too close to an obstacle."""
    for side in ("left", "right") if obstacles else ():
        why = bin_refusal(robot, bin_params.kappa_for(side), obstacles, clearance)
        if why:
            raise ValueError(why)


class CarryFollower:
    """``move_to_bin``'s targets (m, N), the bin pose last, handed out one at a time."""

    def __init__(self, targets: npt.ArrayLike):
        self.targets = np.atleast_2d(np.asarray(targets, float))
        self.index = 0

    @property
    def target(self) -> Array:
        return self.targets[self.index]

    @property
    def last(self) -> bool:
        return self.index >= len(self.targets) - 1

    def advance(self, kappa: Array, reference_finished: bool, tolerance: float) -> Array | None:
        """The next target once the reference rests at this one and the arm is within
        ``tolerance`` (1/m, every segment) of it; None otherwise (or at the last)."""
        if self.last or not reference_finished:
            return None
        if float(np.max(np.abs(np.asarray(kappa, float) - self.target))) > tolerance:
            return None
        self.index += 1
        return self.target
