"""Gripper geometry and its closing sweep: which objects the soft gripper captures (Fig. 6).

Frame: the gripper root (arm tip), x along the heading, y to the left, where the gripper closes.
The gripper centreline is a straight palm ``[0, palm_length]`` followed by a finger of length
``length - palm_length`` that curls to the left with constant curvature ``turn / finger_length``
(``turn`` from 0, open, to ``closed_turn``). Bodies are capsules around that polyline
(``finger_half_width``) plus a short capsule behind the root standing for the arm's last
segment (``arm_half_width``). Objects are discs on the table.

The **closing sweep** raises ``turn`` in ``sweep_steps`` increments; at each increment the
object is pushed out of every capsule it overlaps (quasi-static, frictionless, deepest contact
first). When it cannot be pushed free (squeezed between finger and palm) the finger is blocked
and stops there. The object is **captured** when its centre ends inside the pocket: the polygon
root -> palm -> finger -> finger tip -> root. Everything is batched over K objects.

**Two fingers** (robot file ``[gripper] fingers = "both"``, the stacked pair chosen in
:mod:`core.planning.sides`): a second finger, the mirror image (y -> -y) of the first, grows
from the same palm end and curls to the right on the same channel (one ``turn`` for both; when
one finger is blocked by the object both stop, which changes nothing for the finger holding it).
Its capsules take part in every push, and an object is captured in either pocket.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from core.control.params import GripperSimParams

Array = npt.NDArray[np.float64]


def _clip(a, lo, hi):
    """np.clip via the min/max ufuncs (several times faster on small arrays)."""
    return np.minimum(np.maximum(a, lo), hi)
_FINGER_POINTS = 10
_PUSH_ITERS = 8
_BLOCK_TOL = 2e-4  # m of penetration left after pushing = blocked


@dataclasses.dataclass(frozen=True)
class GripperGeometry:
    """Dimensions of the simulated gripper (m, rad)."""

    length: float
    palm_length: float
    finger_half_width: float
    arm_half_width: float
    closed_turn: float
    capture_turn: float
    sweep_steps: int
    both: bool = False        # a mirrored second finger closing to the right

    @classmethod
    def from_params(cls, length: float, g: GripperSimParams, arm_half_width: float,
                    fingers: str = "left") -> "GripperGeometry":
        """From ``[sim.gripper]``; ``fingers`` is the robot file's ``[gripper] fingers``."""
        return cls(length, g.palm_length, g.finger_half_width, arm_half_width, g.closed_turn,
                   g.capture_turn, g.sweep_steps, fingers == "both")

    @classmethod
    def of(cls, robot, params: GripperSimParams | None = None,
           arm_half_width: float | None = None) -> "GripperGeometry":
        """The soft-arm robot's simulated gripper (``[gripper]`` and ``[sim]``)."""
        g = robot.sim.gripper if params is None else params
        hw = robot.sim.arm_half_width if arm_half_width is None else arm_half_width
        return cls.from_params(robot.gripper.length, g, hw, robot.gripper.fingers)

    @property
    def finger_length(self) -> float:
        return self.length - self.palm_length

    def centreline(self, turn: npt.ArrayLike) -> Array:
        """Polyline (K, M, 2) for turns (K,): arm stub, root, palm end, finger points."""
        turn = np.atleast_1d(np.asarray(turn, dtype=float))
        s = self.finger_length * np.arange(1, _FINGER_POINTS + 1) / _FINGER_POINTS
        k = turn[:, None] / self.finger_length
        u = 0.5 * k * s
        chord = s * np.sinc(u / np.pi)
        pts = np.empty((turn.shape[0], _FINGER_POINTS + 3, 2))
        pts[:, 0] = (-self.length / 4, 0.0)
        pts[:, 1] = (0.0, 0.0)
        pts[:, 2] = (self.palm_length, 0.0)
        pts[:, 3:, 0] = self.palm_length + chord * np.cos(u)
        pts[:, 3:, 1] = chord * np.sin(u)
        return pts

    def half_widths(self) -> Array:
        """Capsule half-widths, (S,), matching :meth:`capsules`."""
        hw = np.full(_FINGER_POINTS + 2 + (_FINGER_POINTS if self.both else 0),
                     self.finger_half_width)
        hw[0] = self.arm_half_width
        return hw

    def capsules(self, turn: npt.ArrayLike) -> tuple[Array, Array]:
        """Segment ends ``(a, b)``, each (K, S, 2): arm stub, palm, finger (and mirrored finger)."""
        line = self.centreline(turn)
        a, b = line[:, :-1], line[:, 1:]
        if not self.both:
            return a, b
        mirror = line[:, 2:] * np.array([1.0, -1.0])  # palm end and the right finger
        return (np.concatenate([a, mirror[:, :-1]], axis=1),
                np.concatenate([b, mirror[:, 1:]], axis=1))

    def outline(self, turn: float) -> Array:
        """One polyline (M, 2) to draw the gripper closed to ``turn``: stub, root, palm, finger;
        with two fingers the right finger tip, back to the palm end, then the left finger."""
        line = self.centreline(turn)[0]
        if not self.both:
            return line
        return np.concatenate([line[:2:-1] * np.array([1.0, -1.0]), line[2:]])


