"""Smooth reachability shading: clipped to the table, areas true to the map, no overlap.

Independent expectations: a map that is one disc of PLANNABLE cells is shaded with the disc's
area (pi r^2, within the grid's resolution) and with no vertex outside the table rectangle even
when the map's grid is larger than the table; green and amber together cover what the map
calls reachable and never the same place twice.
"""

import numpy as np
import pytest

from console.scene.reach_shading import shading_meshes
from core.planning.reachability import FAILS, PLANNABLE, UNREACHABLE, ReachMap


def area(mesh):
    if mesh is None:
        return 0.0
    v, f = mesh
    a, b, c = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    return float(np.abs(cross).sum() / 2)


def disc_map(step=0.02, r_green=0.15, r_amber=0.25, centre=(0.0, 0.1)):
    xs, ys = np.arange(-0.5, 0.5 + 1e-9, step), np.arange(-0.3, 0.55 + 1e-9, step)
    d = np.hypot(*np.meshgrid(xs - centre[0], ys - centre[1]))
    status = np.where(d <= r_green, PLANNABLE, np.where(d <= r_amber, FAILS, UNREACHABLE))
    return ReachMap(xs, ys, status.astype(np.int8), 0.0165)


def test_shading_areas_match_the_map_and_do_not_overlap():
    meshes = shading_meshes(disc_map(), None)
    green, amber = area(meshes[PLANNABLE]), area(meshes[FAILS])
    assert green == pytest.approx(np.pi * 0.15 ** 2, rel=0.05)
    assert amber == pytest.approx(np.pi * (0.25 ** 2 - 0.15 ** 2), rel=0.05)
    # Green and amber are disjoint: their sum is the reachable disc, not more.
    assert green + amber == pytest.approx(np.pi * 0.25 ** 2, rel=0.05)


def test_shading_is_clipped_to_the_table_rectangle():
    extent = (-0.2, 0.3, -0.05, 0.3)           # the disc spills past every edge of it
    meshes = shading_meshes(disc_map(), extent)
    for mesh in meshes.values():
        v, _ = mesh
        assert v[:, 0].min() >= extent[0] - 1e-12 and v[:, 0].max() <= extent[1] + 1e-12
        assert v[:, 1].min() >= extent[2] - 1e-12 and v[:, 1].max() <= extent[3] + 1e-12
    # The part of the reachable disc on the table is still shaded (within the resolution).
    x = np.linspace(extent[0], extent[1], 801)
    y = np.linspace(extent[2], extent[3], 801)
    gx, gy = np.meshgrid(x, y)
    inside = np.hypot(gx, gy - 0.1) <= 0.25
    expected = inside.mean() * (extent[1] - extent[0]) * (extent[3] - extent[2])
    total = area(meshes[PLANNABLE]) + area(meshes[FAILS])
    assert total == pytest.approx(expected, rel=0.05)


def covered(mesh, pts):
    """Which of ``pts`` (k, 2) lie in a triangle of ``mesh``."""
    v, f = mesh
    a, b, c = (v[f[:, i], :2][None] for i in range(3))
    p = pts[:, None]

    def side(p0, p1):
        return (p1[..., 0] - p0[..., 0]) * (p[..., 1] - p0[..., 1]) - (
            p1[..., 1] - p0[..., 1]) * (p[..., 0] - p0[..., 0])

    s1, s2, s3 = side(a, b), side(b, c), side(c, a)
    inside = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    return (inside & (np.abs(s1) + np.abs(s2) + np.abs(s3) > 0)).any(1)


@pytest.mark.parametrize("draw", ["smooth", "blocks"])
def test_shading_edge_follows_the_disc(draw):
    """The green edge stays within 8 mm of the disc's circle everywhere (covers it 8 mm inside,
    not 6 mm outside); the old one square per cell (``reach_mesh``, a staircase of 2 cm
    steps) does not."""
    from console.scene.plan_view import reach_mesh

    reach = disc_map()
    mesh = shading_meshes(reach, None)[PLANNABLE] if draw == "smooth" else reach_mesh(
        reach, PLANNABLE)
    a = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], 1)
    inner = covered(mesh, (0.15 - 0.008) * ring + (0.0, 0.1))
    outer = covered(mesh, (0.15 + 0.006) * ring + (0.0, 0.1))
    follows = inner.all() and not outer.any()
    assert follows == (draw == "smooth")


def test_small_enough_to_send():
    meshes = shading_meshes(disc_map(step=0.02), None)
    size = sum(v.size * 4 + f.size * 4 for v, f in meshes.values())   # float32 / uint32
    assert size < 300_000


def signed_areas(mesh):
    v, f = mesh
    a, b, c = v[f[:, 0], :2], v[f[:, 1], :2], v[f[:, 2], :2]
    return ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]) / 2


@pytest.mark.parametrize("flip", [False, True])
def test_every_face_faces_up_so_one_side_is_enough(flip):
    # The console draws the shading one-sided (three.js draws a transparent double-sided mesh
    # twice a frame): every triangle must be counter-clockwise seen from above (+z), also for
    # a map whose grid runs from +x to -x (its cells' corners come clockwise).
    m = disc_map()
    if flip:
        m = ReachMap(m.xs[::-1].copy(), m.ys, m.status[:, ::-1].copy(), m.radius)
    for mesh in shading_meshes(m, None).values():
        s = signed_areas(mesh)
        assert (s > 0).all(), f"{(s <= 0).sum()} of {len(s)} faces face down"
        assert s.sum() == pytest.approx(area(mesh))
