"""How long a grasp-and-place still takes, and which plan the arm is executing, for the screen.

The operator sees an estimate before Execute and the remaining time while the arm runs
(issue 31.3). Both come from the plan alone: the reference trajGen moves along
(:class:`core.control.trajectory.TrajectoryGenerator`) is ruckig's time-optimal, jerk-limited
rest-to-rest motion under the robot's ``[trajectory]`` limits, so each leg (now -> waypoint 1 ->
... -> the last waypoint -> the carry's targets -> the bin) is timed by ruckig offline, and the
state machine's fixed waits (``settle_time_s`` before a plan, ``grasp_time_s``,
``release_time_s``) are added. The arm lags its reference and ``pass_over`` passes intermediate
waypoints early, so the estimate is an estimate: ``tests/core/test_run_estimate.py`` states the
factor it keeps to a simulated run.

:class:`ExecutingPlan` is the plan the loop's state machine executes (its waypoints, palm points,
object and carry), built by :func:`executing_plan` in the loop process and published with the
loop's view, so the console draws the plan the ARM runs, never its own guess.

Pure: no threads, no I/O, no clock (times are computed, never measured).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

from core.control.carry import plan_side
from core.robots import SoftArm

Array = npt.NDArray[np.float64]

PLANNING_S = 2.5  # what a first plan takes in the planner process (issue 31: "click-to-plan ~2.5 s")


@dataclasses.dataclass(frozen=True)
class ExecutingPlan:
    """The plan the loop's state machine executes, as published to the console.

    Attributes:
        kappas: (n, N) waypoint curvatures, 1/m.
        palms: (n, 3) palm poses (x, y, heading), m and rad.
        center: The object's centre the plan was made for (x, y), m.
        carry: (m, N) the targets of the carry to the bin, the bin pose last.
        replans: How many times the machine re-planned (0: the first plan).
        started_t: Loop time (s) the task began (its settling, or the given plan's start).
    """

    kappas: Array
    palms: Array
    center: tuple[float, float]
    carry: Array
    replans: int = 0
    started_t: float = 0.0

    @property
    def n(self) -> int:
        """Number of waypoints."""
        return int(self.kappas.shape[0])

    def same_waypoints(self, kappas: npt.ArrayLike | None, tol: float = 1e-9) -> bool:
        """Whether ``kappas`` (a plan's waypoints) are this plan's."""
        if kappas is None:
            return False
        k = np.asarray(kappas, float)
        return k.shape == self.kappas.shape and bool(np.all(np.abs(k - self.kappas) <= tol))


def executing_plan(machine: Any) -> ExecutingPlan | None:
    """The plan ``machine`` (a :class:`core.control.grasp_place.GraspAndPlace`) executes now,
    or None while it has none (idle, settling, planning)."""
    plan, center = machine.plan, machine.plan_center
    if plan is None or center is None:
        return None
    kappas = np.atleast_2d(np.asarray(plan.kappas, float))
    if kappas.size == 0:
        return None
    carry = machine.carry.targets if machine.carry is not None else getattr(plan, "carry", None)
    if carry is None:
        carry = machine.bin.kappa_for(plan_side(plan, center))
    events = machine.events
    started = float(events[0][0]) if events else float(machine.times.get("start", 0.0))
    return ExecutingPlan(kappas.copy(), np.asarray(plan.palm_poses, float).copy(),
                         (float(center[0]), float(center[1])),
                         np.atleast_2d(np.asarray(carry, float)).copy(), int(machine.replans),
                         started)


class LegTimer:
    """Times rest-to-rest reference motions with the robot's trajGen limits (ruckig offline).

    Args:
        robot: The soft arm (its ``[trajectory]`` limits).
    """

    def __init__(self, robot: SoftArm) -> None:
        self.limits = robot.trajectory
        self.n = len(self.limits.max_velocity)

    def leg(self, a: npt.ArrayLike, b: npt.ArrayLike) -> float:
        """Seconds of the reference's rest-to-rest motion from ``a`` to ``b`` (1/m)."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        if np.max(np.abs(a - b)) < 1e-9:
            return 0.0
        # ruckig's objects live only for this call: none is left for the interpreter's
        # teardown (where nanobind reports them as leaked).
        lim, n = self.limits, self.n
        inp, traj = InputParameter(n), Trajectory(n)
        inp.max_velocity = lim.max_velocity.tolist()
        inp.max_acceleration = lim.max_acceleration.tolist()
        inp.max_jerk = lim.max_jerk.tolist()
        inp.synchronization = (Synchronization.Phase if lim.synchronization == "phase"
                               else Synchronization.Time)
        inp.current_position = a.tolist()
        inp.current_velocity = [0.0] * n
        inp.current_acceleration = [0.0] * n
        inp.target_position = b.tolist()
        inp.target_velocity = [0.0] * n
        inp.target_acceleration = [0.0] * n
        result = Ruckig(n).calculate(inp, traj)
        if result not in (Result.Working, Result.Finished):
            raise ValueError("no trajectory between these curvatures")
        return float(traj.duration)

    def path(self, start: npt.ArrayLike, targets: Sequence[npt.ArrayLike] | Array) -> float:
        """Seconds through ``targets`` one after another from ``start``, resting at each."""
        total, at = 0.0, np.asarray(start, float)
        for q in np.atleast_2d(np.asarray(targets, float)) if len(targets) else ():
            total += self.leg(at, q)
            at = q
        return total


def remaining_seconds(robot: SoftArm, timer: LegTimer, phase: str,
                      kappa_now: npt.ArrayLike | None, plan: ExecutingPlan | None,
                      waypoint: int = 0) -> float | None:
    """Estimated seconds until the object is released, from ``phase`` (the machine's), the arm's
    curvatures now and the plan it executes (waypoint ``waypoint``, 0-based, is the next one);
    0 when it is done (idle, released, stopped); None when it is planning without a plan yet
    the estimate is only the fixed waits and is not known (no plan: nothing to time)."""
    sm = robot.state_machine
    if phase in ("idle", "released", "stopped"):
        return 0.0
    if phase == "release":
        return sm.release_time_s
    if plan is None or kappa_now is None:
        return None
    now = np.asarray(kappa_now, float)
    tail = sm.grasp_time_s + sm.release_time_s
    if phase == "move_to_bin":
        return timer.path(now, plan.carry) + sm.release_time_s
    if phase == "grasp":
        return timer.path(now, plan.carry) + tail
    k = min(max(int(waypoint), 0), plan.n - 1) if phase == "approach" else 0
    approach = timer.path(now, plan.kappas[k:])
    return approach + sm.grasp_time_s + timer.leg(plan.kappas[-1], plan.carry[0]) + \
        timer.path(plan.carry[0], plan.carry[1:]) + sm.release_time_s


def plan_seconds(robot: SoftArm, timer: LegTimer, kappa_now: npt.ArrayLike,
                 kappas: npt.ArrayLike, carry: npt.ArrayLike, planned: bool = True) -> float:
    """Estimated seconds of a whole grasp-and-place from the arm at ``kappa_now``: through the
    waypoints ``kappas`` (n, N), the grasp, the carry's targets ``carry`` (the bin last) and the
    release. ``planned=False`` (the controller plans the approach itself) adds the settle time
    and :data:`PLANNING_S` before it."""
    sm = robot.state_machine
    k = np.atleast_2d(np.asarray(kappas, float))
    c = np.atleast_2d(np.asarray(carry, float))
    total = (timer.path(kappa_now, k) + sm.grasp_time_s + timer.path(k[-1], c)
             + sm.release_time_s)
    return total if planned else total + sm.settle_time_s + PLANNING_S