def capsule_contacts(p: Array, a: Array, b: Array) -> tuple[Array, Array]:
    """Distance and unit normal from segments a->b to points p.

    Args:
        p: (K, 2) points.
        a, b: (K, S, 2) or (S, 2) segment ends.

    Returns:
        ``(dist, normal)``: (K, S) and (K, S, 2), normal pointing from the segment to p
        (the segment's left normal where p lies on it).
    """
    ab = b - a
    ap = p[:, None, :] - a
    den = np.maximum((ab * ab).sum(-1), 1e-18)
    t = _clip((ap * ab).sum(-1) / den, 0.0, 1.0)
    d = ap - t[..., None] * ab
    dist = np.sqrt((d * d).sum(-1))
    left = np.stack([-ab[..., 1], ab[..., 0]], -1) / np.sqrt(den)[..., None]
    left = np.broadcast_to(left, d.shape)
    safe = dist > 1e-12
    normal = np.where(safe[..., None], d / np.where(safe, dist, 1.0)[..., None], left)
    return dist, normal


def push_out(p: Array, r: Array, a: Array, b: Array, hw: Array,
             iters: int = _PUSH_ITERS) -> tuple[Array, Array]:
    """Push discs (centres p (K,2), radii r (K,)) out of capsules; returns (p, residual overlap)."""
    p = p.copy()
    resid = np.zeros(p.shape[0])
    for _ in range(iters):
        dist, normal = capsule_contacts(p, a, b)
        pen = (r[:, None] + hw) - dist
        j = np.argmax(pen, axis=1)
        rows = np.arange(p.shape[0])
        resid = pen[rows, j]
        hit = resid > 0
        if not hit.any():
            return p, np.maximum(resid, 0.0)
        p[hit] += normal[rows, j][hit] * (resid[hit] + 1e-7)[:, None]
    dist, _ = capsule_contacts(p, a, b)
    return p, np.maximum(((r[:, None] + hw) - dist).max(axis=1), 0.0)


def in_pocket(geom: GripperGeometry, turn: npt.ArrayLike, p: Array) -> npt.NDArray[np.bool_]:
    """Whether centres p (K, 2) lie inside a pocket polygon of a gripper closed to ``turn``
    (the left finger's, or with two fingers also the right one's: the mirror image)."""
    inside = _in_left_pocket(geom, turn, p)
    if geom.both:
        inside |= _in_left_pocket(geom, turn, p * np.array([1.0, -1.0]))
    return inside


def _in_left_pocket(geom: GripperGeometry, turn: npt.ArrayLike, p: Array) -> npt.NDArray[np.bool_]:
    poly = geom.centreline(turn)[:, 1:]  # root, palm end, finger...; closed back to the root
    x, y = p[:, 0:1], p[:, 1:2]
    x0, y0 = poly[..., 0], poly[..., 1]
    x1, y1 = np.roll(x0, -1, axis=1), np.roll(y0, -1, axis=1)
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x0 + (y - y0) * (x1 - x0) / np.where(y1 != y0, y1 - y0, 1.0)
    return (np.count_nonzero(crosses & (x < xi), axis=1) % 2) == 1


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """Per-object outcome of a closing sweep, each (K,) or (K, 2)."""

    position: Array
    turn: Array
    blocked: npt.NDArray[np.bool_]
    captured: npt.NDArray[np.bool_]


def close_sweep(geom: GripperGeometry, p: npt.ArrayLike, r: npt.ArrayLike,
                turn_from: npt.ArrayLike = 0.0, turn_to: float | None = None) -> SweepResult:
    """Close the gripper from ``turn_from`` to ``turn_to`` (default fully) against discs.

    Args:
        geom: Gripper geometry.
        p: (K, 2) object centres in the gripper-root frame.
        r: Radii, scalar or (K,).
        turn_from: Start turn(s), scalar or (K,).
        turn_to: End turn (default ``geom.closed_turn``).

    Returns:
        :class:`SweepResult` with the pushed centres, reached turns, blocked and captured flags.
    """
    p = np.array(p, dtype=float, ndmin=2)
    if p.shape[-1] != 2:
        raise ValueError(f"object centres must have shape (K, 2), got {p.shape}")
    k = p.shape[0]
    r = np.broadcast_to(np.asarray(r, dtype=float), (k,))
    end = geom.closed_turn if turn_to is None else float(turn_to)
    turn = np.broadcast_to(np.asarray(turn_from, dtype=float), (k,)).copy()
    blocked = np.zeros(k, bool)
    hw = geom.half_widths()
    step = geom.closed_turn / geom.sweep_steps
    n_steps = max(0, math.ceil((end - float(turn.min(initial=end))) / step - 1e-9))
    for _ in range(n_steps):
        active = ~blocked & (turn < end)
        if not active.any():
            break
        idx = np.flatnonzero(active)
        proposed = np.minimum(turn[idx] + step, end)
        a, b = geom.capsules(proposed)
        q, resid = push_out(p[idx], r[idx], a, b, hw)
        ok = resid <= _BLOCK_TOL
        p[idx[ok]] = q[ok]
        turn[idx[ok]] = proposed[ok]
        blocked[idx[~ok]] = True
    captured = in_pocket(geom, turn, p) & ((turn >= geom.capture_turn) | blocked)
    return SweepResult(p, turn, blocked, captured)


def to_frame(pose: npt.ArrayLike, xy: npt.ArrayLike) -> Array:
    """World points (..., 2) into the frame of ``pose`` [x, y, theta]."""
    pose = np.asarray(pose, dtype=float)
    d = np.asarray(xy, dtype=float) - pose[:2]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)


def from_frame(pose: npt.ArrayLike, xy: npt.ArrayLike) -> Array:
    """Points (..., 2) in the frame of ``pose`` into the world."""
    pose = np.asarray(pose, dtype=float)
    q = np.asarray(xy, dtype=float)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.stack([pose[0] + c * q[..., 0] - s * q[..., 1],
                     pose[1] + s * q[..., 0] + c * q[..., 1]], -1)
