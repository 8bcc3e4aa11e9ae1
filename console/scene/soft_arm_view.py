"""The soft arm's drawing, apart from the pacing and the tubes every arm view shares.

* Soft arm (planar): the backbone as a tube lying on the table (z = half-width), dark rings at the
  segment boundaries, the pleated gripper in a contrasting colour (a plain rod in the
  ``"vertices"`` drawing) and the palm point w_t.

:func:`console.scene.arm_view_factory.make_arm_view` builds it for a
:class:`console.core.model.SoftArmModel`; how it is drawn and
paced (``"skinned"`` / ``"vertices"``, the dead band): :mod:`console.scene.arm_view`.
"""

from __future__ import annotations

import numpy as np
import viser
import viser.transforms as vtf

from console.scene.arm_view import (BODY_COLOR, GRIPPER_COLOR, MOUNT_COLOR, PALM_COLOR,
                                    RING_COLOR, ArmView, Array, Geometry, Method,
                                    add_skinned_tube, batched_color, merge_meshes, pose_bones,
                                    wxyzs)
from console.scene.dead_band import DeadBand
from console.scene.gripper_mesh import GripperShape, gripper_vertices, load_asset
from console.core.model import SoftArmModel
from console.scene.skin import TubeSkin, planar_matrices
from console.scene.tube import TubeTopology, planar_frames
from core.kinematics import planar as pk


