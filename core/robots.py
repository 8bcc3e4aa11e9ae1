"""Robot descriptions loaded from data files, so parameters never live in code.

``load("soft-arm")`` / ``load("extensible")`` read ``data/robots/<name>.toml``; ``load(path)``
reads any TOML file of the same shape. A missing or wrong field raises
:class:`RobotFileError` naming the field (``segments.length: must be > 0, got -1``).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any, Mapping, Union

import numpy as np
import numpy.typing as npt

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "data" / "robots"


class RobotFileError(ValueError):
    """A robot description file is missing a field or has a bad value."""


@dataclasses.dataclass(frozen=True)
class GripperSpec:
    """Straight soft gripper at the arm tip; offsets are in the gripper-root frame."""

    length: float
    w_off_along: float
    g_off: float
    max_object_radius: float
    half_width: float

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
    """Soft planar grasping arm: N constant-curvature segments and a gripper."""

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
    raw: Mapping[str, Any] = dataclasses.field(repr=False, compare=False)

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
    tip_speed: float
    rack_speed: float
    motor_speed: float
    n_motors: int
    counts_per_metre: float
    motor_mapping: str
    source: Path
    raw: Mapping[str, Any] = dataclasses.field(repr=False, compare=False)

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


def _get(table: Mapping[str, Any], dotted: str) -> Any:
    node: Any = table
    for part in dotted.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise RobotFileError(f"{dotted}: missing")
        node = node[part]
    return node


def check_number(value: Any, field: str, *, lo: float | None = None, hi: float | None = None,
                 strict_lo: bool = False) -> float:
    """``value`` as a finite float within bounds, or :class:`RobotFileError` naming ``field``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RobotFileError(f"{field}: must be a finite number, got {value!r}")
    value = float(value)
    if lo is not None and (value <= lo if strict_lo else value < lo):
        raise RobotFileError(f"{field}: must be {'>' if strict_lo else '>='} {lo:g}, got {value:g}")
    if hi is not None and value > hi:
        raise RobotFileError(f"{field}: must be <= {hi:g}, got {value:g}")
    return value


def _num(table: Mapping[str, Any], dotted: str, *, lo: float | None = None,
         hi: float | None = None, strict_lo: bool = False) -> float:
    return check_number(_get(table, dotted), dotted, lo=lo, hi=hi, strict_lo=strict_lo)


def _int(table: Mapping[str, Any], dotted: str, *, lo: int = 1, hi: int | None = None) -> int:
    value = _get(table, dotted)
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise RobotFileError(f"{dotted}: must be an integer >= {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise RobotFileError(f"{dotted}: must be an integer in {lo}..{hi}, got {value!r}")
    return value


MAX_SEGMENTS = 32  # the serial protocol carries at most 32 channels (hw_bridge.protocol)


def _soft_arm(t: Mapping[str, Any], source: Path) -> SoftArm:
    pose = _get(t, "base.pose")
    if (not isinstance(pose, list) or len(pose) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pose)):
        raise RobotFileError(f"base.pose: must be [x, y, theta], got {pose!r}")
    gripper = GripperSpec(
        length=_num(t, "gripper.length", lo=0, strict_lo=True),
        w_off_along=_num(t, "gripper.w_off_along", lo=0),
        g_off=_num(t, "gripper.g_off", lo=0),
        max_object_radius=_num(t, "gripper.max_object_radius", lo=0, strict_lo=True),
        half_width=_num(t, "gripper.half_width", lo=0, strict_lo=True),
    )
    if gripper.w_off_along > gripper.length:
        raise RobotFileError(
            f"gripper.w_off_along: must be <= gripper.length ({gripper.length:g}), "
            f"got {gripper.w_off_along:g}")
    return SoftArm(
        name=str(_get(t, "name")),
        base_pose=np.array(pose, dtype=float),
        n_segments=_int(t, "segments.count", hi=MAX_SEGMENTS),
        segment_length=_num(t, "segments.length", lo=0, strict_lo=True),
        kappa_max=_num(t, "segments.kappa_max", lo=0, strict_lo=True),
        half_width=_num(t, "segments.half_width", lo=0),
        gripper=gripper,
        capture=CaptureSpec(
            diameter=_num(t, "capture.diameter", lo=0, strict_lo=True),
            nominal_object_radius=_num(t, "capture.nominal_object_radius", lo=0, strict_lo=True),
        ),
        drive_cylinders=_int(t, "actuation.drive_cylinders"),
        prepressurised_segments=_int(t, "actuation.prepressurised_segments", lo=0),
        delta_d=_num(t, "planner.delta_d", lo=0, strict_lo=True),
        constraint_tolerance=_num(t, "planner.constraint_tolerance", lo=0, strict_lo=True),
        source=source,
        raw=t,
    )


