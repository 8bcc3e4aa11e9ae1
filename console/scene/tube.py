"""Vectorised tube meshes swept along framed centre lines, so arms render as smooth bodies.

A tube is a sequence of rings: ring ``i`` is a circle of radius ``r_i`` around ``centers[i]``
in the plane spanned by the unit vectors ``normals[i]`` and ``binormals[i]``; the tangent is
``normals x binormals``. The topology (vertex count and faces) depends only on the number of
tubes, rings and sides, never on the configuration, so a viser mesh handle built once can be
updated in place (``handle.vertices = topology.vertices(...)``) every frame.

Vertex layout per tube: ``n_rings * sides`` side vertices, then (if ``caps``) a start-cap centre
and its own ring of ``sides`` vertices, then the end-cap centre and ring. Cap rings duplicate the
side rings so cap edges stay crisp under the client's smooth vertex normals. All faces wind
counter-clockwise seen from outside (outward normals).
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class TubeTopology:
    """Fixed connectivity of ``n_tubes`` tubes of ``n_rings`` rings with ``sides`` sides each."""

    n_rings: int
    sides: int = 16
    n_tubes: int = 1
    caps: bool = True

    def __post_init__(self) -> None:
        if self.n_rings < 2:
            raise ValueError(f"a tube needs at least 2 rings, got {self.n_rings}")
        if self.sides < 3:
            raise ValueError(f"a tube needs at least 3 sides, got {self.sides}")
        if self.n_tubes < 1:
            raise ValueError(f"n_tubes must be >= 1, got {self.n_tubes}")

    @property
    def vertices_per_tube(self) -> int:
        """Vertices of one tube, caps included."""
        return self.n_rings * self.sides + (2 * (self.sides + 1) if self.caps else 0)

    @property
    def n_vertices(self) -> int:
        """Total vertex count of the mesh."""
        return self.n_tubes * self.vertices_per_tube

    @cached_property
    def faces(self) -> npt.NDArray[np.uint32]:
        """Triangle indices, shape (F, 3), outward winding."""
        m, k = self.n_rings, self.sides
        i, j = np.meshgrid(np.arange(m - 1), np.arange(k), indexing="ij")
        j1 = (j + 1) % k
        a, b = i * k + j, i * k + j1  # ring i
        c, d = (i + 1) * k + j, (i + 1) * k + j1  # ring i + 1
        side = np.concatenate(
            [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
        parts = [side]
        if self.caps:
            ring = np.arange(k)
            s0 = m * k  # start-cap centre; its ring follows
            e0 = s0 + k + 1  # end-cap centre; its ring follows
            start = np.stack([np.full(k, s0), s0 + 1 + (ring + 1) % k, s0 + 1 + ring], -1)
            end = np.stack([np.full(k, e0), e0 + 1 + ring, e0 + 1 + (ring + 1) % k], -1)
            parts += [start, end]
        one = np.concatenate(parts)
        offsets = np.arange(self.n_tubes)[:, None, None] * self.vertices_per_tube
        return (one[None] + offsets).reshape(-1, 3).astype(np.uint32)

    @cached_property
    def _circle(self) -> tuple[Array, Array]:
        angle = 2 * np.pi * np.arange(self.sides) / self.sides
        return np.cos(angle), np.sin(angle)

    def vertices(
        self,
        centers: npt.ArrayLike,
        normals: npt.ArrayLike,
        binormals: npt.ArrayLike,
        radius: float | npt.ArrayLike,
    ) -> npt.NDArray[np.float32]:
        """Vertex positions for the given framed centre lines.

        Args:
            centers: (n_tubes, n_rings, 3) ring centres, or (n_rings, 3) when n_tubes == 1.
            normals: Same shape; unit vectors spanning the ring plane with ``binormals``.
            binormals: Same shape; ``normals x binormals`` is the tube's forward tangent.
            radius: Scalar, (n_rings,) or (n_tubes, n_rings).

        Returns:
            (n_vertices, 3) float32 array matching :attr:`faces`.
        """
        want = (self.n_tubes, self.n_rings, 3)
        arrays = []
        for name, value in (("centers", centers), ("normals", normals), ("binormals", binormals)):
            arr = np.asarray(value, dtype=float)
            if arr.shape == want[1:] and self.n_tubes == 1:
                arr = arr[None]
            if arr.shape != want:
                raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
            arrays.append(arr)
        c, n, b = arrays
        r = np.broadcast_to(np.asarray(radius, dtype=float), want[:2])[..., None, None]
        cos, sin = self._circle
        offset = cos[:, None] * n[:, :, None, :] + sin[:, None] * b[:, :, None, :]  # (T, M, K, 3)
        rings = c[:, :, None, :] + r * offset
        parts = [rings.reshape(self.n_tubes, -1, 3)]
        if self.caps:
            parts += [c[:, :1], rings[:, 0], c[:, -1:], rings[:, -1]]
        return np.concatenate(parts, axis=1).reshape(-1, 3).astype(np.float32)


def frames_from_matrices(frames: npt.ArrayLike) -> tuple[Array, Array, Array]:
    """Centres, normals (local x) and binormals (local y) of (..., 4, 4) frames (tangent = z)."""
    f = np.asarray(frames, dtype=float)
    return f[..., :3, 3], f[..., :3, 0], f[..., :3, 1]


def planar_frames(poses: npt.ArrayLike, z: float) -> tuple[Array, Array, Array]:
    """Frames of planar poses [x, y, theta] (..., 3) lifted to height ``z``.

    The tangent is the heading in the table plane; the normal is its left in-plane normal and
    the binormal is world z, so ``normal x binormal`` is the heading.
    """
    p = np.asarray(poses, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    zeros = np.zeros_like(c)
    centers = np.stack([p[..., 0], p[..., 1], np.full_like(c, z)], axis=-1)
    normals = np.stack([-s, c, zeros], axis=-1)
    binormals = np.stack([zeros, zeros, np.ones_like(c)], axis=-1)
    return centers, normals, binormals
