"""The grasp-and-place state machine of Fig. 3 as a pure step function (§4.2, §5.2).

settling (object still for 2 s) -> planning (``plan_grasp``, injectable and asynchronous) ->
approach (waypoint by waypoint) -> grasp (close the gripper) -> move_to_bin -> release (palm
within 1 cm of the bin) -> released. Failures re-plan or stop, always with a stated reason:

* waypoint not reached ``waypoint_timeout_s`` after the reference arrived -> re-plan from the
  measured configuration (at most ``max_replans`` times, then stop);
* object moved more than ``object_moved_m`` from the planned centre -> hold, wait until it
  settles, re-plan;
* tracking lost (markers occluded) -> freeze the cylinders; stop after ``tracking_timeout_s``;
* object not in the gripper after grasping or lost on the way -> open, re-plan;
* planner refused (object infeasible) or failed, bin (or a carry target) not reached
  ``move_timeout_s`` after the reference arrived -> stop.

STOP (:meth:`GraspAndPlace.stop`) freezes the cylinder volumes, which holds the arm's shape.

The planner is a callable ``PlanRequest -> handle`` where the handle has ``done()`` and
``result()`` (a :class:`concurrent.futures.Future` qualifies), so the loop runner can plan in
another process while this machine keeps ticking; :func:`immediate` wraps a synchronous call.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.control.carry import CarryFollower, check_bin, plan_side
from core.control.grasp_place_types import (MOVING, Decision, Observation, Phase, PlanHandle,
                                            Planner, PlanRequest, WaypointPlan, immediate)
from core.control.params import BinParams, StateMachineParams
from core.control.fastkin import fk, point_in_pose
from core.robots import SoftArm

__all__ = ["MOVING", "Decision", "GraspAndPlace", "Observation", "Phase", "PlanHandle", "Planner",
           "PlanRequest", "WaypointPlan", "immediate"]

Array = npt.NDArray[np.float64]


class GraspAndPlace:
    """Fig. 3 state machine. Call :meth:`step` once per control period.

    Args:
        robot: The soft arm (kinematics for palm positions).
        params: Thresholds and timeouts (``StateMachineParams.from_robot``).
        bin_params: The bin configuration (``BinParams.from_robot``).
        planner: ``PlanRequest -> handle``; see module docstring.
    """

    def __init__(self, robot: SoftArm, params: StateMachineParams, bin_params: BinParams,
                 planner: Planner):
        self.robot, self.p, self.bin, self.planner = robot, params, bin_params, planner
        self._lengths = robot.lengths.tolist()
        self.obstacles: tuple[Any, ...] = ()
        self.clearance = 0.0
        self.reset()

    @classmethod
    def from_robot(cls, robot: SoftArm, planner: Planner) -> "GraspAndPlace":
        return cls(robot, StateMachineParams.from_robot(robot), BinParams.from_robot(robot), planner)

    # -- operator commands ---------------------------------------------------------------------
    def set_obstacles(self, obstacles: Any = (), clearance: float = 0.0) -> None:
        """The obstacles (``core.planning.obstacles.Obstacle``) every plan this machine asks for
        -- the first and every re-plan -- keeps ``clearance`` (m) from; kept until set again.

        Raises ValueError (nothing changes) for a clearance that is not a finite number >= 0.
        """
        clearance = float(clearance)
        if not (math.isfinite(clearance) and clearance >= 0.0):
            raise ValueError(f"clearance must be a finite distance >= 0 m, got {clearance!r}")
        self.obstacles, self.clearance = tuple(obstacles), clearance

    def _request(self, kappa: Array, center: Array, radius: float) -> PlanRequest:
        return PlanRequest(kappa.copy(), center.copy(), float(radius), self.obstacles,
                           self.clearance, self.bin if self.obstacles else None, self._given)

    def reset(self) -> None:
        """Back to idle; forget plan, counters and times."""
        self.phase = Phase.IDLE
        self.reason: str | None = None
        self.plan: Any = None
        self.plan_center: Array | None = None
        self.waypoint = 0
        self.replans = 0
        self.gripper_closed = False
        self.times: dict[str, float] = {}
        self.events: list[tuple[float, str]] = []
        self._handle: PlanHandle | None = None
        self._since = 0.0
        self._anchor: Array | None = None
        self._anchor_t = 0.0
        self._anchor_sum = np.zeros(2)
        self._anchor_n = 0
        self._lost_since: float | None = None
        self._ref_done_since: float | None = None
        self._grip_rel: Array | None = None
        self._pending: Decision | None = None
        self._given: Any = None     # an executed plan whose carry is being planned
        self.carry: CarryFollower | None = None

    def start(self, t: float) -> None:
        """Run the full grasp-and-place: wait for the object to settle, plan, execute.

        Raises ValueError (nothing changes) when the bin pose is too close to an obstacle."""
        self._check_bin()
        self.reset()
        self._enter(Phase.SETTLING, t, "start")

    def execute(self, plan: Any, center: npt.ArrayLike, t: float) -> None:
        """Run a given plan (approach, grasp, place) for the object at ``center``. With
        obstacles and no ``carry`` in the plan its carry is planned first (the arm holds).

        Raises ValueError (nothing changes) when the bin pose is too close to an obstacle."""
        self._check_bin()
        self.reset()
        self.plan, self.plan_center = plan, np.asarray(center, dtype=float)
        self.times["start"] = t
        if self.obstacles and getattr(plan, "carry", None) is None:
            self._given, self.plan = plan, None
            self._enter(Phase.PLANNING, t, "planning the carry to the bin")
            return
        self._pending = self._begin_approach(t)  # the first step() hands out the first target

    def _check_bin(self) -> None:
        check_bin(self.robot, self.bin, self.obstacles, self.clearance)

    def stop(self, t: float, reason: str = "operator STOP") -> None:
        """Freeze the arm where it is (cylinder volumes held) with a reason."""
        self._stop(t, reason)

    # -- helpers -------------------------------------------------------------------------------
    def _enter(self, phase: Phase, t: float, why: str) -> None:
        self.phase = phase
        self._since = t
        self._ref_done_since = None
        self.events.append((t, f"{phase.value}: {why}"))

    def _stop(self, t: float, reason: str) -> Decision:
        self.reason = reason
        self._handle = None
        self._enter(Phase.STOPPED, t, reason)
        self._pending = Decision(Phase.STOPPED, freeze=True, gripper_closed=self.gripper_closed,
                                 reason=reason)
        return self._pending

    @property
    def closing_side(self) -> str:
        """The finger the plan grasps with: ``left`` (the paper's) or ``right``.

        A plan without a ``side`` (a :class:`WaypointPlan` sent by the console) is read from
        its final palm pose: the object centre lies on the closing finger's side of it.
        """
        return plan_side(self.plan, self.plan_center)

    def _side_sign(self) -> float:
        return -1.0 if self.closing_side == "right" else 1.0

    def palm(self, kappa: npt.ArrayLike) -> Array:
        """Palm point [x, y] of a configuration (gripper straight), on the plan's side."""
        tip = fk(kappa, self._lengths, self.robot.base_pose)[-1]
        g = self.robot.gripper
        return np.array(point_in_pose(tip, g.w_off_along, self._side_sign() * g.g_off))

    def _to_gripper(self, kappa: Array, xy: Array) -> Array:
        tip = fk(kappa, self._lengths, self.robot.base_pose)[-1]
        d = xy - tip[:2]
        c, s = math.cos(tip[2]), math.sin(tip[2])
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

    def _settle_reset(self, xy: Array | None, t: float) -> None:
        self._anchor = None if xy is None else xy.copy()
        self._anchor_t = t
        self._anchor_sum = np.zeros(2) if xy is None else xy.copy()
        self._anchor_n = 0 if xy is None else 1

    def _replan(self, t: float, why: str, settle: bool) -> Decision:
        if self.replans >= self.p.max_replans:
            return self._stop(t, f"{why}; gave up after {self.replans} re-plans")
        self.replans += 1
        self._given = None
        self.events.append((t, f"re-plan {self.replans}: {why}"))
        self.plan = None
        self._settle_reset(None, t)
        self._enter(Phase.SETTLING if settle else Phase.PLANNING, t, why)
        return Decision(self.phase, hold_reference=True, gripper_closed=self.gripper_closed)

    def _begin_approach(self, t: float) -> Decision:
        kappas = np.asarray(self.plan.kappas, dtype=float)
        if kappas.ndim != 2 or kappas.shape[0] == 0 or kappas.shape[1] != self.robot.n_segments:
            return self._stop(t, f"plan has no usable waypoints (shape {kappas.shape})")
        self.times.setdefault("approach_start", t)
        self.waypoint = 0
        self._enter(Phase.APPROACH, t, f"waypoint 1/{kappas.shape[0]}")
        return Decision(Phase.APPROACH, kappa_target=kappas[0])

    # -- the step ------------------------------------------------------------------------------
    def step(self, obs: Observation) -> Decision:
        """Advance by one control period and say what the controller should do."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            return pending
        t = obs.t
        if self.phase in (Phase.IDLE, Phase.RELEASED):
            return Decision(self.phase, gripper_closed=self.gripper_closed)
        if self.phase is Phase.STOPPED:
            return Decision(Phase.STOPPED, freeze=True, gripper_closed=self.gripper_closed,
                            reason=self.reason)
        if obs.kappa is None:
            if self._lost_since is None:
                self._lost_since = t
            if t - self._lost_since >= self.p.tracking_timeout_s:
                return self._stop(t, f"tracking lost for {t - self._lost_since:.2f} s")
            return Decision(self.phase, freeze=True, gripper_closed=self.gripper_closed,
                            reason="tracking lost: holding")
        self._lost_since = None
        handler = getattr(self, f"_on_{self.phase.value}")
        return handler(obs, t)

    def _on_settling(self, obs: Observation, t: float) -> Decision:
        xy = obs.object_xy
        if xy is None or obs.object_radius is None:
            self._settle_reset(None, t)
            return Decision(Phase.SETTLING, hold_reference=True, gripper_closed=self.gripper_closed,
                            reason="waiting for the object")
        if self._anchor is None or np.hypot(*(xy - self._anchor)) > self.p.settle_tolerance_m:
            self._settle_reset(xy, t)
        else:
            self._anchor_sum += xy
            self._anchor_n += 1
        if t - self._anchor_t + 1e-9 < self.p.settle_time_s:
            return Decision(Phase.SETTLING, gripper_closed=self.gripper_closed)
        center = self._anchor_sum / self._anchor_n
        self.plan_center = center
        self._enter(Phase.PLANNING, t, f"object settled at ({center[0]:.3f}, {center[1]:.3f})")
        self._handle = self.planner(self._request(obs.kappa, center, float(obs.object_radius)))
        self.times.setdefault("start", t)
        return self._on_planning(obs, t)

    def _on_planning(self, obs: Observation, t: float) -> Decision:
        if self._handle is None:  # re-plan without settling: ask now
            if self.plan_center is None or obs.object_radius is None:
                return self._replan(t, "no object to plan for", settle=True)
            self._handle = self.planner(self._request(obs.kappa, self.plan_center,
                                                      float(obs.object_radius)))
        if obs.object_xy is not None and self.plan_center is not None and \
                np.hypot(*(obs.object_xy - self.plan_center)) > self.p.object_moved_m:
            self._handle = None
            return self._replan(t, "object moved while planning", settle=True)
        if not self._handle.done():
            return Decision(Phase.PLANNING, hold_reference=True, gripper_closed=self.gripper_closed)
        handle, self._handle = self._handle, None
        self._given = None
        try:
            self.plan = handle.result()
        except Exception as exc:  # noqa: BLE001 - every planner failure becomes a stated reason
            refused = any(c.__name__ == "GraspRefused" for c in type(exc).__mro__)
            kind = "refused" if refused else "failed"
            return self._stop(t, f"planner {kind}: {exc}")
        return self._begin_approach(t)

    def _object_moved(self, obs: Observation) -> bool:
        return (obs.object_xy is not None and self.plan_center is not None
                and float(np.hypot(*(obs.object_xy - self.plan_center))) > self.p.object_moved_m)

    def _on_approach(self, obs: Observation, t: float) -> Decision:
        if self._object_moved(obs):
            moved = float(np.hypot(*(obs.object_xy - self.plan_center)))
            return self._replan(t, f"object moved {moved * 1000:.0f} mm during approach", settle=True)
        kappas = np.asarray(self.plan.kappas, dtype=float)
        n = kappas.shape[0]
        err = float(np.max(np.abs(obs.kappa - kappas[self.waypoint])))
        last = self.waypoint == n - 1
        if last:
            palm_err = float(np.hypot(*(self.palm(obs.kappa) - np.asarray(self.plan.palm_poses)[-1][:2])))
            arrived = err <= self.p.final_dkappa and palm_err <= self.p.grasp_position_tol_m
        else:
            arrived = err <= (self.p.pass_dkappa if self.p.pass_over else self.p.advance_dkappa)
        if arrived and last:
            self.times["grasp_start"] = t
            self.gripper_closed = True
            self._enter(Phase.GRASP, t, "at the object")
            return Decision(Phase.GRASP, hold_reference=True, gripper_closed=True)
        if arrived:
            self.waypoint += 1
            self._enter(Phase.APPROACH, t, f"waypoint {self.waypoint + 1}/{n}")
            return Decision(Phase.APPROACH, kappa_target=kappas[self.waypoint])
        if self._timed_out(obs, t):
            return self._replan(t, f"waypoint {self.waypoint + 1}/{n} not reached "
                                   f"(max |dkappa| {err:.2f} 1/m)", settle=False)
        return Decision(Phase.APPROACH)

    def _timed_out(self, obs: Observation, t: float, limit_s: float | None = None) -> bool:
        """True once the reference has rested at its target for ``limit_s`` (default
        ``waypoint_timeout_s``) without the arm arriving."""
        if not obs.reference_finished:
            self._ref_done_since = None
            return False
        if self._ref_done_since is None:
            self._ref_done_since = t
        return t - self._ref_done_since >= (self.p.waypoint_timeout_s if limit_s is None
                                            else limit_s)

    def _on_grasp(self, obs: Observation, t: float) -> Decision:
        if t - self._since < self.p.grasp_time_s:
            return Decision(Phase.GRASP, gripper_closed=True)
        if obs.object_xy is None:
            return Decision(Phase.GRASP, gripper_closed=True, reason="waiting to see the object")
        # Where the plan put the object in the gripper frame: on the closing finger's side.
        aim = np.array([self.robot.gripper.w_off_along, self._side_sign() * (
            2 * self.robot.gripper.g_off + float(obs.object_radius or 0.0))])
        rel = self._to_gripper(obs.kappa, obs.object_xy)
        if float(np.hypot(*(rel - aim))) > self.p.capture_check_m:
            self.gripper_closed = False
            return self._replan(t, "object not in the gripper after grasping", settle=True)
        self._grip_rel = rel
        self.times["grasp_end"] = t
        self._enter(Phase.MOVE_TO_BIN, t, "grasped")
        self._ref_done_since = None  # the approach's reference is not the carry's
        carry = getattr(self.plan, "carry", None)
        self.carry = CarryFollower(self.bin.kappa_for(self.closing_side) if carry is None
                                   else carry)
        return Decision(Phase.MOVE_TO_BIN, kappa_target=self.carry.target, gripper_closed=True)

    def _on_move_to_bin(self, obs: Observation, t: float) -> Decision:
        if obs.object_xy is not None and self._grip_rel is not None:
            rel = self._to_gripper(obs.kappa, obs.object_xy)
            if float(np.hypot(*(rel - self._grip_rel))) > self.p.capture_check_m:
                self.gripper_closed = False
                return self._replan(t, "object lost while moving to the bin", settle=True)
        # a middle target of the carry is reached, not passed: its corner keeps the clearance
        tol = self.p.advance_dkappa
        nxt = self.carry.advance(obs.kappa, obs.reference_finished, tol)
        if nxt is not None:  # each target of the carry gets move_timeout_s once its reference arrived
            self._ref_done_since = None
            self.events.append((t, f"carry: target {self.carry.index + 1}/"
                                   f"{len(self.carry.targets)}"))
            return Decision(Phase.MOVE_TO_BIN, kappa_target=nxt, gripper_closed=True)
        bin_kappa = self.carry.targets[-1]
        dist = float(np.hypot(*(self.palm(obs.kappa) - self.palm(bin_kappa))))
        if dist <= self.p.release_distance_m and self.carry.last:
            self.gripper_closed = False
            self.times["release"] = t
            self._enter(Phase.RELEASE, t, f"palm {dist * 1000:.0f} mm from the bin")
            return Decision(Phase.RELEASE, gripper_closed=False)
        # the reference moves at the trajectory's rate limits (a long carry takes longer than
        # move_timeout_s by itself): the time to arrive counts from when it arrived
        if self._timed_out(obs, t, self.p.move_timeout_s):
            if self.carry.last:
                return self._stop(t, f"bin not reached {self.p.move_timeout_s:g} s after the "
                                     f"reference arrived (palm {dist * 1000:.0f} mm away)")
            err = float(np.max(np.abs(obs.kappa - self.carry.target)))
            return self._stop(t, f"carry target {self.carry.index + 1}/{len(self.carry.targets)}"
                                 f" not reached {self.p.move_timeout_s:g} s after the reference "
                                 f"arrived (max |dkappa| {err:.2f} 1/m, needs {tol:g})")
        return Decision(Phase.MOVE_TO_BIN, gripper_closed=True)

    def _on_release(self, obs: Observation, t: float) -> Decision:
        if t - self._since < self.p.release_time_s:
            return Decision(Phase.RELEASE)
        self.times["released"] = t
        self.reason = None
        self._enter(Phase.RELEASED, t, "object released")
        return Decision(Phase.RELEASED)

    # -- reporting -----------------------------------------------------------------------------
    @property
    def approach_s(self) -> float | None:
        """From the first approach motion to the start of the grasp (re-plans included)."""
        a, b = self.times.get("approach_start"), self.times.get("grasp_start")
        return None if a is None or b is None else b - a

    @property
    def return_s(self) -> float | None:
        """From the end of the grasp to the release (moveToBin)."""
        a, b = self.times.get("grasp_end"), self.times.get("release")
        return None if a is None or b is None else b - a
