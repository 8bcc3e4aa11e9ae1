"""Simulated soft arm (numpy, seeded): the plant every demo without hardware runs on.

Model, per :meth:`SoftArmSim.step` of ``dt`` seconds (parameters in ``[sim]`` of the robot file):

* **Drive cylinders**: 2N + 1 pistons (13 for N = 6) follow their demands at ``cylinder_rate``
  counts/s within ``[cylinder_min, cylinder_max]`` (the inner position loop of the real cylinder
  array).
* **Segments**: curvature lags the steady state ``clip((left - right) / counts_per_kappa,
  +-kappa_max)`` with first order ``d kappa/dt = (kappa_ss - kappa) / tau`` (integrated exactly),
  ``tau = tau_s / (1 + prepressure_stiffening * min(1, min(left, right) / prepressure_ref))`` so
  pre-pressurised segments are stiffer and faster, as in the paper.
* **Stick-slip**: a segment that is being driven (``|kappa_ss - kappa| > stall_drive_threshold``)
  sticks with rate ``stall_rate_hz`` for a uniform ``stall_duration_s`` (curvature frozen), then
  slips: for ``3 slip_tau_s`` it moves with time constant ``slip_tau_s`` toward its steady state
  plus up to ``slip_overshoot`` of the built-up error (an overshoot the loop must correct).
* **Object**: a disc on the table, pushed out of the arm body (backbone capsules of
  ``arm_half_width``) and the gripper (:mod:`core.control.gripper`); while captured it moves
  with the gripper; it is put down where it is when the gripper opens.
* **Gripper**: channel 2N (12 for N = 6) sets the finger turn ``closed_turn * c / counts_closed``;
  closing runs the capture sweep incrementally, so only objects in the capture region are captured.
* **Motion capture** (:meth:`SoftArmSim.measure`): segment-end markers E_1..E_N and the object
  centre with Gaussian noise; each marker is occluded at ``occlusion_rate_hz`` for a uniform
  ``occlusion_duration_s`` (reported as NaN).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from core.control.gripper import GripperGeometry, close_sweep, from_frame, push_out, to_frame
from core.control.fastkin import fk
from core.control.params import SimParams
from core.kinematics.planar import sample_backbone
from core.robots import SoftArm

Array = npt.NDArray[np.float64]


def _clip(a, lo, hi):
    """np.clip via the min/max ufuncs (several times faster on small arrays)."""
    return np.minimum(np.maximum(a, lo), hi)
_BODY_SAMPLES = 3


@dataclasses.dataclass(frozen=True)
class MocapReading:
    """One motion-capture frame: ``markers`` (N, 2) with NaN rows when occluded."""

    t: float
    markers: Array
    object_xy: Array | None
    object_radius: float | None

    @property
    def tracking_ok(self) -> bool:
        return bool(np.all(np.isfinite(self.markers)))


@dataclasses.dataclass
class SimObject:
    """Disc on the table; ``grip`` is its centre in the gripper frame while captured."""

    xy: Array
    radius: float
    grip: Array | None = None


class SoftArmSim:
    """Seeded soft-arm plant with object, gripper sweep and motion capture.

    Args:
        robot: The soft arm.
        params: Plant parameters (default ``SimParams.from_robot(robot)``).
        seed: Seed of the plant's random generator (stick-slip, mocap noise, occlusions).
        kappa0: Initial curvatures (default straight); cylinders start matching them.
    """

    def __init__(self, robot: SoftArm, params: SimParams | None = None, seed: int = 0,
                 kappa0: npt.ArrayLike | None = None):
        self.robot = robot
        self.p = SimParams.from_robot(robot) if params is None else params
        self.n = robot.n_segments
        self.rng = np.random.default_rng(seed)
        self.geom = GripperGeometry.from_params(robot.gripper.length, self.p.gripper,
                                                self.p.arm_half_width, robot.gripper.fingers)
        self.t = 0.0
        k0 = np.zeros(self.n) if kappa0 is None else np.asarray(kappa0, dtype=float)
        if k0.shape != (self.n,) or np.any(np.abs(k0) > robot.kappa_max):
            raise ValueError(f"kappa0 must be {self.n} curvatures within +-{robot.kappa_max}")
        self.kappa = k0.copy()
        self._lengths = robot.lengths.tolist()
        self._ends: Array | None = None
        self.cylinders = np.full(2 * self.n + 1, self.p.cylinder_min)
        diff = k0 * self.p.counts_per_kappa
        self.cylinders[0:2 * self.n:2] += np.maximum(diff, 0)
        self.cylinders[1:2 * self.n:2] += np.maximum(-diff, 0)
        self.demands = self.cylinders.copy()
        self.stuck_until = np.full(self.n, -np.inf)
        self.slip_until = np.full(self.n, -np.inf)
        self.slip_target = np.zeros(self.n)
        self._grip_cache: tuple[float, Array, Array] = (math.nan, np.zeros((0, 2)),
                                                        np.zeros((0, 2)))
        # Bound on how far any backbone point moves per unit curvature change of each segment.
        ln = robot.lengths
        self._sweep_weights = ln * (np.cumsum(ln[::-1])[::-1] + robot.gripper.length)
        self.stalls = 0
        self.turn = 0.0
        self.blocked = False
        self.obj: SimObject | None = None
        self.occluded_until = np.full(self.n + 1, -np.inf)
        self.occlusions = 0
        self._last_measure = 0.0

    # -- scene ---------------------------------------------------------------------------------
    def place_object(self, x: float, y: float, radius: float) -> None:
        """Put a disc on the table (replacing any); it is pushed free of the arm at once."""
        if not radius > 0:
            raise ValueError(f"object radius must be > 0, got {radius}")
        self.obj = SimObject(np.array([x, y], dtype=float), float(radius))
        self._push_object()

    def remove_object(self) -> None:
        self.obj = None

    @property
    def captured(self) -> bool:
        return self.obj is not None and self.obj.grip is not None

    def shape(self) -> Array:
        """True segment-end poses (N+1, 3), base first."""
        if self._ends is None:
            self._ends = fk(self.kappa, self._lengths, self.robot.base_pose)
        return self._ends.copy()

    def tip_pose(self) -> Array:
        return self.shape()[-1]

    def gripper_polyline(self) -> Array:
        """Gripper centreline in the world (M, 2), from the arm stub to the finger tip (with two
        fingers from the right finger's tip to the left one's, :meth:`GripperGeometry.outline`)."""
        return from_frame(self.tip_pose(), self.geom.outline(self.turn))

    # -- dynamics ------------------------------------------------------------------------------
    def step(self, demands: npt.ArrayLike, dt: float) -> None:
        """Advance by ``dt`` under cylinder ``demands`` (2N+1,) counts."""
        d = np.asarray(demands, dtype=float)
        if d.shape != self.cylinders.shape or not np.all(np.isfinite(d)):
            raise ValueError(f"demands must be {self.cylinders.shape[0]} finite counts, got {d.shape}")
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        p = self.p
        self.demands = _clip(d, p.cylinder_min, p.cylinder_max)
        move = p.cylinder_rate * dt
        self.cylinders += _clip(self.demands - self.cylinders, -move, move)
        self.t += dt

        left, right = self.cylinders[0:2 * self.n:2], self.cylinders[1:2 * self.n:2]
        k_ss = _clip((left - right) / p.counts_per_kappa, -self.robot.kappa_max, self.robot.kappa_max)
        common = np.minimum(np.minimum(left, right) - p.cylinder_min, p.prepressure_ref)
        tau = p.tau_s / (1.0 + p.prepressure_stiffening * np.maximum(common, 0) / p.prepressure_ref)
        gap = k_ss - self.kappa
        stuck = self.stuck_until > self.t
        released = (self.stuck_until <= self.t) & (self.stuck_until > self.t - dt)
        if released.any():  # slip: toward the steady state and past it by part of the error
            over = p.slip_overshoot * self.rng.random(int(released.sum()))
            self.slip_target[released] = k_ss[released] + over * gap[released]
            self.slip_until[released] = self.t + 3.0 * p.slip_tau_s
        slipping = self.slip_until > self.t
        driven = (np.abs(gap) > p.stall_drive_threshold) & ~stuck & ~slipping
        starts = driven & (self.rng.random(self.n) < -math.expm1(-p.stall_rate_hz * dt))
        if starts.any():
            lo, hi = p.stall_duration_s
            self.stuck_until[starts] = self.t + self.rng.uniform(lo, hi, int(starts.sum()))
            self.stalls += int(starts.sum())
        goal = np.where(slipping, self.slip_target, k_ss)
        new = goal - (goal - self.kappa) * np.exp(-dt / np.where(slipping, p.slip_tau_s, tau))
        hold = starts | stuck
        new[hold] = self.kappa[hold]
        new = _clip(new, -self.robot.kappa_max, self.robot.kappa_max)
        # Sub-steps so the body never jumps more than ~3 mm between contact checks.
        move = float(np.abs(new - self.kappa) @ self._sweep_weights)
        n_sub = 1 if self.obj is None or self.captured else min(20, max(1, math.ceil(move / 0.003)))
        old_kappa = self.kappa
        for j in range(1, n_sub + 1):
            self.kappa = old_kappa + (new - old_kappa) * (j / n_sub)
            self._ends = None
            if j < n_sub:
                self._push_object()
        self._step_gripper(old_kappa)
        self._push_object()

    def _step_gripper(self, old_kappa: Array) -> None:
        g = self.p.gripper
        target = g.closed_turn * min(max(self.cylinders[-1] / g.counts_closed, 0.0), 1.0)
        obj = self.obj
        if obj is not None and obj.grip is not None:
            if target < 0.5 * self.geom.capture_turn:  # opened: put the object down
                obj.grip = None
            else:
                obj.xy = from_frame(self.tip_pose(), obj.grip)
            self.turn, self.blocked = target, False
            return
        if target <= self.turn:  # opening (or holding): nothing to sweep
            self.turn, self.blocked = target, False
            return
        if obj is None:
            self.turn = target
            return
        if self.blocked:
            return
        tip = self.tip_pose()
        res = close_sweep(self.geom, to_frame(tip, obj.xy)[None], obj.radius, self.turn, target)
        self.turn = float(res.turn[0])
        self.blocked = bool(res.blocked[0])
        obj.xy = from_frame(tip, res.position[0])
        if res.captured[0]:
            obj.grip = res.position[0].copy()

    def _push_object(self) -> None:
        obj = self.obj
        if obj is None or obj.grip is not None:
            return
        ends = self.shape()
        reach = obj.radius + max(self.p.arm_half_width, self.geom.finger_half_width) + 1e-3
        # Any point of a segment is within half its length of one of its ends; any point of the
        # gripper within its length of the tip: skip the capsule test when nothing can touch.
        d = np.hypot(ends[:, 0] - obj.xy[0], ends[:, 1] - obj.xy[1])
        body_near = d.min() <= reach + 0.5 * self.robot.segment_length
        grip_near = d[-1] <= reach + self.robot.gripper.length
        if not (body_near or grip_near):
            return
        parts_a, parts_b, parts_hw = [], [], []
        if body_near:
            body = sample_backbone(self.kappa, self.robot.lengths, _BODY_SAMPLES,
                                   self.robot.base_pose)[:, :2]
            parts_a.append(body[:-1]), parts_b.append(body[1:])
            parts_hw.append(np.full(body.shape[0] - 1, self.p.arm_half_width))
        if grip_near:
            if self._grip_cache[0] != self.turn:  # the gripper's capsules without the arm stub
                a, b = self.geom.capsules(self.turn)
                self._grip_cache = (self.turn, a[0, 1:], b[0, 1:])
            parts_a.append(from_frame(ends[-1], self._grip_cache[1]))
            parts_b.append(from_frame(ends[-1], self._grip_cache[2]))
            parts_hw.append(np.full(self._grip_cache[1].shape[0], self.geom.finger_half_width))
        a, b = np.concatenate(parts_a), np.concatenate(parts_b)
        q, _ = push_out(obj.xy[None], np.array([obj.radius]), a[None], b[None],
                        np.concatenate(parts_hw))
        obj.xy = q[0]

    # -- sensing -------------------------------------------------------------------------------
    def measure(self) -> MocapReading:
        """A motion-capture frame of the current state (noise and occlusions drawn here)."""
        m = self.p.mocap
        ends = self.shape()[1:, :2]
        markers = ends + self.rng.normal(0.0, m.noise_m, ends.shape) if m.noise_m else ends.copy()
        if m.occlusion_rate_hz > 0:
            visible = self.occluded_until <= self.t
            since = max(self.t - self._last_measure, 0.0)
            starts = visible & (self.rng.random(self.n + 1) < -math.expm1(-m.occlusion_rate_hz * since))
            if starts.any():
                lo, hi = m.occlusion_duration_s
                self.occluded_until[starts] = self.t + self.rng.uniform(lo, hi, int(starts.sum()))
                self.occlusions += int(starts.sum())
        self._last_measure = self.t
        hidden = self.occluded_until > self.t
        markers[hidden[:-1]] = np.nan
        if self.obj is None or hidden[-1]:
            return MocapReading(self.t, markers, None, None if self.obj is None else self.obj.radius)
        obj_xy = self.obj.xy + (self.rng.normal(0.0, m.object_noise_m, 2) if m.object_noise_m else 0.0)
        return MocapReading(self.t, markers, obj_xy, self.obj.radius)


class EmulatorPlant:
    """Drop-in for ``hw_bridge.plants.CurvaturePlant`` so the device emulator runs this sim.

    The emulator's MotorBank already moves the pistons at the motor speed, so the sim's own
    piston slew is disabled and the encoder positions drive the segments directly.
    :meth:`mocap_frame` adds the sim's marker noise, occlusions and the object (an extra point).
    """

    def __init__(self, robot: SoftArm, seed: int = 0, params: SimParams | None = None):
        self.sim = SoftArmSim(robot, params, seed)
        self.sim.p = self.sim.p.replace(cylinder_rate=1e12)

    @property
    def kappa(self) -> Array:
        return self.sim.kappa

    def step(self, cylinders: npt.ArrayLike, dt: float) -> None:
        self.sim.step(cylinders, dt)

    def shape(self) -> Array:
        """True segment-end poses (N+1, 3)."""
        return self.sim.shape()

    def mocap_frame(self) -> tuple[Array, bool]:
        """``(points, valid)`` for the UDP packet: base + measured segment ends (+ object)."""
        m = self.sim.measure()
        ends = self.sim.shape()
        pts = np.concatenate([ends[:1], np.column_stack([m.markers, ends[1:, 2]])])
        if m.object_xy is not None:
            pts = np.concatenate([pts, [[m.object_xy[0], m.object_xy[1], 0.0]]])
        return pts, m.tracking_ok
