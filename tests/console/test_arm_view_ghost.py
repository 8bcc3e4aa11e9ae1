"""A planned path's ghost arms come from the arm's own view (``ArmView.ghost_mesh``), so the Paths
panel draws them without asking which arm it has: each ghost is one static mesh whose segment
ends sit where the kinematics put them."""

from __future__ import annotations

import numpy as np

from console.core.model import model_for
from console.panels.extensible.path_scene import N_GHOSTS, PathScene
from console.scene.arm_view_factory import make_arm_view
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.planning.paths import MotionPath
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")


def check_faces(verts: np.ndarray, faces: np.ndarray) -> None:
    assert faces.dtype == np.uint32 and faces.shape[1] == 3
    assert faces.max() == len(verts) - 1 and faces.min() == 0  # every part re-indexed


def test_soft_arm_ghost_is_body_rings_and_gripper_on_the_kinematics(server) -> None:
    view = make_arm_view(server.scene, model_for(SOFT), method="vertices", dead_band=None)
    q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
    verts, faces = view.ghost_mesh(q)
    check_faces(verts, faces)
    sides = 20
    n_body = (SOFT.n_segments * 16 + 1) * sides
    body_tip = verts[n_body - sides:n_body].mean(axis=0)
    tip = pk.forward_kinematics(q, SOFT.lengths, SOFT.base_pose)[-1]
    np.testing.assert_allclose(body_tip[:2], tip[:2], atol=1e-6)
    g = view.geometry(q)
    np.testing.assert_array_equal(verts, np.vstack([g["body"], g["rings"], g["gripper"]]))


def test_extensible_ghost_ends_on_the_tip_and_path_scene_draws_them(server) -> None:
    model = model_for(EXT)
    view = make_arm_view(server.scene, model, dead_band=None)
    q = model.initial()
    q[:, 0] = 0.01
    verts, faces = view.ghost_mesh(q)
    check_faces(verts, faces)
    tip = dk.forward_kinematics(q, EXT.L0, EXT.d)[-1, :3, 3]
    disc = view.platform_topology.vertices_per_tube  # the platforms come last, the tip's last
    np.testing.assert_allclose(verts[-disc:].mean(axis=0), tip, atol=1e-6)

    deltas = np.stack([model.initial(), q, q])
    zeros = np.zeros((3, 3))
    path = MotionPath(times=np.arange(3) * 0.01, targets=zeros, tips=zeros, deltas=deltas,
                      lengths=np.zeros_like(deltas), motor_counts=np.zeros((3, 9), np.int64),
                      errors=np.zeros(3), rate_hz=100.0, jumps=0)
    drawing = PathScene(server.scene)
    drawing.draw_preview(path, np.zeros((2, 3)), view)
    assert len(drawing.ghosts) == N_GHOSTS and all(g.visible for g in drawing.ghosts)
    np.testing.assert_allclose(drawing.ghosts[-1].vertices, view.ghost_mesh(q)[0], atol=1e-6)
