"""Piecewise-constant-curvature kinematics of the planar soft arm (Katzschmann 2015, Alg. 1).

Poses are ``[x, y, theta]`` with theta the heading of the backbone tangent. A segment of
curvature kappa and length L starting at heading theta0 advances along its chord

    d = L * sinc(kappa L / 2) * [cos(theta0 + kappa L/2), sin(theta0 + kappa L/2)],

which is the paper's ``forwKin`` rewritten so it is exact (no 0/0) at kappa = 0. Every function is
batched over leading axes: ``kappa`` of shape (..., N) gives poses of shape (..., N+1, 3).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
BASE_POSE = (0.0, 0.0, math.pi / 2)


def _sinc(u: Array) -> Array:
    """sin(u)/u, exact at 0 (numpy's sinc is sin(pi x)/(pi x))."""
    return np.sinc(u / np.pi)


def _dsinc(u: Array) -> Array:
    """d/du sin(u)/u, with a series near 0 where the closed form cancels."""
    u = np.asarray(u, dtype=float)
    small = np.abs(u) < 1e-3
    safe = np.where(small, 1.0, u)
    closed = (safe * np.cos(safe) - np.sin(safe)) / safe**2
    series = -u / 3.0 + u**3 / 30.0
    return np.where(small, series, closed)


def _check_kappa_lengths(kappa: npt.ArrayLike, lengths: npt.ArrayLike) -> tuple[Array, Array]:
    kappa = np.asarray(kappa, dtype=float)
    lengths = np.asarray(lengths, dtype=float)
    if kappa.ndim == 0:
        raise ValueError("kappa must have shape (..., N), got a scalar")
    if lengths.ndim and lengths.shape[-1] not in (1, kappa.shape[-1]):
        raise ValueError(
            f"lengths must broadcast to kappa's last axis ({kappa.shape[-1]}), got {lengths.shape}")
    lengths = np.broadcast_to(lengths, np.broadcast_shapes(lengths.shape, kappa.shape[-1:]))
    return kappa, lengths


def forward_kinematics(
    kappa: npt.ArrayLike,
    lengths: npt.ArrayLike,
    base_pose: Sequence[float] | Array = BASE_POSE,
) -> Array:
    """Poses at the base and at every segment end.

    Args:
        kappa: Curvatures, shape (..., N), 1/m.
        lengths: Segment lengths, shape (N,) or broadcastable to kappa, m.
        base_pose: [x, y, theta] of the base; shape (3,) or (..., 3).

    Returns:
        Array of shape (..., N+1, 3): ``[x, y, theta]`` at the base and each segment end.
    """
    kappa, lengths = _check_kappa_lengths(kappa, lengths)
    base = np.asarray(base_pose, dtype=float)
    if base.shape[-1] != 3:
        raise ValueError(f"base_pose must have shape (..., 3), got {base.shape}")
    shape = np.broadcast_shapes(kappa.shape[:-1], base.shape[:-1], lengths.shape[:-1])
    n = kappa.shape[-1]
    out = np.empty(shape + (n + 1, 3))
    turn = kappa * lengths
    half = 0.5 * turn
    theta = out[..., 2]
    theta[..., 0] = base[..., 2]
    np.cumsum(turn, axis=-1, out=theta[..., 1:])
    theta[..., 1:] += base[..., 2:3]
    mid = theta[..., :-1] + half
    chord = np.sin(half)
    nonzero = half != 0
    np.divide(chord, half, out=chord, where=nonzero)
    chord[~nonzero] = 1.0
    chord *= lengths
    out[..., 0, 0] = base[..., 0]
    out[..., 0, 1] = base[..., 1]
    np.cumsum(chord * np.cos(mid), axis=-1, out=out[..., 1:, 0])
    np.cumsum(chord * np.sin(mid), axis=-1, out=out[..., 1:, 1])
    out[..., 1:, 0] += base[..., 0:1]
    out[..., 1:, 1] += base[..., 1:2]
    return out


def point_in_frame(pose: Array, offset: npt.ArrayLike) -> Array:
    """A point rigidly attached to ``pose``: offset (along, left) in its frame; shape (..., 2)."""
    pose = np.asarray(pose, dtype=float)
    a, n = np.asarray(offset, dtype=float)[..., 0], np.asarray(offset, dtype=float)[..., 1]
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    return np.stack([pose[..., 0] + a * c - n * s, pose[..., 1] + a * s + n * c], axis=-1)


def sample_backbone(
    kappa: npt.ArrayLike,
    lengths: npt.ArrayLike,
    samples_per_segment: int = 16,
    base_pose: Sequence[float] | Array = BASE_POSE,
) -> Array:
    """Points along the backbone for rendering and clearance checks.

    Returns:
        Array (..., N * samples_per_segment + 1, 3) of poses, from the base to the tip,
        evenly spaced in arc length within each segment.
    """
    kappa, lengths = _check_kappa_lengths(kappa, lengths)
    if samples_per_segment < 1:
        raise ValueError("samples_per_segment must be >= 1")
    ends = forward_kinematics(kappa, lengths, base_pose)
    s = np.arange(1, samples_per_segment + 1) / samples_per_segment  # (S,)
    k = kappa[..., :, None]
    ls = lengths[..., :, None] * s  # (..., N, S)
    th0 = ends[..., :-1, 2:3]
    turn = k * ls
    chord = ls * _sinc(0.5 * turn)
    mid = th0 + 0.5 * turn
    pts = np.empty(ends.shape[:-2] + (kappa.shape[-1], samples_per_segment, 3))
    pts[..., 0] = ends[..., :-1, 0:1] + chord * np.cos(mid)
    pts[..., 1] = ends[..., :-1, 1:2] + chord * np.sin(mid)
    pts[..., 2] = th0 + turn
    flat = pts.reshape(pts.shape[:-3] + (-1, 3))
    return np.concatenate([ends[..., :1, :], flat], axis=-2)


def point_jacobian(
    kappa: npt.ArrayLike,
    lengths: npt.ArrayLike,
    segment: int | None = None,
    arc: float | None = None,
    offset: npt.ArrayLike = (0.0, 0.0),
    base_pose: Sequence[float] | Array = BASE_POSE,
) -> tuple[Array, Array]:
    """Pose of a point on the arm and its analytic Jacobian with respect to kappa.

    The point lies on segment ``segment`` (0-based; default the last) at arc length ``arc``
    from that segment's start (default its full length), plus a rigid ``offset`` (along, left)
    in the local frame there (e.g. the gripper's palm offset w_off at the tip).

    Returns:
        ``(pose, jac)``: pose (..., 3) as [x, y, theta] (theta of the local frame) and
        jac (..., 3, N) = d pose / d kappa.
    """
    kappa, lengths = _check_kappa_lengths(kappa, lengths)
    n = kappa.shape[-1]
    seg = n - 1 if segment is None else int(segment)
    if not 0 <= seg < n:
        raise ValueError(f"segment must be in [0, {n - 1}], got {segment}")
    ends = forward_kinematics(kappa, lengths, base_pose)
    s = lengths[..., seg] if arc is None else np.broadcast_to(float(arc), lengths[..., seg].shape)
    k = kappa[..., seg]
    th0 = ends[..., seg, 2]
    u = 0.5 * k * s
    mid = th0 + u
    chord = s * _sinc(u)
    start = ends[..., seg, :2]
    local = np.stack([chord * np.cos(mid), chord * np.sin(mid)], axis=-1)
    theta = th0 + k * s
    base_point = start + local
    pose_xy = point_in_frame(np.concatenate([base_point, theta[..., None]], axis=-1), offset)
    pose = np.concatenate([pose_xy, theta[..., None]], axis=-1)

    jac = np.zeros(pose.shape[:-1] + (3, n))
    # Rotation of everything downstream of segment i about the end of segment i.
    for i in range(seg):
        r = pose_xy - ends[..., i + 1, :2]
        li = lengths[..., i]
        # Own chord derivative of segment i.
        ui = 0.5 * kappa[..., i] * li
        midi = ends[..., i, 2] + ui
        dchord = li * _dsinc(ui) * 0.5 * li
        chi = li * _sinc(ui)
        dx = dchord * np.cos(midi) - chi * np.sin(midi) * 0.5 * li
        dy = dchord * np.sin(midi) + chi * np.cos(midi) * 0.5 * li
        jac[..., 0, i] = dx - li * r[..., 1]
        jac[..., 1, i] = dy + li * r[..., 0]
        jac[..., 2, i] = li
    # The segment the point lies on: only the arc up to s counts.
    r = pose_xy - base_point
    dchord = s * _dsinc(u) * 0.5 * s
    jac[..., 0, seg] = dchord * np.cos(mid) - chord * np.sin(mid) * 0.5 * s - s * r[..., 1]
    jac[..., 1, seg] = dchord * np.sin(mid) + chord * np.cos(mid) * 0.5 * s + s * r[..., 0]
    jac[..., 2, seg] = s
    return pose, jac


def tip_jacobian(
    kappa: npt.ArrayLike,
    lengths: npt.ArrayLike,
    offset: npt.ArrayLike = (0.0, 0.0),
    base_pose: Sequence[float] | Array = BASE_POSE,
) -> tuple[Array, Array]:
    """Tip pose (or a point rigidly offset from the tip) and d pose / d kappa, (..., 3, N)."""
    return point_jacobian(kappa, lengths, None, None, offset, base_pose)


def single_segment_ik(
    start_pose: npt.ArrayLike, end_point: npt.ArrayLike
) -> tuple[Array, Array]:
    """The paper's ``singleSegInvKin``: the constant-curvature arc from a pose to a point.

    The arc leaves ``start_pose`` tangent to its heading and ends at ``end_point``. With the
    chord c seen in the start frame (c_along, c_left) and gamma its angle to the heading, the arc
    turns by 2 gamma, so kappa = 2 c_left / |c|^2 and L = 2 gamma / kappa, written to stay finite
    as kappa -> 0 (L -> |c|) and for nearly closed arcs (gamma -> pi).

    Args:
        start_pose: (..., 3) [x, y, theta].
        end_point: (..., 2) [x, y].

    Returns:
        ``(kappa, length)``, each of the broadcast leading shape.
    """
    start = np.asarray(start_pose, dtype=float)
    end = np.asarray(end_point, dtype=float)
    if start.shape[-1] != 3 or end.shape[-1] != 2:
        raise ValueError(f"need start_pose (..., 3) and end_point (..., 2), got {start.shape}, {end.shape}")
    dx = end[..., 0] - start[..., 0]
    dy = end[..., 1] - start[..., 1]
    c, s = np.cos(start[..., 2]), np.sin(start[..., 2])
    along = c * dx + s * dy
    left = -s * dx + c * dy
    chord2 = along**2 + left**2
    chord = np.sqrt(chord2)
    gamma = np.arctan2(left, along)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(chord2 > 0, 2.0 * left / np.where(chord2 > 0, chord2, 1.0), 0.0)
        # |gamma| < pi/2: L = |c| gamma / sin gamma (finite at 0); otherwise L = gamma |c|^2 / left.
        near_straight = np.abs(gamma) < 0.5 * np.pi
        length_a = chord / _sinc(gamma)
        length_b = gamma * chord2 / np.where(left != 0, left, 1.0)
    length = np.where(near_straight, length_a, length_b)
    return kappa, length


def fit_arm(markers: npt.ArrayLike, base_pose: Sequence[float] | Array = BASE_POSE) -> tuple[Array, Array]:
    """Fit curvatures and lengths to measured segment-end points (the 100 Hz feedback path).

    Applies :func:`single_segment_ik` segment by segment from the base, as in the paper: each
    segment starts at the previous end point with the heading the previous arc arrived with.

    Args:
        markers: (..., N, 2) measured segment-end points E_1..E_N.

    Returns:
        ``(kappa, lengths)`` each (..., N).
    """
    pts = np.asarray(markers, dtype=float)
    if pts.ndim < 2 or pts.shape[-1] != 2:
        raise ValueError(f"markers must have shape (..., N, 2), got {pts.shape}")
    base = np.asarray(base_pose, dtype=float)
    pose = np.broadcast_to(base, pts.shape[:-2] + (3,)).copy()
    kappa = np.empty(pts.shape[:-1])
    length = np.empty(pts.shape[:-1])
    for i in range(pts.shape[-2]):
        k, ln = single_segment_ik(pose, pts[..., i, :])
        kappa[..., i], length[..., i] = k, ln
        pose[..., :2] = pts[..., i, :]
        pose[..., 2] = pose[..., 2] + k * ln
    return kappa, length
