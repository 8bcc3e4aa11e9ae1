"""Control, trajectory, simulation and state-machine parameters read from the robot file, not code.

Each dataclass reads one section of ``data/robots/soft-arm.toml`` when :func:`core.robots.load`
reads the file (``[controller]``, ``[trajectory]``, ``[sim]`` with ``[sim.mocap]`` /
``[sim.gripper]``, ``[state_machine]``, ``[bin]``); ``from_robot`` returns the loaded section. A
missing, unknown or bad field raises :class:`~core.robot_schema.RobotFileError` naming file and
field (``soft-arm.toml: controller.kp: must be >= 0, got -1``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal, Mapping, Protocol

import numpy as np
import numpy.typing as npt

from core.robot_schema import Section

Array = npt.NDArray[np.float64]


class SoftArmSections(Protocol):
    """The loaded sections ``from_robot`` returns: :class:`core.robots.SoftArm` has them.

    A protocol rather than ``SoftArm`` itself, which is built from these classes (so naming it
    here would close an import circle with :mod:`core.robots`).
    """

    @property
    def controller(self) -> ControllerParams: ...

    @property
    def trajectory(self) -> TrajectoryParams: ...

    @property
    def state_machine(self) -> StateMachineParams: ...

    @property
    def bin(self) -> BinParams: ...

    @property
    def sim(self) -> SimParams: ...


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
    def read(cls, sec: Section) -> "ControllerParams":
        """Read and check ``[controller]``."""
        big = 1e9  # counts, gains: any larger value is a typo
        p = cls(
            kp=sec.num("kp", lo=0, hi=big), ki=sec.num("ki", lo=0, hi=big),
            kd=sec.num("kd", lo=0, hi=big),
            measurement_filter_s=sec.num("measurement_filter_s", lo=0, hi=60),
            derivative_filter_s=sec.num("derivative_filter_s", lo=0, hi=60, strict_lo=True),
            anti_windup_gain=sec.num("anti_windup_gain", lo=0, hi=big),
            counts_per_kappa=sec.num("counts_per_kappa", lo=0, hi=big, strict_lo=True),
            velocity_feedforward_s=sec.num("velocity_feedforward_s", lo=0, hi=60),
            cylinder_min=sec.num("cylinder_min", lo=-big, hi=big),
            cylinder_max=sec.num("cylinder_max", lo=-big, hi=big),
            cylinder_rate=sec.num("cylinder_rate", lo=0, hi=big, strict_lo=True),
            prepressure=sec.num("prepressure", lo=0, hi=big),
            gripper_open=sec.num("gripper_open", lo=-big, hi=big),
            gripper_closed=sec.num("gripper_closed", lo=-big, hi=big),
        )
        if p.cylinder_max <= p.cylinder_min:
            raise sec.error("cylinder_max", f"must be > cylinder_min ({p.cylinder_min:g}), "
                                            f"got {p.cylinder_max:g}")
        if not p.cylinder_min <= p.prepressure < p.cylinder_max:
            raise sec.error("prepressure", f"must lie in [cylinder_min, cylinder_max), "
                                           f"got {p.prepressure:g}")
        sec.finish()
        return p

    @classmethod
    def from_robot(cls, robot: SoftArmSections) -> "ControllerParams":
        """The robot's ``[controller]`` (validated when the file was loaded)."""
        return robot.controller


@dataclasses.dataclass(frozen=True)
class TrajectoryParams:
    """Per-DOF curvature limits for trajGen (``[trajectory]``), units 1/m, 1/(m s), ..."""

    max_velocity: Array
    max_acceleration: Array
    max_jerk: Array
    synchronization: Literal["phase", "time"]

    @classmethod
    def read(cls, sec: Section, n: int) -> "TrajectoryParams":
        """Read ``[trajectory]``: each limit is one number for all n segments or n numbers."""
        lim = {key: np.array(sec.numbers(key, n, lo=0, hi=1e9, strict_lo=True))
               for key in ("max_velocity", "max_acceleration", "max_jerk")}
        sync = sec.choice("synchronization", ("phase", "time"), default="phase")
        sec.finish()
        return cls(synchronization=sync, **lim)  # type: ignore[arg-type]

    @classmethod
    def from_robot(cls, robot: SoftArmSections) -> "TrajectoryParams":
        """The robot's ``[trajectory]`` (validated when the file was loaded)."""
        return robot.trajectory


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
    def read(cls, sec: Section) -> "StateMachineParams":
        """Read ``[state_machine]``: every time and distance > 0 (and at most a day / 10 m)."""
        vals: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            if f.name == "max_replans":
                vals[f.name] = sec.integer(f.name, lo=0, hi=100)
            elif f.name == "pass_over":
                vals[f.name] = sec.flag(f.name)
            else:
                hi = 86_400.0 if f.name.endswith("_s") else 10.0 if f.name.endswith("_m") else 1e6
                vals[f.name] = sec.num(f.name, lo=0, hi=hi, strict_lo=True)
        sec.finish()
        return cls(**vals)

    @classmethod
    def from_robot(cls, robot: SoftArmSections) -> "StateMachineParams":
        """The robot's ``[state_machine]`` (validated when the file was loaded)."""
        return robot.state_machine


