"""Tip motion paths for the extensible arm: Fig. 9's traverses and corners, sampled for the motors.

A path is a polyline of tip waypoints (the builders in :mod:`core.planning.path_shapes`,
re-exported here, make the paper's linear traverse, diagonal traverse and four corners from a
centre, a size and a plane; :func:`polyline` takes any list).
:func:`plan_path` turns it into a :class:`MotionPath` a 100 Hz loop can stream:

1. the polyline is sampled every ``spacing`` metres of tip travel (corners kept exactly) and the
   tip IK is solved per sample, warm-started from the previous one and without restarts, so the
   solution follows one continuous branch; an interval whose racks move more than
   ``jump_ratio`` times the tip displacement is bisected (``max_bisections`` times), and one
   still that steep is counted in ``MotionPath.jumps``; where the branch cannot reach the
   target (it ran into rack or bending limits) the IK restarts may switch branch (also a jump);
2. time law (:func:`timed_path`): each interval lasts max(tip travel / speed, largest rack
   travel / rack_speed, largest motor travel / motor_speed), the limits scaled by
   ``limit_margin``, so the tip speed (Table I: 0.10 m/s), every rack's speed and every motor's
   speed stay within their limits. Motor travels are m = U^-1 L: a proximal motor moves by the
   difference of its segment's rack and the next segment's, up to twice the rack speed, so the
   motor limit binds when consecutive segments' racks move in opposite directions. The motor
   limit also keeps one encoder count in reserve per sample, so the rounded demands obey it;
3. the rack lengths are interpolated linearly in time at ``rate_hz``, so consecutive samples move
   a rack by at most rack_speed / rate_hz and Delta = M L - Delta_0 by at most ||M||_inf times
   that (no jumps); tips are recomputed by forward kinematics and every sample's error to its
   tip target is reported. Every IK sample is within the rack box and the bending limit
   (theta <= theta_max) and that set is convex, so every interpolated sample is too;
4. motor demands: U^-1 L in encoder counts (:func:`delta.motor_counts_from_lengths`).

Settings come from the robot file's optional ``[paths]`` table.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robot_sections import IKSettings, PathSettings
from core.planning.path_shapes import (PATH_KINDS, PathKind, Plane, build_path,  # noqa: F401
                                       diagonal_traverse, four_corners, linear_traverse,
                                       polyline)

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class MotionPath:
    """A time-parametrised tip path, sampled at ``rate_hz``; K samples, n segments.

    Attributes:
        times: (K,) s, from 0 in steps of 1 / rate_hz.
        targets: (K, 3) tip targets on the polyline.
        tips: (K, 3) tips reached by ``deltas`` (forward kinematics).
        deltas: (K, n, 3) postures.
        lengths: (K, n, 3) rack lengths, within [rack_min, rack_max], every segment's bend
            within theta_max.
        motor_counts: (K, 3n) encoder demands, U^-1 L in counts; consecutive samples differ by
            at most motor_speed * counts_per_metre / rate_hz counts.
        errors: (K,) |targets - tips| (m).
        rate_hz: Sample rate.
        jumps: Branch switches plus IK intervals still steeper than ``jump_ratio`` after
            bisection; the racks cross them at their speed limit, the tip off the path.
    """

    times: Array
    targets: Array
    tips: Array
    deltas: Array
    lengths: Array
    motor_counts: npt.NDArray[np.int64]
    errors: Array
    rate_hz: float
    jumps: int

    @property
    def duration(self) -> float:
        """Time of the last sample (s)."""
        return float(self.times[-1])

    @property
    def max_error(self) -> float:
        """Largest distance between a target and the tip reached (m)."""
        return float(self.errors.max())

    def max_tip_speed(self) -> float:
        """Largest tip speed between consecutive samples (m/s)."""
        return _max_rate(self.tips, self.times, norm="l2")

    def max_rack_speed(self) -> float:
        """Largest single-rack speed between consecutive samples (m/s)."""
        return _max_rate(self.lengths.reshape(len(self.times), -1), self.times, norm="inf")

    def max_motor_speed(self) -> float:
        """Largest single-motor speed between consecutive samples, from the lengths (m/s of
        rack travel, like ``motor_speed``)."""
        motors = dk.motors_from_lengths(self.lengths).reshape(len(self.times), -1)
        return _max_rate(motors, self.times, norm="inf")

    def max_delta_step(self) -> float:
        """Largest change of any Delta component between consecutive samples (m)."""
        if len(self.times) < 2:
            return 0.0
        return float(np.abs(np.diff(self.deltas, axis=0)).max())


def _max_rate(x: Array, t: Array, norm: Literal["l2", "inf"]) -> float:
    if len(t) < 2:
        return 0.0
    dx = np.diff(x, axis=0)
    step = np.linalg.norm(dx, axis=1) if norm == "l2" else np.abs(dx).max(axis=1)
    return float((step / np.diff(t)).max())


def _sample_polyline(points: Array, spacing: float) -> Array:
    """Points every <= ``spacing`` along the polyline, its vertices included exactly."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / spacing))
        if np.allclose(a, b):
            continue
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.vstack(out)


