"""Robot descriptions loaded from data files, so parameters never live in code.

``load("soft-arm")`` / ``load("extensible")`` read ``data/robots/<name>.toml``; ``load(path)``
reads any TOML file of the same shape. Every section is read and checked once, here, into typed
frozen dataclasses (``robot.planner``, ``robot.controller``, ``robot.bridge``, ``robot.ik``, ...);
nothing else parses the file. Counts come from the file: ``segments.count`` sizes every
per-segment list, and a list that is given must match it. A missing, unknown or bad field raises
:class:`RobotFileError` naming file, section and key
(``soft-arm.toml: segments.length: must be > 0, got -1``).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Literal, Mapping, Union

import numpy as np
import numpy.typing as npt

from core.control.params import (BinParams, ControllerParams, SimParams, StateMachineParams,
                                  TrajectoryParams)
from core.planning.plan_types import PlannerConfig
from core.robot_schema import RobotFileError, Section, check_number, tomllib
from core.robot_sections import BridgeSection, EmulatorSection, IKSettings, PathSettings

__all__ = ["ROBOTS_DIR", "CaptureSpec", "ExtensibleArm", "GripperSpec", "MAX_SEGMENTS", "Robot",
           "RobotFileError", "Side", "SoftArm", "available", "check_number", "load", "parse"]

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "data" / "robots"

#: Largest ``segments.count`` per kind: the serial protocol carries at most 32 channels (2N + 1
#: drive cylinders, 3N motors), and a typo
#: (``count = 100000``) is refused at load instead of hanging start-up.
MAX_SEGMENTS = {"planar": 15, "delta": 4}

#: A side of the soft arm, seen from its base along the base heading.
Side = Literal["left", "right"]


@dataclasses.dataclass(frozen=True)
class GripperSpec:
    """Straight soft gripper at the arm tip; offsets are in the gripper-root frame."""

    length: float
    w_off_along: float
    g_off: float
    max_object_radius: float
    half_width: float
    fingers: Literal["left", "both"] = "left"

    @property
    def sides(self) -> tuple[Side, ...]:
        """The sides of the arm it can grasp on: ``("left",)`` (the paper's single finger,
        closing to the gripper's left) or ``("left", "right")`` (two stacked fingers on
        the gripper channel, :mod:`core.planning.sides`)."""
        return ("left", "right") if self.fingers == "both" else ("left",)

    @property
    def w_off(self) -> npt.NDArray[np.float64]:
        """Palm-point offset (along, normal) from the gripper root; normal is to the left."""
        return np.array([self.w_off_along, self.g_off])


@dataclasses.dataclass(frozen=True)
class CaptureSpec:
    """Capture region of the gripper (Katzschmann 2015, Fig. 6)."""

    diameter: float
    nominal_object_radius: float


@dataclasses.dataclass(frozen=True)
class SoftArm:
    """Soft planar grasping arm: N constant-curvature segments and a gripper.

    The serial link carries ``drive_cylinders`` = 2N + 1 channels: channels 2i and 2i + 1 are the
    two lateral drive cylinders of segment i, channel 2N is the gripper.

    The file's other sections, read and checked by :func:`load`: ``planner``
    (:class:`~core.planning.plan_types.PlannerConfig`), ``bridge`` / ``emulator``
    (:mod:`core.robot_sections`), ``controller``, ``trajectory``, ``state_machine``, ``bin`` and
    ``sim`` (:mod:`core.control.params`).
    """

    name: str
    base_pose: npt.NDArray[np.float64]
    n_segments: int
    segment_length: float
    kappa_max: float
    half_width: float
    gripper: GripperSpec
    capture: CaptureSpec
    drive_cylinders: int
    prepressurised_segments: int
    delta_d: float
    constraint_tolerance: float
    source: Path
    planner: PlannerConfig = dataclasses.field(repr=False)
    bridge: BridgeSection = dataclasses.field(repr=False)
    emulator: EmulatorSection = dataclasses.field(repr=False)
    controller: ControllerParams = dataclasses.field(repr=False)
    trajectory: TrajectoryParams = dataclasses.field(repr=False, compare=False)
    state_machine: StateMachineParams = dataclasses.field(repr=False)
    bin: BinParams = dataclasses.field(repr=False, compare=False)
    sim: SimParams = dataclasses.field(repr=False)

    kind = "planar"

    @property
    def lengths(self) -> npt.NDArray[np.float64]:
        """Segment lengths, shape (N,)."""
        return np.full(self.n_segments, self.segment_length)

    @property
    def kappa_limits(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Lower and upper curvature bounds, each shape (N,)."""
        k = np.full(self.n_segments, self.kappa_max)
        return -k, k

    @property
    def reach(self) -> float:
        """Upper bound on the palm point's distance from the base (straight arm)."""
        return self.n_segments * self.segment_length + math.hypot(
            self.gripper.w_off_along, self.gripper.g_off
        )


