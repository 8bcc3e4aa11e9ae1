"""Robot-specific configuration rules for the console, so panels never branch on the robot kind.

An :class:`ArmModel` knows the configuration ``q`` of one robot (soft arm: curvatures (N,);
extensible: deltas (n, 3)), its jog coordinates with their slider ranges, how to validate a
request (bad input raises ``ValueError`` with a clear message and moves nothing) and how to keep
it inside the robot's limits (curvature bounds; rack lengths within [rack_min, rack_max] and each
segment's bend theta = |(dx, dy)| / d within theta_max), reporting every clamp in words.

Rack feasibility of an extensible segment is linear: rack j has length
``L0 + dL - dx cos(beta_j) - dy sin(beta_j)`` (see ``core.kinematics.delta``), so moving one
coordinate with the others fixed keeps the racks feasible on an interval; the bending limit
|(dx, dy)| <= d theta_max is a disc, so it too leaves an interval for dx (or dy). Scaling the
bending (dx, dy) towards 0 at fixed dL reaches both whenever dL itself is feasible.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from typing import Literal

import numpy as np
import numpy.typing as npt

from core.units import fmt_deg, fmt_mm
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.robots import ExtensibleArm, Robot, SoftArm

Array = npt.NDArray[np.float64]
_EPS = 1e-12
# Jog speed of the extensible arm at start (m/s, fastest arm point: the tip, mostly): slow enough
# for a class to follow a held jog (the full rack speed swept the tip ~255 mm in 2 s, issue 31).
EXTENSIBLE_JOG_SPEED = 0.02
_SUB = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")


def subscript(i: int) -> str:
    """``3`` -> ``₃`` for labels."""
    return str(i).translate(_SUB)


@dataclasses.dataclass(frozen=True)
class Coordinate:
    """One jog coordinate: where it sits in ``q`` and its slider range."""

    key: str
    label: str
    unit: str
    index: tuple[int, ...]
    lo: float
    hi: float
    step: float
    segment: int
    hint: str = ""


class ArmModel(ABC):
    """Configuration rules of one robot; all methods are pure and thread-safe."""

    kind: Literal["planar", "delta"]
    robot: Robot
    shape: tuple[int, ...]
    coordinates: tuple[Coordinate, ...]
    # The Jog panel's speed (m/s of the fastest arm point) the console starts with, and the most
    # the operator may set; None: hold-to-run's own cap (``console.core.hold_to_run``).
    jog_speed: float | None = None
    max_jog_speed: float | None = None

    def zero(self) -> Array:
        """The all-zero configuration (straight arm; retracted for the extensible arm)."""
        return np.zeros(self.shape)

    def initial(self) -> Array:
        """Where the console starts (the store's first command): the zero configuration unless
        the robot needs room to move (see :meth:`ExtensibleModel.initial`)."""
        return self.zero()

    def validate(self, q: npt.ArrayLike) -> Array:
        """A float copy of ``q``; raises ValueError naming the problem for bad input."""
        try:
            arr = np.array(q, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"configuration must be numeric with shape {self.shape}") from None
        if arr.shape != self.shape:
            raise ValueError(f"configuration must have shape {self.shape}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("configuration must be finite (no NaN or inf)")
        return arr

    @abstractmethod
    def clamp(self, q: Array) -> tuple[Array, tuple[str, ...]]:
        """Nearest-in-spirit configuration within the limits, and a note per clamp."""

    def limit_note(self, q: Array, coord: Coordinate) -> str | None:
        """What stops ``coord`` at ``q`` when it sits within one slider step of a limit that its
        slider's range ends at (a browser clamps a typed number to that range end), else None."""
        return None

    @abstractmethod
    def set_coordinate(self, q: Array, coord: Coordinate, value: float) -> tuple[Array, str | None]:
        """``q`` with one coordinate set to ``value``, clamped so ``q`` stays within limits.

        Returns the new configuration and a note when the value had to be clamped.
        """

    @abstractmethod
    def straightened(self, q: Array) -> Array:
        """``q`` without bending (extension kept for the extensible arm)."""


class SoftArmModel(ArmModel):
    """Soft arm (planar): q = curvatures (N,) in 1/m, each within +-kappa_max."""

    kind = "planar"
    robot: SoftArm

    def __init__(self, robot: SoftArm) -> None:
        self.robot = robot
        self.shape = (robot.n_segments,)
        k = robot.kappa_max
        self.coordinates = tuple(
            Coordinate(key=f"kappa{i + 1}", label=f"κ{subscript(i + 1)}", unit="1/m", index=(i,),
                       lo=-k, hi=k, step=0.1, segment=i,
                       hint=f"Curvature of segment {i + 1}; > 0 turns counter-clockwise.")
            for i in range(robot.n_segments))

    def clamp(self, q: Array) -> tuple[Array, tuple[str, ...]]:
        k = self.robot.kappa_max
        out = np.clip(q, -k, k)
        notes = tuple(f"κ{subscript(i + 1)} clamped to {out[i]:+.1f} 1/m (limit ±{k:g})"
                      for i in np.flatnonzero(out != q))
        return out, notes

    def set_coordinate(self, q: Array, coord: Coordinate, value: float) -> tuple[Array, str | None]:
        out = q.copy()
        out[coord.index] = value
        out, notes = self.clamp(out)
        return out, (notes[0] if notes else None)

    def straightened(self, q: Array) -> Array:
        return np.zeros_like(q)

    def poses(self, q: Array) -> Array:
        """[x, y, theta] at the base and every segment end, (N+1, 3)."""
        return pk.forward_kinematics(q, self.robot.lengths, self.robot.base_pose)

    def palm_point(self, tip_pose: Array) -> Array:
        """Palm point w_t (x, y) for the arm tip (gripper root) pose."""
        return pk.point_in_frame(tip_pose, self.robot.gripper.w_off)


class ExtensibleModel(ArmModel):
    """Extensible arm: q = deltas (n, 3) = (dx, dy, dL) per segment, racks within limits and
    every segment's bend within theta_max."""

    kind = "delta"
    robot: ExtensibleArm

    def __init__(self, robot: ExtensibleArm) -> None:
        self.robot = robot
        self.shape = (robot.n_segments, 3)
        self.max_jog_speed = robot.tip_speed  # the arm's own tip speed limit (limits.tip_speed)
        self.jog_speed = min(EXTENSIBLE_JOG_SPEED, robot.tip_speed)
        beta = dk.rack_angles(robot.phi)
        # d rack_j / d(dx, dy, dL), shape (3 coords, 3 racks).
        self.rack_gradient = np.stack([-np.cos(beta), -np.sin(beta), np.ones(3)])
        span = robot.rack_max - robot.rack_min
        self.bend_max = robot.rack_radius * robot.theta_max  # largest |(dx, dy)|
        # Widest bending reachable at any extension (racks and bending limit), rounded down to
        # the 1 mm slider step.
        bound = [math.floor(min(span / float(np.ptp(g)), self.bend_max) / 0.001 + 1e-6) * 0.001
                 for g in self.rack_gradient[:2]]
        limit = f"θ ≤ {math.degrees(robot.theta_max):.0f}°"
        coords = []
        for i in range(robot.n_segments):
            s = subscript(i + 1)
            coords += [
                Coordinate(f"dx{i + 1}", f"Δx{s}", "m", (i, 0), -bound[0], bound[0], 0.001, i,
                           f"Segment {i + 1}: bend toward +x (racks within limits, {limit})."),
                Coordinate(f"dy{i + 1}", f"Δy{s}", "m", (i, 1), -bound[1], bound[1], 0.001, i,
                           f"Segment {i + 1}: bend toward +y (racks within limits, {limit})."),
                Coordinate(f"dL{i + 1}", f"δL{s}", "m", (i, 2), robot.rack_min - robot.L0,
                           robot.rack_max - robot.L0, 0.001, i,
                           f"Segment {i + 1}: extension; L = L0 + δL."),
            ]
        self.coordinates = tuple(coords)

    def initial(self) -> Array:
        """Straight, every rack at the middle of [rack_min, rack_max] (whole millimetres):
        :func:`core.kinematics.delta.mid_range_delta`, where the device emulator starts too.

        Retracted (zero) every rack sits at rack_min, so no segment can bend: bending one way
        shortens a rack. At mid-range each rack has (rack_max - rack_min) / 2 of travel both
        ways, so every jog, target and path starts with room to move. A rule on the robot's
        own limits (data/robots/*.toml), so every extensible robot file gets its own.
        """
        return dk.mid_range_delta(self.robot)

    def rack_lengths(self, q: Array) -> Array:
        """Rack lengths (n, 3) in metres."""
        return dk.robot_rack_lengths(self.robot, q)

    def frames(self, q: Array) -> Array:
        """Base frame and every segment's tip frame, (n+1, 4, 4)."""
        return dk.forward_kinematics(q, self.robot.L0, self.robot.d)

    def feasible_interval(self, q: Array, segment: int, axis: int) -> tuple[float, float]:
        """Interval of q[segment, axis] keeping that segment's racks within limits, others fixed.

        Empty (lo > hi) only if the segment is already infeasible. See :meth:`bend_interval`
        for the bending limit.
        """
        r = self.robot
        racks = self.rack_lengths(q[segment])
        g = self.rack_gradient[axis]
        v = q[segment, axis]
        lo, hi = -math.inf, math.inf
        for gj, rj in zip(g, racks):
            if abs(gj) < 1e-9:
                continue
            a, b = v + (r.rack_min - rj) / gj, v + (r.rack_max - rj) / gj
            lo, hi = max(lo, min(a, b)), min(hi, max(a, b))
        return lo, hi

    def bend_interval(self, q: Array, segment: int, axis: int) -> tuple[float, float]:
        """Interval of q[segment, axis] keeping that segment's bend within theta_max, the other
        coordinates fixed (the whole line for dL)."""
        if axis == 2:
            return -math.inf, math.inf
        other = float(q[segment, 1 - axis])
        # A hair inside the disc, so rounding never leaves the bend above theta_max.
        half = math.sqrt(max(self.bend_max ** 2 - other ** 2, 0.0)) * (1 - 1e-12)
        return -half, half

    def limit_note(self, q: Array, coord: Coordinate) -> str | None:
        seg, axis = coord.index
        if axis == 2:
            return None
        blo, bhi = self.bend_interval(q, seg, axis)
        value = float(q[seg, axis])
        if min(bhi - value, value - blo) >= coord.step:
            return None
        return (f"{coord.label} at {fmt_mm(value, 0, sign=True)} mm: segment {seg + 1} at its "
                f"bending limit θ = {fmt_deg(self.robot.theta_max, 0)}° "
                f"(|(Δx, Δy)| ≤ {fmt_mm(self.bend_max, 0)} mm)")

    def set_coordinate(self, q: Array, coord: Coordinate, value: float) -> tuple[Array, str | None]:
        seg, axis = coord.index
        out, notes = self.clamp(q)  # the rest of q must be feasible for the interval to exist
        lo, hi = self.feasible_interval(out, seg, axis)
        blo, bhi = self.bend_interval(out, seg, axis)
        clamped = min(max(value, max(lo, blo)), min(hi, bhi))
        out[seg, axis] = clamped
        if abs(clamped - value) <= 1e-9:
            return out, (notes[0] if notes else None)
        if (bhi <= hi) if value > clamped else (blo >= lo):  # the bending limit binds
            return out, (f"{coord.label} clamped to {fmt_mm(clamped, 0, sign=True)} mm: segment "
                         f"{seg + 1} at its bending limit θ = {fmt_deg(self.robot.theta_max, 0)}° "
                         f"(|(Δx, Δy)| ≤ {fmt_mm(self.bend_max, 0)} mm)")
        racks = self.rack_lengths(out[seg])
        limits = (self.robot.rack_min, self.robot.rack_max)
        which, j = np.unravel_index(np.argmin(np.abs(racks[None] - np.array(limits)[:, None])),
                                    (2, 3))
        limit = limits[which]
        note = (f"{coord.label} clamped to {fmt_mm(clamped, 0, sign=True)} mm: rack {j + 1} of "
                f"segment {seg + 1} at its {fmt_mm(limit, 0)} mm limit")
        if axis < 2 and hi - lo < 1e-9:
            note += f" (extend δL{subscript(seg + 1)} first to make room for bending)"
        return out, note

    def clamp(self, q: Array) -> tuple[Array, tuple[str, ...]]:
        r = self.robot
        out = q.copy()
        notes = []
        dl = np.clip(out[:, 2], r.rack_min - r.L0, r.rack_max - r.L0)
        for i in np.flatnonzero(dl != out[:, 2]):
            notes.append(f"δL{subscript(i + 1)} clamped to {fmt_mm(dl[i], 0)} mm (rack limits)")
        out[:, 2] = dl
        length = r.L0 + dl  # (n,) rack length with no bending
        bend = out[:, :2] @ self.rack_gradient[:2]  # (n, 3) rack change due to bending
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            room = np.where(bend > _EPS, (r.rack_max - length[:, None]) / bend,
                            np.where(bend < -_EPS, (r.rack_min - length[:, None]) / bend, np.inf))
            size = np.hypot(out[:, 0], out[:, 1])
            bend_room = np.where(size > self.bend_max, self.bend_max * (1 - 1e-12) / size, np.inf)
        rack_scale = np.clip(np.min(room, axis=1), 0.0, 1.0)
        scale = np.minimum(rack_scale, bend_room)
        for i in np.flatnonzero(scale < 1.0 - 1e-12):
            if bend_room[i] < rack_scale[i]:
                notes.append(f"segment {i + 1} bending scaled to {scale[i]:.0%} to stay within "
                             f"its bending limit θ = {fmt_deg(r.theta_max, 0)}°")
            else:
                notes.append(f"segment {i + 1} bending scaled to {scale[i]:.0%} to keep racks "
                             f"within [{fmt_mm(r.rack_min, 0)}, {fmt_mm(r.rack_max, 0)}] mm")
        out[:, :2] *= scale[:, None]
        return out, tuple(notes)

    def straightened(self, q: Array) -> Array:
        out = q.copy()
        out[:, :2] = 0.0
        return out


def model_for(robot: Robot) -> ArmModel:
    """The console model of a loaded robot description."""
    if isinstance(robot, SoftArm):
        return SoftArmModel(robot)
    if isinstance(robot, ExtensibleArm):
        return ExtensibleModel(robot)
    raise TypeError(f"no console model for {type(robot).__name__}")