def _track(robot: "ExtensibleArm", targets: Array, first: Array, ik: IKSettings,
           ps: PathSettings) -> tuple[Array, Array, int]:
    """Warm-started IK along ``targets`` with bisection of steep intervals.

    When the branch being followed cannot reach a target (a rack limit ends it) the seeded
    restarts are tried, at most once per ``retry_spacing`` of travel; a better configuration
    they find is taken as a branch switch (counted as a jump; the time law then moves the racks
    across at their speed limit while the tip leaves the path, which the errors show).

    Returns the targets actually solved (with inserted midpoints), their rack lengths (k, n, 3)
    and the number of jumps (branch switches and intervals still steep after bisection).
    """
    out_t, out_L = [targets[0]], [first]
    jumps, travel, last_retry = 0, 0.0, -math.inf
    for target in targets[1:]:
        stack = [(target, 0)]
        while stack:
            tgt, depth = stack[-1]
            prev = dk.delta_from_actuators(out_L[-1], robot.phi, robot.L0)
            res = solve_tip_ik(robot, tgt, prev, restarts=False, settings=ik)
            ds = float(np.linalg.norm(tgt - out_t[-1]))
            travel += ds
            if res.error > ik.tolerance and travel - last_retry >= ps.retry_spacing:
                last_retry = travel
                other = solve_tip_ik(robot, tgt, prev, restarts=True, settings=ik)
                if other.error < res.error - ik.tolerance:
                    jumps += 1
                    stack.pop()
                    out_t.append(tgt)
                    out_L.append(other.lengths)
                    continue
            rack = float(np.abs(res.lengths - out_L[-1]).max())
            if rack > ps.jump_ratio * ds + 1e-9 and depth < ps.max_bisections:
                travel -= ds
                stack.append((0.5 * (out_t[-1] + tgt), depth + 1))
                continue
            jumps += rack > ps.jump_ratio * ds + 1e-9
            stack.pop()
            out_t.append(tgt)
            out_L.append(res.lengths)
    return np.array(out_t), np.array(out_L), jumps


def _densify(targets: Array, L: Array, spacing: float) -> tuple[Array, Array]:
    """Split every interval whose racks travel more than ``spacing`` into equal parts of
    linearly interpolated rack lengths (and targets), so the chord bound below stays tight."""
    if len(L) < 2:
        return targets, L
    travel = np.abs(np.diff(L, axis=0)).reshape(len(L) - 1, -1).max(axis=1)
    parts = np.maximum(1, np.ceil(travel / spacing - 1e-9).astype(int))
    if (parts == 1).all():
        return targets, L
    out_t, out_L = [targets[:1]], [L[:1]]
    for i, m in enumerate(parts):
        frac = (np.arange(1, m + 1) / m)[:, None]
        out_t.append(targets[i] + (targets[i + 1] - targets[i]) * frac)
        out_L.append(L[i] + (L[i + 1] - L[i]) * frac[:, :, None])
    return np.vstack(out_t), np.vstack(out_L)


def _tip_chord_bound(robot: "ExtensibleArm", L: Array, substeps: int = 8) -> Array:
    """Per interval, ``substeps`` times the longest tip chord over equal parts of the linear
    interpolation of the rack lengths: a tip travel that, divided by the tip speed, keeps the
    reached tip (not only the target) within the speed limit between any two samples."""
    frac = np.arange(substeps + 1) / substeps
    sub = L[:-1, None] + (L[1:] - L[:-1])[:, None] * frac[None, :, None, None]
    tips = dk.tip_position(robot, dk.delta_from_actuators(sub, robot.phi, robot.L0))
    return substeps * np.linalg.norm(np.diff(tips, axis=1), axis=2).max(axis=1)


def plan_path(robot: "ExtensibleArm", waypoints: npt.ArrayLike, *, speed: float | None = None,
              start_delta: npt.ArrayLike | None = None,
              settings: PathSettings | None = None) -> MotionPath:
    """Time-parametrised joint path within the rack, bending and speed limits that moves the tip
    along ``waypoints``.

    Args:
        robot: The extensible arm.
        waypoints: (k, 3) tip polyline (m), e.g. from :func:`build_path`.
        speed: Tip speed (m/s), at most the robot's ``tip_speed`` (default: that limit).
        start_delta: (n, 3) current posture (moved into the limits). When given, the path
            starts at its tip and first moves to ``waypoints[0]``; otherwise it starts at
            ``waypoints[0]`` (cold IK).
        settings: Overrides the robot file's ``[paths]`` settings.

    Returns:
        The :class:`MotionPath`.

    Raises:
        ValueError: bad waypoints, speed above the limit or not positive, bad start posture.
    """
    if getattr(robot, "kind", None) != "delta":
        raise ValueError(f"robot must be an extensible (delta) arm, got {type(robot).__name__}")
    ps = settings if settings is not None else PathSettings.from_robot(robot)
    ik = IKSettings.from_robot(robot)
    points = polyline(waypoints)
    v = robot.tip_speed if speed is None else speed
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise ValueError(f"speed must be a finite number > 0 (m/s), got {speed!r}")
    if v > robot.tip_speed:
        raise ValueError(f"speed {v:g} m/s exceeds the tip speed limit {robot.tip_speed:g} m/s")
    n = robot.n_segments
    if start_delta is not None:
        sd = np.asarray(start_delta, dtype=float)
        if sd.shape != (n, 3) or not np.all(np.isfinite(sd)):
            raise ValueError(f"start_delta must be a finite ({n}, 3) array, got shape {sd.shape}")
        L_start = dk.limit_rack_lengths(robot, dk.robot_rack_lengths(robot, sd))
        start_tip = dk.tip_position(robot, dk.delta_from_actuators(L_start, robot.phi, robot.L0))
        points = np.vstack([start_tip, points])
    else:
        L_start = solve_tip_ik(robot, points[0], settings=ik).lengths

    spacing = min(ps.spacing, v / ps.rate_hz)
    targets, L, jumps = _track(robot, _sample_polyline(points, spacing), L_start, ik, ps)
    targets, L = _densify(targets, L, spacing)

    return timed_path(robot, targets, L, speed=v, settings=ps, jumps=jumps)