@dataclasses.dataclass(frozen=True)
class ExtensibleArm:
    """Extensible tri-rack arm in the Delta-parametrisation (Hughes 2020).

    Limits: every rack length in [rack_min, rack_max]; every segment's bend
    theta = |(dx, dy)| / d <= theta_max (rad); rack speeds <= rack_speed and motor speeds (the
    motor travels m = U^-1 L, in metres of rack travel driven by the motor's pinion, so one
    count is 1 / counts_per_metre m) <= motor_speed (m/s); tip speed <= tip_speed (m/s).
    ``n_motors`` = 3N (one per rack). The file's other sections: ``bridge`` / ``emulator`` and
    the optional ``ik`` / ``paths`` (:mod:`core.robot_sections`).

    ``half_width`` is the platform radius the console draws; ``body_radius`` (m, default
    ``half_width``, at least ``rack_radius``) is the arm's body for box clearance: every point
    within it of the backbone (racks and platforms) counts as the arm
    (:mod:`core.kinematics.box_clearance`).
    """

    name: str
    n_segments: int
    rack_radius: float
    phi: float
    L0: float
    rack_min: float
    rack_max: float
    theta_max: float
    half_width: float
    body_radius: float
    tip_speed: float
    rack_speed: float
    motor_speed: float
    n_motors: int
    counts_per_metre: float
    motor_mapping: str
    source: Path
    bridge: BridgeSection = dataclasses.field(repr=False)
    emulator: EmulatorSection = dataclasses.field(repr=False)
    ik: IKSettings = dataclasses.field(default_factory=IKSettings, repr=False)
    paths: PathSettings = dataclasses.field(default_factory=PathSettings, repr=False)

    kind = "delta"

    @property
    def d(self) -> float:
        """Racks' radial distance from the backbone."""
        return self.rack_radius

    @property
    def bend_max(self) -> float:
        """Largest bending magnitude |(dx, dy)| = d * theta_max of a segment (m)."""
        return self.rack_radius * self.theta_max

    @property
    def motor_speed_counts(self) -> float:
        """``motor_speed`` in encoder counts per second."""
        return self.motor_speed * self.counts_per_metre


Robot = Union[SoftArm, ExtensibleArm]


def _soft_arm(top: Section, source: Path) -> SoftArm:
    base, seg, grip = top.sub("base"), top.sub("segments"), top.sub("gripper")
    cap, act = top.sub("capture"), top.sub("actuation")
    pose = base.value("pose")
    if (not isinstance(pose, list) or len(pose) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in pose)
            or max(abs(pose[0]), abs(pose[1])) > 100 or abs(pose[2]) > 2 * math.pi):
        raise base.error("pose", f"must be [x, y, theta] with |x|, |y| <= 100 m and "
                                 f"|theta| <= 2 pi, got {pose!r}")
    n = seg.integer("count", lo=1, hi=MAX_SEGMENTS["planar"])
    gripper = GripperSpec(
        length=grip.num("length", lo=0, hi=10.0, strict_lo=True),
        w_off_along=grip.num("w_off_along", lo=0, hi=10.0),
        g_off=grip.num("g_off", lo=0, hi=10.0),
        max_object_radius=grip.num("max_object_radius", lo=0, hi=10.0, strict_lo=True),
        half_width=grip.num("half_width", lo=0, hi=10.0, strict_lo=True),
        fingers=grip.choice("fingers", ("left", "both"), default="left"),
    )
    if gripper.w_off_along > gripper.length:
        raise grip.error("w_off_along", f"must be <= gripper.length ({gripper.length:g}), "
                                        f"got {gripper.w_off_along:g}")
    kappa_max = seg.num("kappa_max", lo=0, hi=1e4, strict_lo=True)
    channels = 2 * n + 1
    cylinders = act.value("drive_cylinders", channels)
    if isinstance(cylinders, bool) or cylinders != channels:
        raise act.error("drive_cylinders", f"must be 2 per segment + gripper = {channels} "
                                           f"(segments.count = {n}), got {cylinders!r}")
    planner = PlannerConfig.read(top.sub("planner"), n)
    arm = SoftArm(
        name=top.text("name"),
        base_pose=np.array(pose, dtype=float),
        n_segments=n,
        segment_length=seg.num("length", lo=0, hi=10.0, strict_lo=True),
        kappa_max=kappa_max,
        half_width=seg.num("half_width", lo=0, hi=10.0),
        gripper=gripper,
        capture=CaptureSpec(
            diameter=cap.num("diameter", lo=0, hi=10.0, strict_lo=True),
            nominal_object_radius=cap.num("nominal_object_radius", lo=0, hi=10.0, strict_lo=True),
        ),
        drive_cylinders=channels,
        prepressurised_segments=act.integer("prepressurised_segments", lo=0, hi=n),
        delta_d=planner.delta_d,
        constraint_tolerance=planner.constraint_tolerance,
        source=source,
        planner=planner,
        bridge=BridgeSection.read(top.sub("bridge")),
        emulator=EmulatorSection.read(top.sub("emulator"), planar=True),
        controller=ControllerParams.read(top.sub("controller")),
        trajectory=TrajectoryParams.read(top.sub("trajectory"), n),
        state_machine=StateMachineParams.read(top.sub("state_machine")),
        bin=BinParams.read(top.sub("bin"), n, kappa_max),
        sim=SimParams.read(top.sub("sim"), gripper.length),
    )
    for s in (base, seg, grip, cap, act):
        s.finish()
    return arm


