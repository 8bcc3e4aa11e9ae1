"""Control, trajectory, simulation and state-machine parameters read from the robot file, not code.

Each dataclass reads one section of ``data/robots/soft-arm.toml`` through ``robot.raw``
(``[controller]``, ``[trajectory]``, ``[sim]`` with ``[sim.mocap]`` / ``[sim.gripper]``,
``[state_machine]``, ``[bin]``). A missing or bad field raises
:class:`~core.robots.RobotFileError` naming it (``controller.kp: must be >= 0, got -1``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal, Mapping

import numpy as np
import numpy.typing as npt

from core.robots import RobotFileError, SoftArm, check_number

Array = npt.NDArray[np.float64]


def _section(robot: SoftArm, dotted: str) -> Mapping[str, Any]:
    node: Any = robot.raw
    for part in dotted.split("."):
        node = node.get(part) if isinstance(node, Mapping) else None
    if not isinstance(node, Mapping):
        raise RobotFileError(f"{robot.source.name}: [{dotted}]: missing")
    return node


def _num(t: Mapping[str, Any], sec: str, key: str, *, lo: float | None = 0.0,
         strict: bool = False, hi: float | None = None) -> float:
    return check_number(t.get(key), f"{sec}.{key}", lo=lo, hi=hi, strict_lo=strict)


def _pair(t: Mapping[str, Any], sec: str, key: str) -> tuple[float, float]:
    v = t.get(key)
    if (not isinstance(v, list) or len(v) != 2 or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
            or not 0 <= v[0] <= v[1]):
        raise RobotFileError(f"{sec}.{key}: must be [lo, hi] with 0 <= lo <= hi, got {v!r}")
    return float(v[0]), float(v[1])


def _per_dof(t: Mapping[str, Any], sec: str, key: str, n: int) -> Array:
    v = t.get(key)
    vals = v if isinstance(v, list) else [v] * n
    if len(vals) != n or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                 and math.isfinite(x) and x > 0 for x in vals):
        raise RobotFileError(f"{sec}.{key}: must be > 0 (a number or {n} numbers), got {v!r}")
    return np.array(vals, dtype=float)


def _bool(t: Mapping[str, Any], sec: str, key: str) -> bool:
    v = t.get(key)
    if not isinstance(v, bool):
        raise RobotFileError(f"{sec}.{key}: must be true or false, got {v!r}")
    return v


@dataclasses.dataclass(frozen=True)
class ControllerParams:
    """Gains and actuator ranges of the cascaded curvature controller (``[controller]``).

    Cylinder quantities are in drive-cylinder counts (volume units, as on the serial link).
    """

    kp: float
    ki: float
    measurement_filter_s: float
    kd: float
    derivative_filter_s: float
    anti_windup_gain: float
    counts_per_kappa: float
    velocity_feedforward_s: float
    cylinder_min: float
    cylinder_max: float
    cylinder_rate: float
    prepressure: float
    gripper_open: float
    gripper_closed: float

    @classmethod
    def from_robot(cls, robot: SoftArm) -> "ControllerParams":
        t, s = _section(robot, "controller"), "controller"
        p = cls(
            kp=_num(t, s, "kp"), ki=_num(t, s, "ki"), kd=_num(t, s, "kd"),
            measurement_filter_s=_num(t, s, "measurement_filter_s"),
            derivative_filter_s=_num(t, s, "derivative_filter_s", strict=True),
            anti_windup_gain=_num(t, s, "anti_windup_gain"),
            counts_per_kappa=_num(t, s, "counts_per_kappa", strict=True),
            velocity_feedforward_s=_num(t, s, "velocity_feedforward_s"),
            cylinder_min=_num(t, s, "cylinder_min", lo=None),
            cylinder_max=_num(t, s, "cylinder_max", lo=None),
            cylinder_rate=_num(t, s, "cylinder_rate", strict=True),
            prepressure=_num(t, s, "prepressure"),
            gripper_open=_num(t, s, "gripper_open", lo=None),
            gripper_closed=_num(t, s, "gripper_closed", lo=None),
        )
        if p.cylinder_max <= p.cylinder_min:
            raise RobotFileError(f"controller.cylinder_max: must be > cylinder_min, got {p.cylinder_max:g}")
        if not p.cylinder_min <= p.prepressure < p.cylinder_max:
            raise RobotFileError(f"controller.prepressure: must lie in [cylinder_min, cylinder_max), "
                                 f"got {p.prepressure:g}")
        return p


@dataclasses.dataclass(frozen=True)
class TrajectoryParams:
    """Per-DOF curvature limits for trajGen (``[trajectory]``), units 1/m, 1/(m s), ..."""

    max_velocity: Array
    max_acceleration: Array
    max_jerk: Array
    synchronization: Literal["phase", "time"]

    @classmethod
    def from_robot(cls, robot: SoftArm) -> "TrajectoryParams":
        t, s, n = _section(robot, "trajectory"), "trajectory", robot.n_segments
        sync = t.get("synchronization")
        if sync not in ("phase", "time"):
            raise RobotFileError(f"trajectory.synchronization: must be 'phase' or 'time', got {sync!r}")
        return cls(_per_dof(t, s, "max_velocity", n), _per_dof(t, s, "max_acceleration", n),
                   _per_dof(t, s, "max_jerk", n), sync)


@dataclasses.dataclass(frozen=True)
class StateMachineParams:
    """Timeouts and thresholds of the grasp-and-place state machine (``[state_machine]``)."""

    settle_time_s: float
    settle_tolerance_m: float
    advance_dkappa: float
    pass_over: bool
    pass_dkappa: float
    final_dkappa: float
    grasp_position_tol_m: float
    waypoint_timeout_s: float
    object_moved_m: float
    tracking_timeout_s: float
    max_replans: int
    grasp_time_s: float
    release_distance_m: float
    release_time_s: float
    move_timeout_s: float
    capture_check_m: float

    @classmethod
    def from_robot(cls, robot: SoftArm) -> "StateMachineParams":
        t, s = _section(robot, "state_machine"), "state_machine"
        replans = t.get("max_replans")
        if isinstance(replans, bool) or not isinstance(replans, int) or replans < 0:
            raise RobotFileError(f"state_machine.max_replans: must be an integer >= 0, got {replans!r}")
        names = [f.name for f in dataclasses.fields(cls)]
        vals: dict[str, Any] = {}
        for name in names:
            if name == "max_replans":
                vals[name] = replans
            elif name == "pass_over":
                vals[name] = _bool(t, s, name)
            else:
                vals[name] = _num(t, s, name, strict=True)
        return cls(**vals)


@dataclasses.dataclass(frozen=True)
class BinParams:
    """Where ``moveToBin`` goes (``[bin]``): the straight pose or configured curvatures."""

    kappa: Array
    drop_radius_m: float

    @classmethod
    def from_robot(cls, robot: SoftArm) -> "BinParams":
        t, s, n = _section(robot, "bin"), "bin", robot.n_segments
        mode = t.get("mode")
        if mode == "straight":
            kappa = np.zeros(n)
        elif mode == "kappa":
            k = t.get("kappa")
            if (not isinstance(k, list) or len(k) != n or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) <= robot.kappa_max
                    for x in k)):
                raise RobotFileError(f"bin.kappa: must be {n} curvatures within +-{robot.kappa_max:g}, "
                                     f"got {k!r}")
            kappa = np.array(k, dtype=float)
        else:
            raise RobotFileError(f"bin.mode: must be 'straight' or 'kappa', got {mode!r}")
        return cls(kappa, _num(t, s, "drop_radius_m", strict=True))


@dataclasses.dataclass(frozen=True)
class MocapSimParams:
    """Simulated motion capture (``[sim.mocap]``)."""

    noise_m: float
    object_noise_m: float
    occlusion_rate_hz: float
    occlusion_duration_s: tuple[float, float]


@dataclasses.dataclass(frozen=True)
class GripperSimParams:
    """Simulated gripper geometry and closing sweep (``[sim.gripper]``), gripper-root frame."""

    palm_length: float
    finger_half_width: float
    counts_closed: float
    closed_turn: float
    capture_turn: float
    sweep_steps: int


@dataclasses.dataclass(frozen=True)
class SimParams:
    """Simulated soft arm plant (``[sim]``)."""

    counts_per_kappa: float
    tau_s: float
    prepressure_stiffening: float
    prepressure_ref: float
    cylinder_rate: float
    cylinder_min: float
    cylinder_max: float
    stall_rate_hz: float
    stall_duration_s: tuple[float, float]
    stall_drive_threshold: float
    slip_overshoot: float
    slip_tau_s: float
    arm_half_width: float
    mocap: MocapSimParams
    gripper: GripperSimParams

    @classmethod
    def from_robot(cls, robot: SoftArm) -> "SimParams":
        t, s = _section(robot, "sim"), "sim"
        m, ms = _section(robot, "sim.mocap"), "sim.mocap"
        g, gs = _section(robot, "sim.gripper"), "sim.gripper"
        steps = g.get("sweep_steps")
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 2:
            raise RobotFileError(f"sim.gripper.sweep_steps: must be an integer >= 2, got {steps!r}")
        grip = GripperSimParams(
            palm_length=_num(g, gs, "palm_length", strict=True, hi=robot.gripper.length),
            finger_half_width=_num(g, gs, "finger_half_width", strict=True),
            counts_closed=_num(g, gs, "counts_closed", strict=True),
            closed_turn=_num(g, gs, "closed_turn", strict=True, hi=2 * math.pi),
            capture_turn=_num(g, gs, "capture_turn", strict=True, hi=2 * math.pi),
            sweep_steps=steps)
        return cls(
            counts_per_kappa=_num(t, s, "counts_per_kappa", strict=True),
            tau_s=_num(t, s, "tau_s", strict=True),
            prepressure_stiffening=_num(t, s, "prepressure_stiffening"),
            prepressure_ref=_num(t, s, "prepressure_ref", strict=True),
            cylinder_rate=_num(t, s, "cylinder_rate", strict=True),
            cylinder_min=_num(t, s, "cylinder_min", lo=None),
            cylinder_max=_num(t, s, "cylinder_max", lo=None),
            stall_rate_hz=_num(t, s, "stall_rate_hz"),
            stall_duration_s=_pair(t, s, "stall_duration_s"),
            stall_drive_threshold=_num(t, s, "stall_drive_threshold"),
            slip_overshoot=_num(t, s, "slip_overshoot"),
            slip_tau_s=_num(t, s, "slip_tau_s", strict=True),
            arm_half_width=_num(t, s, "arm_half_width", strict=True),
            mocap=MocapSimParams(
                noise_m=_num(m, ms, "noise_m"), object_noise_m=_num(m, ms, "object_noise_m"),
                occlusion_rate_hz=_num(m, ms, "occlusion_rate_hz"),
                occlusion_duration_s=_pair(m, ms, "occlusion_duration_s")),
            gripper=grip)

    def replace(self, **changes: Any) -> "SimParams":
        """A copy with some fields changed (``mocap=`` / ``gripper=`` take dicts of fields too)."""
        for key in ("mocap", "gripper"):
            if isinstance(changes.get(key), Mapping):
                changes[key] = dataclasses.replace(getattr(self, key), **changes[key])
        return dataclasses.replace(self, **changes)
