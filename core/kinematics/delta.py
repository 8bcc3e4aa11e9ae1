"""Delta-parametrised kinematics of the extensible tri-rack arm (Hughes 2020, eq. 2-3).

A segment's posture is ``delta = (dx, dy, dL)``: the tip bends by theta = |(dx, dy)| / d toward
the direction of (dx, dy) and the backbone has length L = L0 + dL. With omega = (-dy, dx, 0) / d
the segment's transform is

    R = I + A [omega]x + B [omega]x^2,   p = L * (B dx / d, B dy / d, A),
    A = sin(theta) / theta,  B = (1 - cos(theta)) / theta^2,

and A, B are evaluated by series near theta = 0, so nothing divides 0 by 0 at delta = 0.

Rack map. A rack at angle beta around the backbone (radius d) of a constant-curvature segment
has length L - dx cos(beta) - dy sin(beta). The paper's racks sit at beta_j = -phi + 2 pi (j-1)/3,
which reproduces rows 1 and 3 of its printed eq. (3); the printed row 2 has the wrong sign on its
third entry (which makes M singular at phi = 0, 2 pi/3, pi). :func:`rack_matrix` is the map
derived from the geometry.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]
_SERIES_THETA = 0.05


def _ab(s: Array) -> tuple[Array, Array, Array, Array]:
    """A(s), B(s) and their derivatives with respect to s = theta^2."""
    s = np.asarray(s, dtype=float)
    theta = np.sqrt(s)
    small = theta < _SERIES_THETA
    t = np.where(small, 1.0, theta)
    sin, cos = np.sin(t), np.cos(t)
    a = np.where(small, 1 - s / 6 + s**2 / 120 - s**3 / 5040, sin / t)
    b = np.where(small, 0.5 - s / 24 + s**2 / 720 - s**3 / 40320, (1 - cos) / t**2)
    da = np.where(small, -1 / 6 + s / 60 - s**2 / 1680 + s**3 / 90720,
                  (t * cos - sin) / (2 * t**3))
    db = np.where(small, -1 / 24 + s / 360 - s**2 / 13440 + s**3 / 907200,
                  (0.5 * t * sin - (1 - cos)) / t**4)
    return a, b, da, db


def _skew(w: Array) -> Array:
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def _check_delta(delta: npt.ArrayLike) -> Array:
    delta = np.asarray(delta, dtype=float)
    if delta.shape[-1:] != (3,):
        raise ValueError(f"delta must have shape (..., 3) = (dx, dy, dL), got {delta.shape}")
    return delta


def segment_transform(delta: npt.ArrayLike, L0: float, d: float) -> Array:
    """Homogeneous transform from a segment's base frame to its tip frame.

    Args:
        delta: (..., 3) = (dx, dy, dL) in metres.
        L0: Reference backbone length; L = L0 + dL.
        d: Racks' radial distance from the backbone.

    Returns:
        (..., 4, 4) transforms.
    """
    return _transform(_checked(delta, d), L0, d)[0]  # (without the unused derivative)


def _checked(delta: npt.ArrayLike, d: float) -> Array:
    delta = _check_delta(delta)
    if d <= 0:
        raise ValueError(f"d must be > 0, got {d}")
    return delta


def _transform(delta: Array, L0: float, d: float) -> tuple[Array, tuple[Array, ...]]:
    """T (..., 4, 4) and the terms its derivative reuses (length, a, b, da, db, omega, k, k2)."""
    dx, dy, dl = delta[..., 0], delta[..., 1], delta[..., 2]
    length = L0 + dl
    s = (dx**2 + dy**2) / d**2
    a, b, da, db = _ab(s)
    omega = np.stack([-dy, dx, np.zeros_like(dx)], axis=-1) / d
    k = _skew(omega)
    k2 = k @ k
    eye = np.broadcast_to(np.eye(3), k.shape)
    T = np.zeros(delta.shape[:-1] + (4, 4))
    T[..., :3, :3] = eye + a[..., None, None] * k + b[..., None, None] * k2
    T[..., 0, 3] = length * b * dx / d
    T[..., 1, 3] = length * b * dy / d
    T[..., 2, 3] = length * a
    T[..., 3, 3] = 1.0
    return T, (length, a, b, da, db, omega, k, k2)


def segment_transform_and_jacobian(delta: npt.ArrayLike, L0: float, d: float) -> tuple[Array, Array]:
    """Segment transform and its analytic derivative.

    Returns:
        ``(T, dT)`` with T (..., 4, 4) and dT (..., 3, 4, 4) = dT / d(dx, dy, dL).
    """
    delta = _checked(delta, d)
    dx, dy = delta[..., 0], delta[..., 1]
    T, (length, a, b, da, db, omega, k, k2) = _transform(delta, L0, d)

    dT = np.zeros(delta.shape[:-1] + (3, 4, 4))
    ds = np.stack([2 * dx / d**2, 2 * dy / d**2], axis=-1)
    domega = np.array([[0.0, 1.0 / d, 0.0], [-1.0 / d, 0.0, 0.0]])  # d omega / d(dx), d(dy)
    for j in range(2):
        dk = _skew(np.broadcast_to(domega[j], omega.shape))
        dR = ((da * ds[..., j])[..., None, None] * k + a[..., None, None] * dk
              + (db * ds[..., j])[..., None, None] * k2 + b[..., None, None] * (dk @ k + k @ dk))
        dT[..., j, :3, :3] = dR
    dT[..., 0, 0, 3] = length * (db * ds[..., 0] * dx + b) / d
    dT[..., 0, 1, 3] = length * db * ds[..., 0] * dy / d
    dT[..., 0, 2, 3] = length * da * ds[..., 0]
    dT[..., 1, 0, 3] = length * db * ds[..., 1] * dx / d
    dT[..., 1, 1, 3] = length * (db * ds[..., 1] * dy + b) / d
    dT[..., 1, 2, 3] = length * da * ds[..., 1]
    dT[..., 2, 0, 3] = b * dx / d
    dT[..., 2, 1, 3] = b * dy / d
    dT[..., 2, 2, 3] = a
    return T, dT


def forward_kinematics(deltas: npt.ArrayLike, L0: float | npt.ArrayLike, d: float) -> Array:
    """Frames of a chain of segments, chained without twist.

    Args:
        deltas: (..., n, 3).
        L0: Reference length, scalar or (n,).

    Returns:
        (..., n+1, 4, 4): the base frame (identity) and each segment's tip frame.
    """
    deltas = _check_delta(deltas)
    n = deltas.shape[-2]
    L0s = np.broadcast_to(np.asarray(L0, dtype=float), (n,))
    frames = np.empty(deltas.shape[:-2] + (n + 1, 4, 4))
    frames[..., 0, :, :] = np.eye(4)
    for i in range(n):
        frames[..., i + 1, :, :] = frames[..., i, :, :] @ segment_transform(deltas[..., i, :], L0s[i], d)
    return frames


def chain_tip_and_jacobian(deltas: npt.ArrayLike, L0: float | npt.ArrayLike, d: float) -> tuple[Array, Array]:
    """Tip position and its analytic Jacobian with respect to all deltas.

    Returns:
        ``(p, J)``: p (..., 3) and J (..., 3, 3n), columns ordered (dx1, dy1, dL1, dx2, ...).
    """
    deltas = _check_delta(deltas)
    n = deltas.shape[-2]
    L0s = np.broadcast_to(np.asarray(L0, dtype=float), (n,))
    Ts, dTs = [], []
    for i in range(n):
        T, dT = segment_transform_and_jacobian(deltas[..., i, :], L0s[i], d)
        Ts.append(T)
        dTs.append(dT)
    # suffix[i] = tip position expressed in frame i (homogeneous).
    suffix = [None] * (n + 1)
    tip_h = np.zeros(deltas.shape[:-2] + (4,))
    tip_h[..., 3] = 1.0
    suffix[n] = tip_h
    for i in range(n - 1, -1, -1):
        suffix[i] = np.einsum("...ij,...j->...i", Ts[i], suffix[i + 1])
    J = np.empty(deltas.shape[:-2] + (3, 3 * n))
    prefix = np.broadcast_to(np.eye(4), deltas.shape[:-2] + (4, 4))
    for i in range(n):
        local = np.einsum("...kij,...j->...ik", dTs[i], suffix[i + 1])  # (..., 4, 3)
        J[..., :, 3 * i:3 * i + 3] = (prefix @ local)[..., :3, :]
        prefix = prefix @ Ts[i]
    return suffix[0][..., :3], J


def rack_angles(phi: float) -> Array:
    """Angular positions beta_j of the three racks around the backbone (radians)."""
    return -phi + 2 * np.pi * np.arange(3) / 3


def rack_matrix(phi: float) -> Array:
    """M(phi) of eq. (3), derived from the rack geometry (rows 1 and 3 as printed).

    ``delta = M @ lengths - (0, 0, L0)``. Its determinant is 2 sqrt(3) / 9 for every phi, so it is
    invertible everywhere, unlike the printed matrix.
    """
    c = 2.0 / 3.0
    return np.array([
        [-c * math.cos(phi), c * math.cos(phi + math.pi / 3), c * math.cos(phi - math.pi / 3)],
        [c * math.sin(phi), -c * math.sin(phi + math.pi / 3), -c * math.sin(phi - math.pi / 3)],
        [1 / 3, 1 / 3, 1 / 3],
    ])


def rack_matrix_inverse(phi: float) -> Array:
    """M(phi)^-1 in closed form: rack j has length L0 + dL - dx cos(beta_j) - dy sin(beta_j)."""
    beta = rack_angles(phi)
    return np.stack([-np.cos(beta), -np.sin(beta), np.ones(3)], axis=-1)


def delta_from_actuators(lengths: npt.ArrayLike, phi: float, L0: float) -> Array:
    """Eq. (2): rack lengths (..., 3) -> delta (..., 3)."""
    lengths = np.asarray(lengths, dtype=float)
    if lengths.shape[-1:] != (3,):
        raise ValueError(f"lengths must have shape (..., 3), got {lengths.shape}")
    out = lengths @ rack_matrix(phi).T
    out[..., 2] -= L0
    return out


def actuators_from_delta(delta: npt.ArrayLike, phi: float, L0: float) -> Array:
    """Inverse of eq. (2): delta (..., 3) -> rack lengths (..., 3)."""
    delta = _check_delta(delta).copy()
    delta[..., 2] += L0
    return delta @ rack_matrix_inverse(phi).T


def motor_matrix(n_segments: int) -> Array:
    """U: block upper-triangular matrix of 3x3 identities (paper, end of section II-C).

    Rack lengths L = U @ m, so motor travels are m = U^-1 L: a motor on platform i moves its rack
    relative to that platform, lengthening segment i and every segment before it.
    """
    return np.kron(np.triu(np.ones((n_segments, n_segments))), np.eye(3))


def motors_from_lengths(lengths: npt.ArrayLike) -> Array:
    """m = U^-1 L for rack lengths (..., n, 3) -> motor travels (..., n, 3) in metres."""
    L = np.asarray(lengths, dtype=float)
    m = L.copy()
    m[..., :-1, :] -= L[..., 1:, :]  # U^-1 is I on the diagonal and -I just above it.
    return m


def lengths_from_motors(motors: npt.ArrayLike) -> Array:
    """L = U m: motor travels (..., n, 3) -> rack lengths (..., n, 3)."""
    m = np.asarray(motors, dtype=float)
    return np.flip(np.cumsum(np.flip(m, axis=-2), axis=-2), axis=-2)


def motor_counts_from_lengths(robot: "ExtensibleArm", lengths: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Integer encoder demand counts for rack lengths (n, 3), flattened to (3n,)."""
    m = motors_from_lengths(lengths) * robot.counts_per_metre
    return np.rint(m).astype(np.int64).reshape(m.shape[:-2] + (-1,))