def _extensible(top: Section, source: Path) -> ExtensibleArm:
    seg, lim, mot = top.sub("segments"), top.sub("limits"), top.sub("motors")
    n = seg.integer("count", lo=1, hi=MAX_SEGMENTS["delta"])
    rack_min = seg.num("rack_min", lo=0, hi=10.0)
    rack_max = seg.num("rack_max", lo=0, hi=10.0, strict_lo=True)
    if rack_max <= rack_min:
        raise seg.error("rack_max", f"must be > segments.rack_min ({rack_min:g}), got {rack_max:g}")
    n_motors = mot.value("count", 3 * n)
    if isinstance(n_motors, bool) or n_motors != 3 * n:
        raise mot.error("count", f"must be 3 per segment ({3 * n}, segments.count = {n}), "
                                 f"got {n_motors!r}")
    mapping = mot.choice("mapping", ("block_upper_triangular",), default="block_upper_triangular")
    counts_per_metre = mot.num("counts_per_metre", lo=0, hi=1e12, strict_lo=True)
    motor_speed = lim.num("motor_speed", lo=0, hi=100.0, strict_lo=True)
    emulator = EmulatorSection.read(top.sub("emulator"), planar=False)
    need = motor_speed * counts_per_metre
    if emulator.motor_speed_counts < need:  # the emulated motors must keep up with the planner
        raise RobotFileError(
            f"{top.file}: emulator.motor_speed_counts: must be >= limits.motor_speed * "
            f"motors.counts_per_metre ({need:g} counts/s) or the emulated motors lag every "
            f"planned path, got {emulator.motor_speed_counts:g}")
    rack_radius = seg.num("rack_radius", lo=0, hi=10.0, strict_lo=True)
    half_width = seg.num("half_width", lo=0, hi=10.0, strict_lo=True)
    body_radius = seg.num("body_radius", lo=0, hi=10.0, default=half_width)
    if body_radius < rack_radius:
        raise seg.error("body_radius", f"must be >= segments.rack_radius ({rack_radius:g} m): "
                                       f"the racks run at that radius, got {body_radius:g}")
    arm = ExtensibleArm(
        name=top.text("name"),
        n_segments=n,
        rack_radius=rack_radius,
        phi=seg.num("phi", lo=-2 * math.pi, hi=2 * math.pi),
        L0=seg.num("L0", lo=0, hi=10.0),
        rack_min=rack_min,
        rack_max=rack_max,
        theta_max=seg.num("theta_max", lo=0, hi=2 * math.pi, strict_lo=True),
        half_width=half_width,
        body_radius=body_radius,
        tip_speed=lim.num("tip_speed", lo=0, hi=100.0, strict_lo=True),
        rack_speed=lim.num("rack_speed", lo=0, hi=100.0, strict_lo=True),
        motor_speed=motor_speed,
        n_motors=3 * n,
        counts_per_metre=counts_per_metre,
        motor_mapping=mapping,
        source=source,
        bridge=BridgeSection.read(top.sub("bridge")),
        emulator=emulator,
        ik=IKSettings.read(top.sub("ik", required=False)),
        paths=PathSettings.read(top.sub("paths", required=False)),
    )
    for s in (seg, lim, mot):
        s.finish()
    return arm


def available() -> list[str]:
    """Names of the robot descriptions shipped in ``data/robots``."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.toml"))


def parse(table: Mapping[str, Any], source: Path | str, *, label: str | None = None) -> Robot:
    """Build a robot from an already-parsed TOML table (as :func:`load` does after reading).

    Args:
        table: The whole file as a table.
        source: Where it came from (kept as ``robot.source``).
        label: File name used in messages (default: ``source``'s name).

    Raises:
        RobotFileError: a field is missing, unknown or bad; the message names file and field.
    """
    source = Path(source)
    top = Section(table, label or source.name)
    kind = top.choice("kind", ("planar", "delta"))
    robot: Robot = _soft_arm(top, source) if kind == "planar" else _extensible(top, source)
    top.finish()
    return robot


def load(name_or_path: str | Path) -> Robot:
    """Load a robot description by shipped name (``"soft-arm"``) or by TOML path.

    Raises:
        RobotFileError: the file is missing, is not TOML, or a field is missing, unknown or bad;
            the message names the file and the field (``section.key``).
    """
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = ROBOTS_DIR / f"{name_or_path}.toml"
        if not path.exists():
            raise RobotFileError(
                f"unknown robot {str(name_or_path)!r}; shipped robots: {', '.join(available())}")
    try:
        table = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise RobotFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotFileError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise RobotFileError(f"{path}: not valid TOML: {exc}") from None
    shipped = path.resolve().parent == ROBOTS_DIR
    return parse(table, path, label=path.name if shipped else str(path))