@dataclasses.dataclass(frozen=True)
class BinParams:
    """Where ``moveToBin`` goes (``[bin]``): the straight pose or configured curvatures.

    ``kappa`` holds the left finger's object over the bin. ``kappa_right`` (a bin placed on the
    table for a gripper with fingers on both sides, :func:`core.control.row.bin_at`) holds the
    right finger's object over the same point; None: the right finger goes to ``kappa`` too (the
    robot file's bin, a configuration rather than a point).
    """

    kappa: Array
    drop_radius_m: float
    kappa_right: Array | None = None

    def kappa_for(self, side: str) -> Array:
        """The configuration ``moveToBin`` goes to with the object held by the ``side`` finger."""
        if side == "right" and self.kappa_right is not None:
            return self.kappa_right
        return self.kappa

    @classmethod
    def read(cls, sec: Section, n: int, kappa_max: float) -> "BinParams":
        """Read ``[bin]``: ``mode = "straight"``, or ``"kappa"`` with ``kappa`` = n curvatures."""
        mode = sec.choice("mode", ("straight", "kappa"))
        if mode == "kappa":
            kappa = np.array(sec.numbers("kappa", n, lo=-kappa_max, hi=kappa_max, broadcast=False))
        else:
            kappa = np.zeros(n)
            if "kappa" in sec.table:
                raise sec.error("kappa", "only used with mode = 'kappa'")
        p = cls(kappa, sec.num("drop_radius_m", lo=0, hi=10.0, strict_lo=True))
        sec.finish()
        return p

    @classmethod
    def from_robot(cls, robot: SoftArmSections) -> "BinParams":
        """The robot's ``[bin]`` (validated when the file was loaded)."""
        return robot.bin


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
    def read(cls, sec: Section, gripper_length: float) -> "SimParams":
        """Read ``[sim]`` with its ``[sim.mocap]`` and ``[sim.gripper]`` tables."""
        big = 1e9
        m, g = sec.sub("mocap"), sec.sub("gripper")
        grip = GripperSimParams(
            palm_length=g.num("palm_length", lo=0, strict_lo=True, hi=gripper_length),
            finger_half_width=g.num("finger_half_width", lo=0, hi=1.0, strict_lo=True),
            counts_closed=g.num("counts_closed", lo=0, hi=big, strict_lo=True),
            closed_turn=g.num("closed_turn", lo=0, strict_lo=True, hi=2 * math.pi),
            capture_turn=g.num("capture_turn", lo=0, strict_lo=True, hi=2 * math.pi),
            sweep_steps=g.integer("sweep_steps", lo=2, hi=10_000))
        mocap = MocapSimParams(
            noise_m=m.num("noise_m", lo=0, hi=1.0),
            object_noise_m=m.num("object_noise_m", lo=0, hi=1.0),
            occlusion_rate_hz=m.num("occlusion_rate_hz", lo=0, hi=1e4),
            occlusion_duration_s=m.interval("occlusion_duration_s"))
        p = cls(
            counts_per_kappa=sec.num("counts_per_kappa", lo=0, hi=big, strict_lo=True),
            tau_s=sec.num("tau_s", lo=0, hi=100, strict_lo=True),
            prepressure_stiffening=sec.num("prepressure_stiffening", lo=0, hi=1e3),
            prepressure_ref=sec.num("prepressure_ref", lo=0, hi=big, strict_lo=True),
            cylinder_rate=sec.num("cylinder_rate", lo=0, hi=big, strict_lo=True),
            cylinder_min=sec.num("cylinder_min", lo=-big, hi=big),
            cylinder_max=sec.num("cylinder_max", lo=-big, hi=big),
            stall_rate_hz=sec.num("stall_rate_hz", lo=0, hi=1e4),
            stall_duration_s=sec.interval("stall_duration_s"),
            stall_drive_threshold=sec.num("stall_drive_threshold", lo=0, hi=big),
            slip_overshoot=sec.num("slip_overshoot", lo=0, hi=100),
            slip_tau_s=sec.num("slip_tau_s", lo=0, hi=100, strict_lo=True),
            arm_half_width=sec.num("arm_half_width", lo=0, hi=1.0, strict_lo=True),
            mocap=mocap, gripper=grip)
        if p.cylinder_max <= p.cylinder_min:
            raise sec.error("cylinder_max", f"must be > cylinder_min ({p.cylinder_min:g}), "
                                            f"got {p.cylinder_max:g}")
        for s in (g, m, sec):
            s.finish()
        return p

    @classmethod
    def from_robot(cls, robot: SoftArmSections) -> "SimParams":
        """The robot's ``[sim]`` (validated when the file was loaded)."""
        return robot.sim

    def replace(self, **changes: Any) -> "SimParams":
        """A copy with some fields changed (``mocap=`` / ``gripper=`` take dicts of fields too)."""
        for key in ("mocap", "gripper"):
            if isinstance(changes.get(key), Mapping):
                changes[key] = dataclasses.replace(getattr(self, key), **changes[key])
        return dataclasses.replace(self, **changes)
