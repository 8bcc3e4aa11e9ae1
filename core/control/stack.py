"""One control period of the soft arm: mocap -> fit -> state machine -> trajGen -> controller.

:class:`ControlStack` is the ``update`` of the loop runner's read -> update -> write cycle. It is
pure (no threads, no I/O, no clock): the caller passes the reading and the time, and gets the
2N + 1 cylinder demands to write (or None while disarmed) plus a :class:`Telemetry` snapshot.
Operator commands (:meth:`arm`, :meth:`start`, :meth:`execute`, :meth:`goto`, :meth:`stop`,
:meth:`disarm`) must be called from the same thread as :meth:`update` (the loop thread).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from core.control.controller import CurvatureController
from core.control.params import BinParams
from core.control.grasp_place import GraspAndPlace, Observation, Phase, Planner
from core.control.trajectory import TrajectoryGenerator
from core.control.fastkin import fit
from core.robots import SoftArm

Array = npt.NDArray[np.float64]


class Reading(Protocol):
    """What the stack needs from a device read: markers (N, 2) (NaN = occluded) and the object."""

    markers: Array
    object_xy: Array | None
    object_radius: float | None


@dataclasses.dataclass(frozen=True)
class Telemetry:
    """Immutable per-tick snapshot for the GUI and logs."""

    t: float
    armed: bool
    phase: str
    reason: str | None
    waypoint: int
    n_waypoints: int
    replans: int
    tracking_ok: bool
    prepressurised: bool
    kappa_meas: Array | None
    kappa_ref: Array
    kappa_target: Array
    commands: Array
    saturated: npt.NDArray[np.bool_]
    gripper_closed: bool
    object_xy: Array | None


class ControlStack:
    """Curvature controller + trajGen + grasp-and-place machine for one arm.

    Args:
        robot: The soft arm.
        dt: Control period, s.
        planner: Planner for the state machine (see :mod:`core.control.grasp_place`).
    """

    def __init__(self, robot: SoftArm, dt: float, planner: Planner):
        self.robot = robot
        self.dt = dt
        self._base = robot.base_pose.tolist()
        self.controller = CurvatureController.from_robot(robot)
        self.traj = TrajectoryGenerator.from_robot(robot, dt)
        self.machine = GraspAndPlace.from_robot(robot, planner)
        self.armed = False
        self.kappa_meas: Array | None = None
        self._freeze = False
        self._resume_target = np.zeros(robot.n_segments)
        self._kf: Array | None = None
        self._kf_t = 0.0
        self._last: Telemetry | None = None

    # -- operator commands (loop thread only) -------------------------------------------------
    def arm(self, cylinders: npt.ArrayLike | None = None) -> None:
        """Start commanding from the device's cylinder positions; root segments pre-pressurise."""
        self.controller.reset(cylinders)
        if self.kappa_meas is not None:
            self._restart_from(self.kappa_meas)
        self.machine.reset()
        self._freeze = False
        self.armed = True

    def disarm(self) -> None:
        """Stop writing demands (the device holds or disables its drives)."""
        self.armed = False
        self.machine.reset()

    def start(self, t: float) -> None:
        """Full grasp-and-place (settle, plan, approach, grasp, place)."""
        self._require_armed("start")
        self.machine.start(t)

    def set_obstacles(self, obstacles: Any = (), clearance: float = 0.0) -> None:
        """Obstacles every plan of the task keeps ``clearance`` (m) from (first plan and
        re-plans; :meth:`GraspAndPlace.set_obstacles`)."""
        self.machine.set_obstacles(obstacles, clearance)

    def set_bin(self, bin_params: BinParams | None) -> None:
        """Where the next task takes the object: a bin placed on the table
        (:func:`core.control.row.bin_at`), or None for the robot file's ``[bin]``."""
        self.machine.bin = BinParams.from_robot(self.robot) if bin_params is None else bin_params

    def execute(self, plan: Any, center: npt.ArrayLike, t: float) -> None:
        """Execute a given grasp plan for the object at ``center``, then place it."""
        self._require_armed("execute")
        self.machine.execute(plan, center, t)
        self._freeze = False

    def goto(self, kappa: npt.ArrayLike, t: float) -> None:
        """Manual move to a configuration through trajGen (only while no task runs)."""
        self._require_armed("goto")
        if self.machine.phase not in (Phase.IDLE, Phase.RELEASED, Phase.STOPPED):
            raise RuntimeError(f"goto refused: grasp-and-place is in {self.machine.phase.value}")
        self.traj.set_target(kappa)  # validates first: bad input moves nothing
        self.machine.reset()
        if self._freeze and self.kappa_meas is not None:
            self.traj.reset(self.kappa_meas)
            self.traj.set_target(kappa)
        self._freeze = False

    def stop(self, t: float, reason: str = "operator STOP") -> None:
        """Hold the arm: cylinder volumes frozen, reference stopped, task aborted with a reason."""
        self.machine.stop(t, reason)
        if not self._freeze:
            self._resume_target = self.traj.sample.position.copy()
        self.traj.hold()
        self._freeze = True

    def device_fault(self, t: float, reason: str) -> Telemetry | None:
        """The device failed (no reading, or a write refused), or the update itself raised:
        hold, abort the task with ``reason`` and stop commanding, so nothing moves until the
        operator arms again.

        Returns the last telemetry marked so (phase, reason, disarmed; its ``t`` stays that of
        the last reading, so it reads as stale), or None before the first reading.
        """
        if self.armed:
            self.stop(t, reason)
            self.armed = False
        if self._last is None:
            return None
        m = self.machine
        self._last = dataclasses.replace(self._last, armed=False, phase=m.phase.value,
                                         reason=m.reason, tracking_ok=False)
        return self._last

    def _restart_from(self, kappa: Array, target: Array | None = None) -> None:
        """Restart trajGen at the measured ``kappa`` toward ``target`` (default: ``kappa``),
        the target clamped to the curvature limit +-kappa_max.

        A measurement may lie beyond the limit (the arm bent past it by a load or by hand,
        motion-capture noise at full bend) and a target kept from such a state (a freeze's
        resume target) too; trajGen refuses targets beyond the limit, so the period would raise.
        The reference starts where the arm is and moves back within the limit.
        """
        k_max = self.traj.kappa_max
        self.traj.reset(kappa)
        self.traj.set_target(np.clip(kappa if target is None else target, -k_max, k_max))

    def _require_armed(self, what: str) -> None:
        if not self.armed:
            raise RuntimeError(f"{what} refused: the arm is not armed")

    # -- the period ----------------------------------------------------------------------------
    def measure(self, reading: Reading) -> Array | None:
        """Fit curvatures to the markers (None when any marker is occluded)."""
        m = np.asarray(reading.markers, dtype=float)
        if m.shape != (self.robot.n_segments, 2) or not np.all(np.isfinite(m)):
            return None
        kappa, _ = fit(m, self._base)
        return kappa

    def _filter(self, kappa: Array | None, t: float) -> Array | None:
        """First-order low-pass (``controller.measurement_filter_s``); restarts after a gap."""
        if kappa is None:
            return None
        tau = self.controller.p.measurement_filter_s
        if self._kf is None or tau <= 0 or t - self._kf_t > 0.1:
            self._kf = kappa.copy()
        else:
            self._kf += (t - self._kf_t) / (tau + t - self._kf_t) * (kappa - self._kf)
        self._kf_t = t
        return self._kf.copy()

    def update(self, reading: Reading, t: float, periods: int = 1) -> tuple[Array | None, Telemetry]:
        """One control period. Returns (demands to write or None, telemetry)."""
        kappa = self._filter(self.measure(reading), t)
        self.kappa_meas = kappa if kappa is not None else self.kappa_meas
        if not self.armed:
            if kappa is not None:
                self.traj.reset(kappa)
            return None, self._telemetry(t, reading, kappa, self.controller.commands,
                                         np.zeros(self.robot.n_segments, bool))
        obs = Observation(t, kappa, reading.object_xy, reading.object_radius,
                          self.traj.sample.finished)
        d = self.machine.step(obs)
        if d.freeze:
            if not self._freeze:
                self._resume_target = self.traj.target
                self.traj.hold()
            self._freeze = True
        elif self._freeze and kappa is not None:
            # Tracking is back: continue toward the same target from where the arm is.
            self._freeze = False
            self._restart_from(kappa, self._resume_target)
        if d.hold_reference:
            self.traj.hold()
        if d.kappa_target is not None:
            self.traj.set_target(d.kappa_target)
        if self._freeze or kappa is None:
            out = self.controller.hold(d.gripper_closed, self.dt * periods)
        else:
            ref = self.traj.update(periods)
            out = self.controller.step(ref.position, kappa, self.dt * periods, ref.velocity,
                                       d.gripper_closed)
        return out.commands, self._telemetry(t, reading, kappa, out.commands, out.saturated)

    def _telemetry(self, t: float, reading: Reading, kappa: Array | None, commands: Array,
                   saturated: npt.NDArray[np.bool_]) -> Telemetry:
        m = self.machine
        plan = m.plan
        tel = Telemetry(
            t=t, armed=self.armed, phase=m.phase.value, reason=m.reason, waypoint=m.waypoint,
            n_waypoints=0 if plan is None else int(np.asarray(plan.kappas).shape[0]),
            replans=m.replans, tracking_ok=kappa is not None,
            prepressurised=self.controller.prepressurised,
            kappa_meas=None if kappa is None else kappa.copy(),
            kappa_ref=self.traj.sample.position.copy(), kappa_target=self.traj.target,
            commands=np.array(commands, dtype=float), saturated=saturated,
            gripper_closed=m.gripper_closed,
            object_xy=None if reading.object_xy is None else np.array(reading.object_xy, dtype=float))
        self._last = tel
        return tel