def lengths_from_motor_counts(robot: "ExtensibleArm", counts: npt.ArrayLike) -> Array:
    """Rack lengths (..., n, 3) from encoder counts (..., 3n)."""
    c = np.asarray(counts, dtype=float)
    m = c.reshape(c.shape[:-1] + (robot.n_segments, 3)) / robot.counts_per_metre
    return lengths_from_motors(m)


def robot_rack_lengths(robot: "ExtensibleArm", delta: npt.ArrayLike) -> Array:
    """Rack lengths (..., n, 3) of every segment of ``robot`` at ``delta`` (..., n, 3)."""
    return actuators_from_delta(delta, robot.phi, robot.L0)


def bend_angles(delta: npt.ArrayLike, d: float) -> Array:
    """Bend theta = |(dx, dy)| / d of every segment: delta (..., 3) -> (...,)."""
    delta = _check_delta(delta)
    return np.hypot(delta[..., 0], delta[..., 1]) / d


def mid_range_delta(robot: "ExtensibleArm") -> Array:
    """Straight, every rack at the middle of [rack_min, rack_max] (whole millimetres), (n, 3).

    Retracted (zero) every rack sits at rack_min, so no segment can bend: bending one way
    shortens a rack. At mid-range each rack has (rack_max - rack_min) / 2 of travel both ways.
    The console starts here, and so does the device emulator (nothing moves to get there).
    """
    mid = math.floor((0.5 * (robot.rack_min + robot.rack_max) - robot.L0) * 1e3 + 1e-9) / 1e3
    q = np.zeros((robot.n_segments, 3))
    q[:, 2] = mid
    return q