class SoftArmView(ArmView[SoftArmModel]):
    """Soft arm lying on the table plane."""

    samples_per_segment = 16
    sides = 20
    bone_stride = 4  # samples between bones: 4 bones per segment, 27 in all
    ring_half_length = 0.003

    def __init__(self, scene: viser.SceneApi, model: SoftArmModel, root: str = "/arm",
                 method: Method = "skinned", dead_band: DeadBand | None = DeadBand()) -> None:
        super().__init__(scene, model, root, method, dead_band)
        r = model.robot
        self.radius = r.half_width
        self.z = r.half_width  # the tube rests on the table
        n_rings = r.n_segments * self.samples_per_segment + 1
        self.body_topology = TubeTopology(n_rings, self.sides)
        self.ring_topology = TubeTopology(2, self.sides, n_tubes=r.n_segments)
        self.gripper_topology = TubeTopology(2, self.sides)
        self.gripper_closed = False
        # The pleated gripper open and closed ("skinned"); the "vertices" drawing has a rod.
        self.gripper_shapes: dict[bool, viser.MeshHandle] = {}
        self.skin = TubeSkin(n_rings, self.bone_stride,
                             float(np.mean(r.lengths)) / self.samples_per_segment
                             * self.bone_stride)
        q0 = model.zero()
        g = self.geometry(q0)
        if method == "vertices":
            self.body = scene.add_mesh_simple(f"{root}/body", g["body"],
                                              self.body_topology.faces, color=BODY_COLOR)
            self.rings = scene.add_mesh_simple(f"{root}/segment_rings", g["rings"],
                                               self.ring_topology.faces, color=RING_COLOR)
            self.gripper = scene.add_mesh_simple(f"{root}/gripper", g["gripper"],
                                                 self.gripper_topology.faces,
                                                 color=GRIPPER_COLOR)
        else:
            self.body = add_skinned_tube(scene, f"{root}/body", self.skin, self.body_topology,
                                         self.radius, BODY_COLOR)
            # One ring band and one gripper, drawn in their own frames (tangent = local z).
            band = TubeTopology(2, self.sides)
            ends = self._frames_at_ends(self.frames(q0))
            self.rings = scene.add_batched_meshes_simple(
                f"{root}/segment_rings",
                band.vertices([[0, 0, -self.ring_half_length], [0, 0, self.ring_half_length]],
                              [[1, 0, 0]] * 2, [[0, 1, 0]] * 2, self.radius * 1.18),
                band.faces, wxyzs(ends), ends[:, :3, 3],
                batched_colors=batched_color(RING_COLOR), lod="off")
            # The pleated gripper (static/gripper.stl fitted to the robot file), open and
            # closed, under one node moved by the tip pose; closing only swaps visibility.
            self.gripper = scene.add_frame(f"{root}/gripper", show_axes=False)
            shape = GripperShape.of(r)
            asset = load_asset()
            self.gripper_shapes = {
                closed: scene.add_mesh_simple(
                    f"{root}/gripper/{'closed' if closed else 'open'}",
                    *gripper_vertices(shape, closed, asset), color=GRIPPER_COLOR,
                    flat_shading=True, visible=not closed)
                for closed in (False, True)}
        self.palm = scene.add_icosphere(f"{root}/palm_point", radius=0.006, color=PALM_COLOR,
                                        position=g["palm"], cast_shadow=False)
        base = r.base_pose
        self.mount = scene.add_box(
            f"{root}/base_mount", color=MOUNT_COLOR, dimensions=(0.05, 0.02, 2 * self.z + 0.006),
            position=(base[0] - 0.01 * np.cos(base[2]), base[1] - 0.01 * np.sin(base[2]),
                      self.z + 0.003),
            wxyz=vtf.SO3.from_z_radians(base[2] - np.pi / 2).wxyz)
        self.update(q0)

    def set_gripper_closed(self, closed: bool) -> None:
        """Show the pleated gripper curled (closed) or straight (open): two visibility
        messages on a change, nothing otherwise; any thread (``"vertices"`` draws a rod)."""
        shapes = self.gripper_shapes
        closed = bool(closed)
        if not shapes or closed == self.gripper_closed:
            return
        self.gripper_closed = closed
        shapes[closed].visible = True
        shapes[not closed].visible = False

    def _frames_at_ends(self, frames: Array) -> Array:
        return frames[self.samples_per_segment::self.samples_per_segment]

    def frames(self, q: Array) -> Array:
        """(n S + 1, 4, 4) backbone frames at the table height (tangent = local z)."""
        r = self.model.robot
        backbone = pk.sample_backbone(q, r.lengths, self.samples_per_segment, r.base_pose)
        return planar_matrices(backbone, self.z)

    def geometry(self, q: Array) -> Geometry:
        m = self.model
        r = m.robot
        backbone = pk.sample_backbone(q, r.lengths, self.samples_per_segment, r.base_pose)
        body = self.body_topology.vertices(*planar_frames(backbone, self.z), self.radius)
        ends = backbone[self.samples_per_segment::self.samples_per_segment]  # (N, 3)
        half = self.ring_half_length
        heading = np.stack([np.cos(ends[:, 2]), np.sin(ends[:, 2]), np.zeros(len(ends))], -1)
        c, n, b = planar_frames(ends, self.z)
        ring_c = np.stack([c - half * heading, c + half * heading], axis=1)
        rings = self.ring_topology.vertices(ring_c, np.repeat(n[:, None], 2, 1),
                                            np.repeat(b[:, None], 2, 1), self.radius * 1.18)
        tip = ends[-1]
        g_end = tip.copy()
        g_end[:2] += r.gripper.length * heading[-1, :2]
        gc, gn, gb = planar_frames(np.stack([tip, g_end]), self.z)
        gripper = self.gripper_topology.vertices(gc, gn, gb, r.gripper.half_width * 0.85)
        palm_xy = m.palm_point(tip)
        return {"body": body, "rings": rings, "gripper": gripper, "tip": tip,
                "palm": np.array([palm_xy[0], palm_xy[1], self.z + 0.004])}

    def ghost_mesh(self, q: Array) -> tuple[Array, Array]:
        """Body, segment rings and gripper rod at ``q`` as one mesh."""
        g = self.geometry(q)
        return merge_meshes([(g["body"], self.body_topology.faces),
                             (g["rings"], self.ring_topology.faces),
                             (g["gripper"], self.gripper_topology.faces)])

    def _palm(self, tip_frame: Array) -> Array:
        heading = np.arctan2(tip_frame[1, 2], tip_frame[0, 2])
        palm_xy = self.model.palm_point(np.array([tip_frame[0, 3], tip_frame[1, 3], heading]))
        return np.array([palm_xy[0], palm_xy[1], self.z + 0.004])

    def _send(self, q: Array, frames: Array) -> None:
        if self.method == "vertices":
            g = self.geometry(q)
            self.body.vertices = g["body"]
            self.rings.vertices = g["rings"]
            self.gripper.vertices = g["gripper"]
            self.palm.position = g["palm"]
            return
        pose_bones(self.body, self.skin.bone_poses(frames))
        ends = self._frames_at_ends(frames)
        self.rings.batched_wxyzs = wxyzs(ends)
        self.rings.batched_positions = ends[:, :3, 3]
        tip = ends[-1]
        self.gripper.wxyz = wxyzs(tip[None])[0]
        self.gripper.position = tip[:3, 3]
        self.palm.position = self._palm(tip)
