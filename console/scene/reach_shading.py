"""Smooth reachability shading clipped to the table: the map's cells as rounded filled regions.

A :class:`core.planning.reachability.ReachMap` is a grid of outcomes; drawn as one square per
cell it is a block pattern. Here each outcome's indicator (1 in the cell, 0 outside) is refined
to twice the grid's resolution (bilinear), blurred once with a [1, 2, 1] kernel and contoured at
one half by marching triangles, so the edges run between differing cells with rounded corners.
The grid's axes are first clipped to the table rectangle, so every vertex lies on the table.
Green (plannable) and amber (reachable, the approach fails) never overlap: amber is "reachable
and not plannable". Pure numpy; :func:`shading_meshes` is what the grasp layer draws.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.planning.reachability import FAILS, PLANNABLE, ReachMap

Array = npt.NDArray[np.float64]
Mesh = tuple[Array, npt.NDArray[np.uint32]]
LEVEL = 0.5


def _refine(values: Array, axis: int) -> Array:
    """Insert the midpoint between neighbours along ``axis`` (n -> 2n - 1 samples)."""
    v = np.moveaxis(values, axis, 0)
    out = np.empty((2 * len(v) - 1,) + v.shape[1:])
    out[0::2] = v
    out[1::2] = 0.5 * (v[:-1] + v[1:])
    return np.moveaxis(out, 0, axis)


def _blur_rows(v: Array) -> Array:
    """One [1, 2, 1] / 4 pass along the first axis (edges repeated)."""
    p = np.concatenate([v[:1], v, v[-1:]])
    return 0.25 * p[:-2] + 0.5 * p[1:-1] + 0.25 * p[2:]


def smooth_fields(reach: ReachMap, extent: tuple[float, float, float, float] | None
                  ) -> tuple[Array, Array, Array, Array]:
    """(xs, ys, plannable, reachable): the refined lattice (clipped to ``extent``) and the two
    blurred indicators on it, each (len(ys), len(xs))."""
    xs, ys = reach.xs.astype(float), reach.ys.astype(float)
    if extent is not None:
        x0, x1, y0, y1 = extent
        xs, ys = np.clip(xs, x0, x1), np.clip(ys, y0, y1)
    fields = []
    for wanted in ((PLANNABLE,), (PLANNABLE, FAILS)):
        f = np.isin(reach.status, wanted).astype(float)
        if f.shape[0] > 1:
            f = _blur_rows(_refine(f, 0))
        if f.shape[1] > 1:
            f = _blur_rows(_refine(f, 1).T).T
        fields.append(f)
    if len(xs) > 1:
        xs = _refine(xs, 0)
    if len(ys) > 1:
        ys = _refine(ys, 0)
    return xs, ys, fields[0], fields[1]


def _clip(poly: list[Array], which: int, level: float) -> list[Array]:
    """Sutherland-Hodgman: the part of a polygon (rows x, y, f0, f1) where column ``which`` >=
    ``level`` (linear along each edge)."""
    out: list[Array] = []
    for k, cur in enumerate(poly):
        prev = poly[k - 1]
        a, b = prev[which] - level, cur[which] - level
        if (a > 0 > b) or (a < 0 < b):
            out.append(prev + (a / (a - b)) * (cur - prev))
        if b >= 0:
            out.append(cur)
    return out


def region_mesh(xs: Array, ys: Array, fields: list[Array], z: float) -> Mesh | None:
    """Triangles of the region where every field is >= LEVEL (marching triangles), each wound
    counter-clockwise seen from above, so the shading can be drawn one-sided (its front faces
    up): three.js draws a transparent double-sided mesh twice a frame (back faces, then
    front), and a software renderer pays for the vertices of both draws."""
    ny, nx = fields[0].shape
    if nx < 2 or ny < 2:
        return None
    gx, gy = np.meshgrid(xs, ys)
    node = np.arange(nx * ny).reshape(ny, nx)
    a, b = node[:-1, :-1].ravel(), node[:-1, 1:].ravel()
    c, d = node[1:, 1:].ravel(), node[1:, :-1].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    vals = np.stack([f.ravel() for f in fields], 1)                       # (nodes, k)
    inside = (vals >= LEVEL).all(1)
    full = inside[tris].all(1)
    # A triangle can hold part of the region only if each field is above LEVEL at a corner.
    partial = ~full & (vals[tris] >= LEVEL).any(1).all(1)
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    used, full_faces = np.unique(tris[full], return_inverse=True)
    verts = [pts[used]]
    faces = [full_faces.reshape(-1, 3)]
    count = len(used)
    extra_v, extra_f = [], []
    for t in tris[partial]:
        poly = [np.concatenate([pts[i], vals[i]]) for i in t]
        for k in range(vals.shape[1]):
            poly = _clip(poly, 2 + k, LEVEL)
            if len(poly) < 3:
                break
        if len(poly) < 3:
            continue
        extra_v.extend(p[:2] for p in poly)
        extra_f.extend([count, count + i, count + i + 1] for i in range(1, len(poly) - 1))
        count += len(poly)
    if extra_v:
        verts.append(np.array(extra_v))
        faces.append(np.array(extra_f))
    v2 = np.concatenate(verts)
    f = np.concatenate(faces).astype(np.uint32)
    p, q, r = v2[f[:, 0]], v2[f[:, 1]], v2[f[:, 2]]
    twice_area = (q - p)[:, 0] * (r - p)[:, 1] - (q - p)[:, 1] * (r - p)[:, 0]
    keep = np.abs(twice_area) > 1e-14
    f, up = f[keep], twice_area[keep] > 0
    f = np.where(up[:, None], f, f[:, ::-1])  # every face counter-clockwise: it faces up (+z)
    if len(f) == 0:
        return None
    return np.c_[v2, np.full(len(v2), z)], f


def shading_meshes(reach: ReachMap, extent: tuple[float, float, float, float] | None = None,
                   z: float = 0.0007) -> dict[int, Mesh | None]:
    """Meshes of the PLANNABLE (green) and FAILS (amber: reachable, not plannable) regions."""
    xs, ys, plannable, reachable = smooth_fields(reach, extent)
    return {PLANNABLE: region_mesh(xs, ys, [plannable], z),
            FAILS: region_mesh(xs, ys, [reachable, 1.0 - plannable], z)}