def limit_rack_lengths(robot: "ExtensibleArm", lengths: npt.ArrayLike) -> Array:
    """Rack lengths (..., n, 3) moved into the feasible set: racks in [rack_min, rack_max] and
    every segment's bend theta <= theta_max.

    The racks are clipped onto their box, then each segment whose bend is too large has its
    racks' deviations from their mean scaled down. Rack j deviates from the mean L0 + dL by
    -dx cos(beta_j) - dy sin(beta_j) (the cosines and sines of the three rack angles sum to 0), so
    the scaling scales (dx, dy) by the same factor and keeps dL; the result is a convex
    combination of in-box racks and their in-box mean, hence still in the box. Feasible
    lengths are returned unchanged. The feasible set is convex (a box intersected with one
    elliptic cylinder per segment), so straight lines between feasible lengths stay feasible.
    """
    L = np.clip(np.asarray(lengths, dtype=float), robot.rack_min, robot.rack_max)
    if L.shape[-1:] != (3,):
        raise ValueError(f"lengths must have shape (..., 3), got {L.shape}")
    bend = np.linalg.norm(L @ rack_matrix(robot.phi)[:2].T, axis=-1)  # |(dx, dy)|
    limit = robot.rack_radius * robot.theta_max
    over = bend > limit
    if not over.any():
        return L
    # A hair inside the limit, so theta <= theta_max holds after rounding too.
    scale = np.where(over, limit * (1 - 1e-12) / np.where(over, bend, 1.0), 1.0)[..., None]
    mean = L.mean(axis=-1, keepdims=True)
    return mean + scale * (L - mean)


def tip_position(robot: "ExtensibleArm", delta: npt.ArrayLike) -> Array:
    """Tip position (..., 3) of ``robot`` at ``delta`` (..., n, 3) (or flat (3n,))."""
    delta = np.asarray(delta, dtype=float)
    if delta.shape[-1] == 3 * robot.n_segments and delta.ndim == 1:
        delta = delta.reshape(robot.n_segments, 3)
    if delta.shape[-2:] != (robot.n_segments, 3):
        raise ValueError(f"delta must have shape (..., {robot.n_segments}, 3), got {delta.shape}")
    return forward_kinematics(delta, robot.L0, robot.d)[..., -1, :3, 3]
