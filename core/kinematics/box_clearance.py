"""How far the extensible arm's body is from axis-aligned boxes (shelves, drawer walls).

The operator's obstacles for the extensible arm are axis-aligned boxes in the base frame
(:class:`Box`: centre and full edge lengths, metres). This module is the geometry the tip IK
(:mod:`core.kinematics.delta_ik`), the path planner (:mod:`core.planning.paths`) and the console
share:

* :func:`signed_distance` of points to a box (negative inside: minus the depth to the nearest
  face) and its gradient (the outward normal of the nearest feature, unit length almost
  everywhere);
* :func:`backbone_points`: points along every segment's constant-curvature backbone, sampled
  by arc fraction (the backbone at fraction s of segment i is the tip of segment i with its
  Delta scaled to (s dx, s dy) and its length to s L);
* :func:`clearance_of` / :func:`motion_clearance`: the smallest distance from the arm's body
  surface to any box, for a posture or for the straight rack-space lines between postures
  (what the runner streams: Delta = M L - Delta_0 is affine in the racks, so a straight line in
  L is one in Delta), with the box and the backbone point where it is smallest
  (:class:`Clearance`).

The body. The arm is more than its centre line: the racks run at ``rack_radius`` and the
platforms reach ``half_width`` from it. The robot file's ``[segments] body_radius`` (default
the platform radius) is the arm's body: every point within ``body_radius`` of the backbone.
The distance from that tube to a box is the backbone's distance minus ``body_radius``
(:func:`surface_distance`; negative once the body touches or enters the box), and every
clearance here, in the IK's box task, in paths and in their messages is that surface distance:
"clearance 10 mm" is 10 mm between the arm's surface and the box. The base keep-out
(:func:`check_box_for_base`) counts the body too.

Sampling bound: backbone points ``spacing`` apart along the arc leave every other backbone point
within ``spacing / 2`` of a sample, so the true clearance is at least the sampled one minus
``spacing / 2`` (a distance function is 1-Lipschitz). The body radius is a constant offset of
that distance, so the bound holds for the surface distance unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]
DENSE_SPACING = 0.001  # m between backbone samples of the dense checks
MAX_BOX_SIZE = 5.0     # m, largest edge of a box (a typo in mm would give 1000 m)
MAX_BOX_REACH = 5.0    # m, a box centre this far from the base is a typo


@dataclasses.dataclass(frozen=True)
class Box:
    """An axis-aligned box obstacle in the arm's base frame (m).

    Attributes:
        name: Unique name the operator sees ("Shelf 1").
        centre: (x, y, z) of its centre.
        size: Full edge lengths along x, y, z, each > 0.
    """

    name: str
    centre: tuple[float, float, float]
    size: tuple[float, float, float]

    @property
    def lo(self) -> Array:
        return np.asarray(self.centre) - 0.5 * np.asarray(self.size)

    @property
    def hi(self) -> Array:
        return np.asarray(self.centre) + 0.5 * np.asarray(self.size)


def _triple(value: object, what: str) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be 3 numbers (x, y, z), got {value!r}") from None
    if arr.shape != (3,):
        raise ValueError(f"{what} must be 3 numbers (x, y, z), got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite numbers, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def make_box(name: str, centre: object, size: object) -> Box:
    """A checked :class:`Box`; ValueError with the reason for a bad one.

    Args:
        name: Non-empty name.
        centre: (3,) centre (m), finite, within ``MAX_BOX_REACH`` of the base.
        size: (3,) full edge lengths (m), each finite, > 0 and <= ``MAX_BOX_SIZE``.
    """
    name = str(name).strip()
    if not name:
        raise ValueError("a box needs a name")
    c = _triple(centre, f"box '{name}' centre")
    s = _triple(size, f"box '{name}' size")
    if min(s) <= 0:
        raise ValueError(f"box '{name}' size must be > 0 along x, y and z, got "
                         f"{', '.join(f'{v * 1e3:g}' for v in s)} mm")
    if max(s) > MAX_BOX_SIZE:
        raise ValueError(f"box '{name}' is larger than {MAX_BOX_SIZE:g} m along an axis")
    if max(abs(v) for v in c) > MAX_BOX_REACH:
        raise ValueError(f"box '{name}' centre is more than {MAX_BOX_REACH:g} m from the base")
    return Box(name, c, s)


def check_clearance(clearance: object) -> float:
    """A clearance (m): finite and >= 0, else ValueError."""
    try:
        c = float(clearance)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"clearance must be a number (m), got {clearance!r}") from None
    if not math.isfinite(c) or c < 0 or c > 1.0:
        raise ValueError(f"clearance must be between 0 and 1000 mm, got {clearance!r} m")
    return c


def check_box_for_base(box: Box, clearance: float, body_radius: float = 0.0) -> None:
    """Refuse a box the arm's base (the backbone's first point, the origin, with the body
    ``body_radius`` (m) around it) is inside of or closer to than ``clearance``: no posture
    could then keep the arm clear of it."""
    d = float(signed_distance(np.zeros(3), box))
    if d <= 0:
        raise ValueError(f"box '{box.name}' contains the arm's base (origin)")
    if d - body_radius <= 0:
        raise ValueError(f"box '{box.name}' touches the arm's body at its base ({d * 1e3:.1f} mm "
                         f"from the origin, within the body radius {body_radius * 1e3:.1f} mm)")
    if d - body_radius < clearance:
        raise ValueError(f"box '{box.name}' is {(d - body_radius) * 1e3:.1f} mm from the arm's "
                         f"body at its base, closer than the clearance {clearance * 1e3:.1f} mm: "
                         f"no posture could keep clear")


def signed_distance(points: npt.ArrayLike, box: Box) -> Array:
    """Signed distance (...,) of ``points`` (..., 3) to ``box``: the Euclidean distance outside,
    minus the depth to the nearest face inside."""
    return signed_distance_and_gradient(points, box)[0]


def surface_distance(robot: ExtensibleArm, points: npt.ArrayLike, box: Box) -> Array:
    """Distance (...,) from the arm's body around backbone ``points`` (..., 3) to ``box``: the
    signed distance minus ``robot.body_radius`` (negative once the body reaches the box)."""
    return signed_distance(points, box) - robot.body_radius


def signed_distance_and_gradient(points: npt.ArrayLike, box: Box) -> tuple[Array, Array]:
    """Signed distance (...,) and its gradient (..., 3) with respect to the points.

    Outside, the gradient is the unit vector from the nearest box point; inside, the outward
    normal of the nearest face (ties: the first axis).
    """
    p = np.asarray(points, dtype=float)
    half = 0.5 * np.asarray(box.size)
    rel = p - np.asarray(box.centre)
    q = np.abs(rel) - half                      # per-axis excess over the half size
    sgn = np.where(rel < 0, -1.0, 1.0)
    out = np.maximum(q, 0.0)
    out_norm = np.linalg.norm(out, axis=-1)
    inside = np.max(q, axis=-1)                 # <= 0 inside
    dist = np.where(out_norm > 0, out_norm, np.minimum(inside, 0.0))
    grad_out = sgn * out / np.maximum(out_norm, 1e-300)[..., None]
    axis = np.argmax(q, axis=-1)
    grad_in = np.zeros_like(p)
    np.put_along_axis(grad_in, axis[..., None], np.take_along_axis(sgn, axis[..., None], -1), -1)
    grad = np.where((out_norm > 0)[..., None], grad_out, grad_in)
    return dist, grad


def backbone_points(robot: ExtensibleArm, delta: npt.ArrayLike, per_segment: int) -> Array:
    """Points along the backbone at ``delta`` (..., n, 3): (..., n * per_segment + 1, 3), the
    base first, then ``per_segment`` points per segment at arc fractions 1/m, 2/m, ..., 1."""
    delta = np.asarray(delta, dtype=float)
    n = robot.n_segments
    if delta.shape[-2:] != (n, 3):
        raise ValueError(f"delta must have shape (..., {n}, 3), got {delta.shape}")
    frames = dk.forward_kinematics(delta, robot.L0, robot.d)       # (..., n+1, 4, 4)
    s = np.arange(1, per_segment + 1) / per_segment                 # (m,)
    # Arc point at fraction s (the segment transform's translation with theta -> s theta,
    # L -> s L): s L (B dx / d, B dy / d, A) with A = sin(t) / t, B = (1 - cos t) / t^2.
    dx, dy = delta[..., :, None, 0], delta[..., :, None, 1]       # (..., n, 1)
    length = s * (robot.L0 + delta[..., :, None, 2])               # (..., n, m)
    theta = s * np.hypot(dx, dy) / robot.d
    a = np.sinc(theta / np.pi)
    b = 0.5 * np.sinc(theta / (2 * np.pi)) ** 2
    local = np.stack([length * b * s * dx / robot.d, length * b * s * dy / robot.d, length * a],
                     axis=-1)                                       # (..., n, m, 3)
    R, t = frames[..., :-1, None, :3, :3], frames[..., :-1, None, :3, 3]
    pts = np.einsum("...ij,...j->...i", R, local) + t               # (..., n, m, 3)
    base = np.zeros(delta.shape[:-2] + (1, 3))
    return np.concatenate([base, pts.reshape(delta.shape[:-2] + (n * per_segment, 3))], axis=-2)


def samples_for(robot: ExtensibleArm, spacing: float = DENSE_SPACING) -> int:
    """Backbone samples per segment so that samples are at most ``spacing`` apart along the
    longest segment the racks allow."""
    return max(2, math.ceil(robot.rack_max / spacing))


@dataclasses.dataclass(frozen=True)
class Clearance:
    """The smallest distance found from the arm's body surface to a box.

    Attributes:
        distance: Surface distance (m): the backbone's signed distance minus the body radius;
            ``inf`` without boxes, negative when the body reaches into a box.
        box: Name of the nearest box ("" without boxes).
        point: (3,) backbone point where it is smallest (None without boxes); the body's
            surface there is the body radius nearer the box.
        index: Which posture (of a sequence) it belongs to (0 for a single posture).
    """

    distance: float
    box: str = ""
    point: Array | None = None
    index: int = 0

    def clear_of(self, clearance: float) -> bool:
        return self.distance >= clearance

    def describe(self) -> str:
        """'the arm passes 12.3 mm from box "Shelf"' (its surface; or into it)."""
        if not self.box:
            return "no boxes"
        if self.distance < 0:
            return f"the arm enters box '{self.box}' ({-self.distance * 1e3:.1f} mm deep)"
        return f"the arm passes {self.distance * 1e3:.1f} mm from box '{self.box}'"


NO_BOXES = Clearance(math.inf)


def _nearest(robot: ExtensibleArm, points: Array, boxes: Sequence[Box]) -> Clearance:
    """Nearest (box, point) over points (K, P, 3): K postures of P backbone points."""
    best = NO_BOXES
    for box in boxes:
        d = surface_distance(robot, points, box)
        k, j = np.unravel_index(int(np.argmin(d)), d.shape)
        if d[k, j] < best.distance:
            best = Clearance(float(d[k, j]), box.name, points[k, j].copy(), int(k))
    return best


def clearance_of(robot: ExtensibleArm, delta: npt.ArrayLike, boxes: Sequence[Box],
                 spacing: float = DENSE_SPACING) -> Clearance:
    """Smallest distance of the arm's body surface at ``delta`` (n, 3) to ``boxes``, the
    backbone sampled every ``spacing`` (or closer) along each segment."""
    if not boxes:
        return NO_BOXES
    pts = backbone_points(robot, np.asarray(delta, dtype=float)[None], samples_for(robot, spacing))
    return _nearest(robot, pts, boxes)



def _refined(robot: ExtensibleArm, L: Array, boxes: Sequence[Box], spacing: float,
             below: float | None = None, chunk: int = 256) -> Clearance:
    """Dense minimum over the postures ``L`` (R, n, 3): a coarse pass (10 mm along the arc)
    bounds every posture from below (sampled minus half the coarse gap); only postures whose
    bound is below the best coarse value are sampled every ``spacing``. ``index`` is the row.
    With ``below``, a coarse sample already closer than that is returned at once (the answer
    "not clear" needs no refinement)."""
    coarse_gap = max(spacing, 0.01)
    mc = samples_for(robot, coarse_gap)
    gap = robot.rack_max / mc
    d_c = np.empty(len(L))
    for a in range(0, len(L), chunk):
        pts = backbone_points(robot, dk.delta_from_actuators(L[a:a + chunk], robot.phi,
                                                             robot.L0), mc)
        d_c[a:a + chunk] = np.min([surface_distance(robot, pts, b).min(axis=-1)
                                   for b in boxes], axis=0)
        if below is not None and d_c[a:a + chunk].min() < below:
            k = a + int(np.argmin(d_c[a:a + chunk]))
            return dataclasses.replace(_nearest(robot, pts[k - a][None], boxes), index=k)
    rows = np.flatnonzero(d_c - 0.5 * gap <= d_c.min())
    best = NO_BOXES
    m = samples_for(robot, spacing)
    for a in range(0, len(rows), chunk):
        idx = rows[a:a + chunk]
        pts = backbone_points(robot, dk.delta_from_actuators(L[idx], robot.phi, robot.L0), m)
        found = _nearest(robot, pts, boxes)
        if found.distance < best.distance:
            best = dataclasses.replace(found, index=int(idx[found.index]))
    return best


def motion_clearance(robot: ExtensibleArm, lengths: npt.ArrayLike, boxes: Sequence[Box],
                     spacing: float = DENSE_SPACING, below: float | None = None) -> Clearance:
    """Smallest body-surface-to-box distance along straight rack-space lines through the rack
    lengths ``lengths`` (K, n, 3) (the runner streams straight lines in rack space), with the
    backbone sampled every ``spacing`` along the arc and each line subdivided so no backbone
    sample moves more than about ``spacing / 2`` between checked postures.

    ``Clearance.index`` is the interval (0 .. K-2; 0 for K = 1) where it is smallest. With
    ``below``, the first found closer than that may be returned instead (a quick "not clear").
    """
    if not boxes:
        return NO_BOXES
    L = np.asarray(lengths, dtype=float)
    if L.ndim != 3 or L.shape[1:] != (robot.n_segments, 3):
        raise ValueError(f"lengths must have shape (K, {robot.n_segments}, 3), got {L.shape}")
    if len(L) == 1:
        return _refined(robot, L, boxes, spacing, below)
    coarse = backbone_points(robot, dk.delta_from_actuators(L, robot.phi, robot.L0), 8)
    moved = np.linalg.norm(np.diff(coarse, axis=0), axis=-1).max(axis=-1)   # (K-1,)
    parts = np.maximum(1, np.ceil(2.0 * moved / spacing).astype(int))
    rows, owner = [L[:1]], [np.zeros(1, dtype=int)]
    for i, k in enumerate(parts):
        frac = (np.arange(1, k + 1) / k)[:, None, None]
        rows.append(L[i] + (L[i + 1] - L[i]) * frac)
        owner.append(np.full(k, i))
    found = _refined(robot, np.concatenate(rows), boxes, spacing, below)
    return dataclasses.replace(found, index=int(np.concatenate(owner)[found.index]))
