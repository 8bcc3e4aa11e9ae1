"""Skinned tubes: a tube mesh sent once, then bent by a few bone poses per frame (pure numpy).

Streaming a tube's vertices costs every viewer ~24 KB per redraw; a skinned tube costs one pose
per bone. The tube is bound straight (the bind pose: along +z, bone ``b`` at ``z = (b - 1) h``
with identity rotation) and every vertex follows up to four bones with uniform cubic B-spline
weights of its arc position ``u`` (in knot units), so the drawn centre line is C2: no kinks at
the bones, however few there are. Bones sit on every ``stride``-th backbone sample (the knots),
plus one phantom bone before the first and after the last knot so the ends are covered (each
continues the end's bend, so the end rings are not tilted).

The client (three.js ``SkinnedMesh``) draws ``v' = sum_i w_i B_i B_i,bind^-1 v``;
:meth:`TubeSkin.deform` computes the same in numpy, which the tests compare with the vertex
path's ``geometry(q)``. A B-spline does not interpolate its control points, so on a bent tube the
blended centre line sits off the backbone by about ``kappa h^2 / 6``; :meth:`TubeSkin.bone_poses`
moves each bone by the residual at its knot (a few fixed-point steps), which cancels it to
well under a millimetre at the arms' largest curvatures.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from console.scene.tube import TubeTopology

Array = npt.NDArray[np.float64]

# Uniform cubic B-spline weights at knot offsets -1, 0, +1 (a vertex exactly on a knot).
_ON_KNOT = np.array([1.0, 4.0, 1.0]) / 6.0


def bspline_weights(u: npt.ArrayLike, n_knots: int) -> tuple[npt.NDArray[np.int64], Array]:
    """Bone indices and weights (each (V, 4)) of points at knot coordinates ``u``.

    Args:
        u: (V,) arc positions in knot units, within [0, n_knots - 1].
        n_knots: Number of knots; bones are numbered 0 .. n_knots + 1 (0 and n_knots + 1 are
            the phantoms, bone ``k + 1`` sits on knot ``k``).
    """
    u = np.asarray(u, dtype=float)
    if n_knots < 2:
        raise ValueError(f"a skinned tube needs at least 2 knots, got {n_knots}")
    if np.any(u < -1e-9) or np.any(u > n_knots - 1 + 1e-9):
        raise ValueError(f"u must lie within [0, {n_knots - 1}]")
    base = np.clip(np.floor(u).astype(np.int64), 0, n_knots - 2)
    f = np.clip(u - base, 0.0, 1.0)
    w = np.stack([(1 - f) ** 3, 3 * f**3 - 6 * f**2 + 4, -3 * f**3 + 3 * f**2 + 3 * f + 1,
                  f**3], axis=-1) / 6.0
    idx = base[:, None] + np.arange(4)[None, :]  # knots base-1 .. base+2 = bones base .. base+3
    return idx, w


@dataclasses.dataclass(frozen=True)
class TubeSkin:
    """Bones on every ``stride``-th of ``n_samples`` backbone samples, ``spacing`` apart when bound.

    Args:
        n_samples: Backbone samples (rings) along the whole tube; ``(n_samples - 1)`` must be a
            multiple of ``stride``.
        stride: Samples between neighbouring bones.
        spacing: Bind-pose distance between neighbouring bones (m); the nominal one is best
            for the client's vertex normals, any positive value is correct.
    """

    n_samples: int
    stride: int
    spacing: float

    def __post_init__(self) -> None:
        if self.stride < 1 or (self.n_samples - 1) % self.stride:
            raise ValueError(f"n_samples - 1 = {self.n_samples - 1} is not a multiple of "
                             f"stride = {self.stride}")
        if self.spacing <= 0:
            raise ValueError(f"spacing must be > 0, got {self.spacing}")

    @property
    def n_knots(self) -> int:
        return (self.n_samples - 1) // self.stride + 1

    @property
    def n_bones(self) -> int:
        return self.n_knots + 2

    def bind_poses(self) -> Array:
        """(B, 4, 4) bind poses: identity rotation, bone b at z = (b - 1) * spacing."""
        poses = np.tile(np.eye(4), (self.n_bones, 1, 1))
        poses[:, 2, 3] = (np.arange(self.n_bones) - 1) * self.spacing
        return poses

    def bind(self, topology: TubeTopology, first_sample: npt.ArrayLike, radius: float,
             ) -> tuple[npt.NDArray[np.float32], Array]:
        """Straight bind-pose vertices and dense skin weights (V, B) of ``topology``.

        Args:
            topology: The tube(s) to bind; tube ``t``'s ring ``i`` is backbone sample
                ``first_sample[t] + i``.
            first_sample: (n_tubes,) backbone sample index of each tube's first ring.
            radius: Tube radius (m).
        """
        first = np.asarray(first_sample, dtype=float).reshape(topology.n_tubes, 1)
        u = (first + np.arange(topology.n_rings)[None, :]) / self.stride  # (T, R) knot units
        shape = (topology.n_tubes, topology.n_rings, 3)
        normals = np.broadcast_to([1.0, 0.0, 0.0], shape)
        binormals = np.broadcast_to([0.0, 1.0, 0.0], shape)
        centres = np.zeros(shape)
        centres[..., 2] = u
        # The same layout with radius 0 and z = u gives every vertex its arc position.
        u_vertex = topology.vertices(centres, normals, binormals, 0.0)[:, 2].astype(float)
        centres[..., 2] = u * self.spacing
        vertices = topology.vertices(centres, normals, binormals, radius)
        idx, w = bspline_weights(u_vertex, self.n_knots)
        dense = np.zeros((len(vertices), self.n_bones))
        np.put_along_axis(dense, idx, w, axis=1)
        return vertices, dense

    def bind_each(self, topology: TubeTopology, radius: float,
                  ) -> tuple[npt.NDArray[np.float32], Array, Array]:
        """Bind every tube of ``topology`` to a bone set of its own (tube ``t`` to bones
        ``t B .. t B + B - 1``): a curvature jump between tubes is then drawn sharp.

        Returns:
            Bind vertices (V, 3), dense skin weights (V, T B) and bind poses (T B, 4, 4).
        """
        if topology.n_rings != self.n_samples:
            raise ValueError(f"each tube must have {self.n_samples} rings, "
                             f"got {topology.n_rings}")
        one = TubeTopology(topology.n_rings, topology.sides, 1, topology.caps)
        vertices, weights = self.bind(one, [0], radius)
        t = topology.n_tubes
        dense = np.zeros((t * len(vertices), t * self.n_bones))
        for i in range(t):
            dense[i * len(vertices):(i + 1) * len(vertices),
                  i * self.n_bones:(i + 1) * self.n_bones] = weights
        return np.tile(vertices, (t, 1)), dense, np.tile(self.bind_poses(), (t, 1, 1))

    def bind_segments(self, topology: TubeTopology, n_segments: int, radius: float,
                      ) -> tuple[npt.NDArray[np.float32], Array, Array]:
        """Bind one tube of ``n_segments`` consecutive pieces of ``n_samples`` rings (shared
        end rings) to a bone set per piece: a curvature jump at a piece's end stays sharp.

        Ring ``i`` belongs to piece ``min(i // (n_samples - 1), n_segments - 1)``.

        Returns:
            Bind vertices (V, 3), dense skin weights (V, n_segments B) and bind poses.
        """
        per = self.n_samples - 1
        if topology.n_tubes != 1 or topology.n_rings != n_segments * per + 1:
            raise ValueError(f"need one tube of {n_segments * per + 1} rings, got "
                             f"{topology.n_tubes} of {topology.n_rings}")
        shape = (1, topology.n_rings, 3)
        normals = np.broadcast_to([1.0, 0.0, 0.0], shape)
        binormals = np.broadcast_to([0.0, 1.0, 0.0], shape)
        centres = np.zeros(shape)
        centres[..., 2] = np.arange(topology.n_rings)
        ring = topology.vertices(centres, normals, binormals, 0.0)[:, 2].astype(float)
        piece = np.minimum(np.round(ring).astype(int) // per, n_segments - 1)
        u = (ring - piece * per) / self.stride
        centres[..., 2] = np.arange(topology.n_rings) / self.stride * self.spacing
        vertices = topology.vertices(centres, normals, binormals, radius)
        idx, w = bspline_weights(u, self.n_knots)
        dense = np.zeros((len(vertices), n_segments * self.n_bones))
        np.put_along_axis(dense, idx + (piece * self.n_bones)[:, None], w, axis=1)
        bind = np.concatenate([self.bind_poses() + self._shift(k * per) for k in
                               range(n_segments)])
        return vertices, dense, bind

    def _shift(self, samples: int) -> Array:
        """A (4, 4) offset moving bind poses ``samples`` backbone samples along +z."""
        out = np.zeros((4, 4))
        out[2, 3] = samples / self.stride * self.spacing
        return out

    def bone_poses_segments(self, frames: npt.ArrayLike, n_segments: int) -> Array:
        """Bone poses of :meth:`bind_segments` / :meth:`bind_each`: one set per piece.

        ``frames`` (..., n_segments (n_samples - 1) + 1, 4, 4): leading dimensions are tubes
        posed together (one vectorised call); returns (..., n_segments n_bones, 4, 4).
        """
        f = np.asarray(frames, dtype=float)
        per = self.n_samples - 1
        pieces = np.stack([f[..., k * per:(k + 1) * per + 1, :, :] for k in range(n_segments)],
                          axis=-4)  # (..., n_segments, n_samples, 4, 4)
        poses = self.bone_poses(pieces)
        return poses.reshape(*f.shape[:-3], n_segments * self.n_bones, 4, 4)

    def bone_poses(self, frames: npt.ArrayLike, iterations: int = 3) -> Array:
        """(..., B, 4, 4) bone poses whose skinned centre line passes through the knot frames.

        Args:
            frames: (..., n_samples, 4, 4) backbone frames (columns: normal, binormal, tangent,
                centre), sampled evenly in arc length; leading dimensions are independent
                tubes, posed in one vectorised step.
            iterations: Fixed-point steps moving each bone by the residual at its knot.
        """
        f = np.asarray(frames, dtype=float)
        if f.shape[-3:] != (self.n_samples, 4, 4):
            raise ValueError(f"frames must have shape (..., {self.n_samples}, 4, 4), got "
                             f"{f.shape}")
        knots = f[..., :: self.stride, :, :]
        # Phantoms continue the tube with its end bends: T_-1 = T_0 T_1^-1 T_0 (and at the tip).
        k0, k1, kl, km = (knots[..., i, :, :] for i in (0, 1, -1, -2))
        before = k0 @ _rigid_inverse(k1) @ k0
        after = kl @ _rigid_inverse(km) @ kl
        poses = np.concatenate([before[..., None, :, :], knots, after[..., None, :, :]], axis=-3)
        target = knots[..., :3, 3]
        h = self.spacing
        n = self.n_knots
        # On knot k the blend uses bones k, k+1, k+2 at bind offsets +h, 0, -h along z.
        offsets = (h, 0.0, -h)
        for _ in range(iterations):
            p, t = poses[..., :3, 3], poses[..., :3, 2]
            centre = (_ON_KNOT[0] * (p[..., 0:n, :] + offsets[0] * t[..., 0:n, :])
                      + _ON_KNOT[1] * (p[..., 1:n + 1, :] + offsets[1] * t[..., 1:n + 1, :])
                      + _ON_KNOT[2] * (p[..., 2:n + 2, :] + offsets[2] * t[..., 2:n + 2, :]))
            err = centre - target
            poses[..., 1:-1, :3, 3] -= err
            poses[..., 0, :3, 3] -= err[..., 0, :]
            poses[..., -1, :3, 3] -= err[..., -1, :]
        return poses

    @staticmethod
    def deform(vertices: npt.ArrayLike, weights: npt.ArrayLike, bind: npt.ArrayLike,
               poses: npt.ArrayLike) -> Array:
        """Linear blend skinning as three.js draws it: v' = sum_i w_i B_i B_i,bind^-1 v."""
        v = np.asarray(vertices, dtype=float)
        w = np.asarray(weights, dtype=float)
        m = np.asarray(poses, dtype=float) @ np.linalg.inv(np.asarray(bind, dtype=float))
        per_bone = np.einsum("bij,vj->vbi", m[:, :3, :3], v) + m[None, :, :3, 3]  # (V, B, 3)
        return np.einsum("vb,vbi->vi", w, per_bone)


def _rigid_inverse(m: Array) -> Array:
    """Inverse of rigid (..., 4, 4) transforms: [R^T, -R^T p] (no general inverse needed)."""
    out = np.zeros_like(m)
    rt = np.swapaxes(m[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -(rt @ m[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def planar_matrices(poses: npt.ArrayLike, z: float) -> Array:
    """(..., 4, 4) frames of planar poses [x, y, theta] at height z: normal = left of the
    heading, binormal = world z, tangent = heading (the frames ``tube.planar_frames`` spans)."""
    p = np.asarray(poses, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    out = np.zeros(p.shape[:-1] + (4, 4))
    out[..., 0, 0], out[..., 1, 0] = -s, c
    out[..., 2, 1] = 1.0
    out[..., 0, 2], out[..., 1, 2] = c, s
    out[..., 0, 3], out[..., 1, 3], out[..., 2, 3] = p[..., 0], p[..., 1], z
    out[..., 3, 3] = 1.0
    return out
