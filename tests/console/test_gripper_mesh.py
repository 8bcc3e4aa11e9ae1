"""The pleated gripper asset: it loads, spans the robot file's gripper, closes like the simulator's
finger, and the arm view moves it by one pose and shows open / closed by visibility alone."""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh

from console.scene.arm_view_factory import make_arm_view
from console.scene.gripper_mesh import (ASSET, NEUTRAL_Y, GripperShape, bend, fit, gripper_vertices,
                                  load_asset)
from console.core.model import model_for
from core.control.gripper import GripperGeometry
from core.robots import load

SOFT = load("soft-arm")


def test_asset_loads_and_spans_the_robot_files_gripper() -> None:
    g = SOFT.gripper
    mesh = trimesh.load(ASSET, force="mesh")  # read independently of console.scene.gripper_mesh
    assert len(mesh.faces) > 100
    np.testing.assert_allclose(mesh.bounds, [[0.0, -g.half_width, -g.half_width],
                                             [g.length, g.half_width, g.half_width]], atol=1e-6)
    vertices, faces = load_asset()
    assert faces.max() < len(vertices)
    # Drawn in the tip frame (left, up, along): the gripper runs from the root to its length.
    v, _ = gripper_vertices(GripperShape.of(SOFT), closed=False)
    np.testing.assert_allclose(v.min(0), [-g.half_width, -g.half_width, 0.0], atol=1e-6)
    np.testing.assert_allclose(v.max(0), [g.half_width, g.half_width, g.length], atol=1e-6)


def test_asset_is_fitted_to_another_robots_gripper() -> None:
    shape = dataclasses.replace(GripperShape.of(SOFT), length=0.08, half_width=0.009)
    v = fit(load_asset()[0], shape)
    np.testing.assert_allclose(v.min(0), [0.0, -0.009, -0.009], atol=1e-9)
    np.testing.assert_allclose(v.max(0), [0.08, 0.009, 0.009], atol=1e-9)


def test_closed_gripper_curls_like_the_simulators_finger_without_stretching() -> None:
    shape = GripperShape.of(SOFT)
    sim = GripperGeometry.from_params(shape.length, SOFT.sim.gripper, SOFT.half_width)
    # The constraint layer's middle line, straight, then bent to the closed turn.
    x = np.linspace(0.0, shape.length, 400)
    y_n = NEUTRAL_Y * shape.half_width
    line = np.column_stack([x, np.full_like(x, y_n), np.zeros_like(x)])
    curled = bend(line, shape, shape.closed_turn)
    palm = x <= shape.palm_length
    np.testing.assert_array_equal(curled[palm], line[palm])  # the palm stays straight
    length = np.linalg.norm(np.diff(curled, axis=0), axis=1).sum()
    assert abs(length - shape.length) < 1e-5  # the layer bends, it does not stretch
    # The simulator's finger centreline (root at y = 0) at the same turn, shifted to the layer.
    finger = sim.centreline(shape.closed_turn)[0, 2:]  # palm end, then finger points
    s = np.concatenate([[0.0], sim.finger_length * np.arange(1, len(finger)) / (len(finger) - 1)])
    ours = bend(np.column_stack([shape.palm_length + s, np.full_like(s, y_n), 0 * s]), shape,
                shape.closed_turn)
    np.testing.assert_allclose(ours[:, :2], finger + [0.0, y_n], atol=1e-9)
    # Closing toward +y (left): the finger tip ends on the closing side.
    assert curled[-1, 1] > y_n


def test_arm_view_moves_the_gripper_by_one_pose_and_closes_it_by_visibility(server) -> None:
    view = make_arm_view(server.scene, model_for(SOFT))
    q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
    sent: list[object] = []
    original = server.scene._queue_scene_message
    server.scene._queue_scene_message = lambda m: (sent.append(m), original(m))[1]
    assert view.update(q)
    mine = [m for m in sent if "/gripper" in str(getattr(m, "name", ""))]
    assert {type(m).__name__ for m in mine} <= {"SetPositionMessage", "SetOrientationMessage"}
    assert all(m.name == "/arm/gripper" for m in mine) and len(mine) == 2
    # The far end of the drawn (open) gripper lies one gripper length along the tip heading.
    tip = view.frames(q)[-1]
    np.testing.assert_allclose(view.gripper.position, tip[:3, 3], atol=1e-9)
    v, _ = gripper_vertices(GripperShape.of(SOFT), closed=False)
    import viser.transforms as vtf

    rot = vtf.SO3(np.asarray(view.gripper.wxyz)).as_matrix()
    world = v.astype(float) @ rot.T + view.gripper.position
    heading = q.sum() * SOFT.segment_length + SOFT.base_pose[2]  # equal segment lengths
    far = tip[:2, 3] + SOFT.gripper.length * np.array([np.cos(heading), np.sin(heading)])
    along = (world[:, :2] - tip[:2, 3]) @ [np.cos(heading), np.sin(heading)]
    assert abs(along.max() - SOFT.gripper.length) < 1e-6
    np.testing.assert_allclose(world[np.argmax(along), :2], far, atol=SOFT.gripper.half_width)
    # Open / closed: two visibility messages on a change, none when it stays.
    sent.clear()
    view.set_gripper_closed(True)
    assert view.gripper_shapes[True].visible and not view.gripper_shapes[False].visible
    assert len(sent) == 2
    view.set_gripper_closed(True)
    assert len(sent) == 2
    view.set_gripper_closed(False)
    assert view.gripper_shapes[False].visible and not view.gripper_shapes[True].visible