def _extensible(t: Mapping[str, Any], source: Path) -> ExtensibleArm:
    rack_min = _num(t, "segments.rack_min", lo=0)
    rack_max = _num(t, "segments.rack_max", lo=0, strict_lo=True)
    if rack_max <= rack_min:
        raise RobotFileError(
            f"segments.rack_max: must be > segments.rack_min ({rack_min:g}), got {rack_max:g}")
    n_segments = _int(t, "segments.count", hi=MAX_SEGMENTS)
    n_motors = _int(t, "motors.count")
    if n_motors != 3 * n_segments:
        raise RobotFileError(
            f"motors.count: must be 3 per segment ({3 * n_segments}), got {n_motors}")
    mapping = _get(t, "motors.mapping")
    if mapping != "block_upper_triangular":
        raise RobotFileError(f"motors.mapping: must be 'block_upper_triangular', got {mapping!r}")
    counts_per_metre = _num(t, "motors.counts_per_metre", lo=0, strict_lo=True)
    motor_speed = _num(t, "limits.motor_speed", lo=0, strict_lo=True)
    emulator = t.get("emulator")
    if isinstance(emulator, Mapping) and "motor_speed_counts" in emulator:
        # The emulated motors must keep up with what the planner asks of the real ones.
        emu = check_number(emulator["motor_speed_counts"], "emulator.motor_speed_counts",
                           lo=0, strict_lo=True)
        need = motor_speed * counts_per_metre
        if emu < need:
            raise RobotFileError(
                f"emulator.motor_speed_counts: must be >= limits.motor_speed * "
                f"motors.counts_per_metre ({need:g} counts/s) or the emulated motors lag every "
                f"planned path, got {emu:g}")
    return ExtensibleArm(
        name=str(_get(t, "name")),
        n_segments=n_segments,
        rack_radius=_num(t, "segments.rack_radius", lo=0, strict_lo=True),
        phi=_num(t, "segments.phi"),
        L0=_num(t, "segments.L0", lo=0),
        rack_min=rack_min,
        rack_max=rack_max,
        theta_max=_num(t, "segments.theta_max", lo=0, hi=2 * math.pi, strict_lo=True),
        half_width=_num(t, "segments.half_width", lo=0, strict_lo=True),
        tip_speed=_num(t, "limits.tip_speed", lo=0, strict_lo=True),
        rack_speed=_num(t, "limits.rack_speed", lo=0, strict_lo=True),
        motor_speed=motor_speed,
        n_motors=n_motors,
        counts_per_metre=counts_per_metre,
        motor_mapping=mapping,
        source=source,
        raw=t,
    )


def available() -> list[str]:
    """Names of the robot descriptions shipped in ``data/robots``."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.toml"))


def load(name_or_path: str | Path) -> Robot:
    """Load a robot description by shipped name (``"soft-arm"``) or by TOML path.

    Raises:
        RobotFileError: the file is missing, is not TOML, or a field is missing or bad;
            the message names the field.
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
    except tomllib.TOMLDecodeError as exc:
        raise RobotFileError(f"{path}: not valid TOML: {exc}") from None
    kind = table.get("kind")
    try:
        if kind == "planar":
            return _soft_arm(table, path)
        if kind == "delta":
            return _extensible(table, path)
    except RobotFileError as exc:
        raise RobotFileError(f"{path.name}: {exc}") from None
    raise RobotFileError(f"{path.name}: kind: must be 'planar' or 'delta', got {kind!r}")