def timed_path(robot: "ExtensibleArm", targets: npt.ArrayLike, lengths: npt.ArrayLike, *,
               speed: float | None = None, settings: PathSettings | None = None,
               jumps: int = 0) -> MotionPath:
    """Time law and sampling (steps 2-4 above) of a keyframed path.

    Args:
        robot: The extensible arm.
        targets: (k, 3) tip targets of the keyframes (m).
        lengths: (k, n, 3) rack lengths of the keyframes, within the rack and bending limits
            (as the IK returns them); the samples interpolate them linearly in time.
        speed: Tip speed (m/s), default the robot's ``tip_speed``.
        settings: Overrides the robot file's ``[paths]`` settings.
        jumps: Passed through to :attr:`MotionPath.jumps`.

    Returns:
        The :class:`MotionPath`: each interval lasts as long as the slowest of its tip, rack and
        motor travel at the (margin-scaled) limits allows.

    Raises:
        ValueError: shapes do not match the robot, or lengths are outside the limits.
    """
    ps = settings if settings is not None else PathSettings.from_robot(robot)
    v = robot.tip_speed if speed is None else float(speed)
    n = robot.n_segments
    targets = np.asarray(targets, dtype=float)
    L = np.asarray(lengths, dtype=float)
    if targets.ndim != 2 or targets.shape[1] != 3 or L.shape != (len(targets), n, 3) \
            or len(targets) < 1:
        raise ValueError(f"targets (k, 3) and lengths (k, {n}, 3) must match, k >= 1; "
                         f"got {targets.shape} and {L.shape}")
    if not np.allclose(dk.limit_rack_lengths(robot, L), L, rtol=0.0, atol=1e-12):
        raise ValueError("lengths must be within the rack limits and theta_max")

    # Time law: every interval at the tip speed unless a rack or motor would exceed its limit.
    flat = L.reshape(len(L), -1)
    motors = dk.motors_from_lengths(L).reshape(len(L), -1)
    v_tip, v_rack = v * ps.limit_margin, robot.rack_speed * ps.limit_margin
    # One count per sample in reserve: rounding to counts adds less than a count per sample.
    v_motor = min(robot.motor_speed * ps.limit_margin,
                  robot.motor_speed - ps.rate_hz / robot.counts_per_metre)
    if v_motor <= 0:
        raise ValueError(f"motor_speed {robot.motor_speed:g} m/s is below one count per sample "
                         f"at {ps.rate_hz:g} Hz")
    dt = np.maximum.reduce([
        np.linalg.norm(np.diff(targets, axis=0), axis=1) / v_tip,
        _tip_chord_bound(robot, L) / v_tip,
        np.abs(np.diff(flat, axis=0)).max(axis=1) / v_rack,
        np.abs(np.diff(motors, axis=0)).max(axis=1) / v_motor,
    ]) if len(targets) > 1 else np.zeros(0)
    t_ik = np.concatenate([[0.0], np.cumsum(dt)])

    count = math.ceil(t_ik[-1] * ps.rate_hz - 1e-9) + 1
    times = np.arange(count) / ps.rate_hz
    samples = np.stack([np.interp(times, t_ik, flat[:, j]) for j in range(flat.shape[1])], axis=1)
    # Interpolations of feasible keyframes are feasible (convex set); this only removes rounding.
    samples = dk.limit_rack_lengths(robot, samples.reshape(count, n, 3))
    tgt = np.stack([np.interp(times, t_ik, targets[:, j]) for j in range(3)], axis=1)
    deltas = dk.delta_from_actuators(samples, robot.phi, robot.L0)
    reached = dk.tip_position(robot, deltas)
    return MotionPath(
        times=times, targets=tgt, tips=reached, deltas=deltas, lengths=samples,
        motor_counts=dk.motor_counts_from_lengths(robot, samples),
        errors=np.linalg.norm(tgt - reached, axis=1), rate_hz=ps.rate_hz, jumps=int(jumps))
