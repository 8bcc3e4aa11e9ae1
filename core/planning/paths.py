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

Box obstacles (``boxes``, ``clearance``; :mod:`core.kinematics.box_clearance`): the clearance is
the arm's body surface's (the backbone's distance minus the robot file's ``body_radius``); every
sampled tip target, with the body around it, must itself be ``clearance`` from every box; each
IK sample is solved with the boxes
(a set-based clearance task, :mod:`core.kinematics.delta_ik_boxes`) and ``PATH_MARGIN`` more
clearance, so the straight rack-space lines between samples keep the rest; and the finished
motion -- every 100 Hz sample and the lines between them, which the runner streams -- is
checked by dense forward kinematics (:func:`box_clearance.motion_clearance`). A path that
cannot keep clear raises :class:`BlockedPath`, naming the box, where and how close.

Settings come from the robot file's optional ``[paths]`` table.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Literal, Sequence

import numpy as np
import numpy.typing as npt

from core.kinematics import box_clearance as bc
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robot_sections import IKSettings, PathSettings
from core.planning.path_shapes import (PATH_KINDS, PathKind, Plane, build_path,  # noqa: F401
                                       diagonal_traverse, four_corners, linear_traverse,
                                       polyline)

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]
PATH_MARGIN = 0.001  # m of clearance the IK samples keep beyond the asked one (for the lines)


class BlockedPath(ValueError):
    """No collision-free path: the message names the box, where and how close."""


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
        clearance: Planned with boxes: the smallest distance from the arm's body surface to a
            box over the whole motion, sampled densely (m); ``inf`` without boxes.
        nearest_box: The box that distance is to ("" without boxes).
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
    clearance: float = math.inf
    nearest_box: str = ""

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
           ps: PathSettings, boxes: tuple[bc.Box, ...] = (),
           clearance: float = 0.0) -> tuple[Array, Array, int]:
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
            res = solve_tip_ik(robot, tgt, prev, restarts=False, settings=ik, boxes=boxes,
                               clearance=clearance)
            ds = float(np.linalg.norm(tgt - out_t[-1]))
            travel += ds
            if res.error > ik.tolerance and travel - last_retry >= ps.retry_spacing:
                last_retry = travel
                other = solve_tip_ik(robot, tgt, prev, restarts=True, settings=ik, boxes=boxes,
                                     clearance=clearance)
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
              settings: PathSettings | None = None, boxes: Sequence[bc.Box] = (),
              clearance: float = 0.0) -> MotionPath:
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
        boxes: Box obstacles the arm's whole body keeps ``clearance`` from, along the whole
            motion (see "Box obstacles" above).
        clearance: That distance (m), from the body's surface.

    Returns:
        The :class:`MotionPath`.

    Raises:
        BlockedPath: the boxes leave no collision-free path (which box, where, how close).
        ValueError: bad waypoints, speed above the limit or not positive, bad start posture,
            bad boxes or clearance.
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
    box_list, need = _check_boxes(boxes, clearance)
    spacing = min(ps.spacing, v / ps.rate_hz)
    samples = _sample_polyline(points, spacing)
    if box_list:
        _check_targets(robot, samples, box_list, need)
    if start_delta is None:
        first = solve_tip_ik(robot, points[0], settings=ik, boxes=box_list,
                             clearance=need + PATH_MARGIN if box_list else 0.0)
        if first.refusal:
            raise BlockedPath(f"the path's first point {_mm_xyz(points[0])} mm: {first.refusal}")
        L_start = first.lengths
    keep = need + PATH_MARGIN if box_list else 0.0
    targets, L, jumps = _track(robot, samples, L_start, ik, ps, box_list, keep)
    targets, L = _densify(targets, L, spacing)

    path = timed_path(robot, targets, L, speed=v, settings=ps, jumps=jumps)
    if not box_list:
        return path
    found = bc.motion_clearance(robot, path.lengths, box_list)
    if not found.clear_of(need):
        k = found.index
        raise BlockedPath(f"no collision-free path: at t = {path.times[k]:.2f} s (tip "
                          f"{_mm_xyz(path.tips[k])} mm, target {_mm_xyz(path.targets[k])} mm) "
                          f"{found.describe()}, closer than the clearance {need * 1e3:.1f} mm")
    return dataclasses.replace(path, clearance=found.distance, nearest_box=found.box)


def _mm_xyz(p: Array) -> str:
    return "(" + ", ".join(f"{v * 1e3:.0f}" for v in np.asarray(p, dtype=float)) + ")"


def _check_boxes(boxes: Sequence[bc.Box], clearance: float) -> tuple[tuple[bc.Box, ...], float]:
    items = tuple(boxes or ())
    if not all(isinstance(b, bc.Box) for b in items):
        raise ValueError("boxes must be core.kinematics.box_clearance.Box objects")
    return items, bc.check_clearance(clearance)


def _check_targets(robot: "ExtensibleArm", samples: Array, boxes: tuple[bc.Box, ...],
                   clearance: float) -> None:
    """The tip is a backbone point: the body around every tip target must be ``clearance``
    from every box."""
    for box in boxes:
        d = bc.signed_distance(samples, box)
        k = int(np.argmin(d))
        if d[k] - robot.body_radius < clearance:
            where = ("inside" if d[k] < 0 else
                     f"{d[k] * 1e3:.1f} mm (the arm's body reaching into it) from"
                     if d[k] < robot.body_radius else
                     f"{d[k] * 1e3:.1f} mm (the arm's surface "
                     f"{(d[k] - robot.body_radius) * 1e3:.1f} mm) from")
            raise BlockedPath(f"the path's tip passes {where} box '{box.name}' at "
                              f"{_mm_xyz(samples[k])} mm, closer than the clearance "
                              f"{clearance * 1e3:.1f} mm")


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
