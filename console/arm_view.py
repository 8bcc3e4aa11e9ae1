"""3D drawing of the selected arm, built once and updated in place every frame.

:class:`ArmView` subclasses create their viser scene nodes in ``__init__`` and only assign
``vertices`` / ``position`` / ``wxyz`` in :meth:`ArmView.update`, so no node is ever re-created
while the arm moves. The geometry itself comes from pure ``geometry(q)`` methods (vectorised
numpy, no viser), which tests check against the kinematics without a server.

* Soft planar arm: the backbone as a tube lying on the table (z = half-width), dark rings at the
  segment boundaries, the straight gripper in a contrasting colour and the palm point w_t.
* Extensible arm (base at the origin, local z = world z up): a thin backbone, the three racks of
  every segment as tubes on their constant-curvature offset arcs (one colour per rack, matching
  the readout), platform discs at the base and every segment end, and a tip frame.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import numpy.typing as npt
import viser
import viser.transforms as vtf

from console.model import ArmModel, DeltaModel, PlanarModel
from console.tube import TubeTopology, frames_from_matrices, planar_frames
from core.kinematics import delta as dk
from core.kinematics import planar as pk

Array = npt.NDArray[np.float64]
Geometry = dict[str, Any]

BODY_COLOR = (96, 178, 204)
RING_COLOR = (45, 62, 80)
MOUNT_COLOR = (120, 128, 140)
GRIPPER_COLOR = (236, 138, 44)
PALM_COLOR = (200, 40, 60)
RACK_COLORS = ((214, 82, 68), (74, 160, 88), (66, 110, 206))
PLATFORM_COLOR = (150, 160, 176)
BACKBONE_COLOR = (150, 160, 172)


class ArmView(ABC):
    """Scene nodes of one arm under ``root``; call :meth:`update` from one thread only."""

    def __init__(self, scene: viser.SceneApi, model: ArmModel, root: str = "/arm") -> None:
        self.scene = scene
        self.model = model
        self.root = root

    @abstractmethod
    def geometry(self, q: Array) -> Geometry:
        """Everything :meth:`update` assigns, computed from configuration ``q`` (pure)."""

    @abstractmethod
    def update(self, q: Array) -> None:
        """Redraw for configuration ``q`` by assigning to the existing handles."""


class PlanarArmView(ArmView):
    """Soft planar arm lying on the table plane."""

    samples_per_segment = 16
    sides = 20

    def __init__(self, scene: viser.SceneApi, model: PlanarModel, root: str = "/arm") -> None:
        super().__init__(scene, model, root)
        r = model.robot
        self.radius = r.half_width
        self.z = r.half_width  # the tube rests on the table
        n_rings = r.n_segments * self.samples_per_segment + 1
        self.body_topology = TubeTopology(n_rings, self.sides)
        self.ring_topology = TubeTopology(2, self.sides, n_tubes=r.n_segments)
        self.gripper_topology = TubeTopology(2, self.sides)
        g = self.geometry(model.zero())
        self.body = scene.add_mesh_simple(f"{root}/body", g["body"], self.body_topology.faces,
                                          color=BODY_COLOR)
        self.rings = scene.add_mesh_simple(f"{root}/segment_rings", g["rings"],
                                           self.ring_topology.faces, color=RING_COLOR)
        self.gripper = scene.add_mesh_simple(f"{root}/gripper", g["gripper"],
                                             self.gripper_topology.faces, color=GRIPPER_COLOR)
        self.palm = scene.add_icosphere(f"{root}/palm_point", radius=0.006, color=PALM_COLOR,
                                        position=g["palm"], cast_shadow=False)
        base = r.base_pose
        self.mount = scene.add_box(
            f"{root}/base_mount", color=MOUNT_COLOR, dimensions=(0.05, 0.02, 2 * self.z + 0.006),
            position=(base[0] - 0.01 * np.cos(base[2]), base[1] - 0.01 * np.sin(base[2]),
                      self.z + 0.003),
            wxyz=vtf.SO3.from_z_radians(base[2] - np.pi / 2).wxyz)

    def geometry(self, q: Array) -> Geometry:
        m: PlanarModel = self.model  # type: ignore[assignment]
        r = m.robot
        backbone = pk.sample_backbone(q, r.lengths, self.samples_per_segment, r.base_pose)
        body = self.body_topology.vertices(*planar_frames(backbone, self.z), self.radius)
        ends = backbone[self.samples_per_segment::self.samples_per_segment]  # (N, 3)
        half = 0.003
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

    def update(self, q: Array) -> None:
        g = self.geometry(q)
        self.body.vertices = g["body"]
        self.rings.vertices = g["rings"]
        self.gripper.vertices = g["gripper"]
        self.palm.position = g["palm"]


class DeltaArmView(ArmView):
    """Extensible tri-rack arm standing on the table."""

    samples_per_segment = 32
    sides = 12
    backbone_radius = 0.005
    rack_radius = 0.0035
    platform_thickness = 0.008

    def __init__(self, scene: viser.SceneApi, model: DeltaModel, root: str = "/arm") -> None:
        super().__init__(scene, model, root)
        r = model.robot
        n, s = r.n_segments, self.samples_per_segment
        self.beta = dk.rack_angles(r.phi)
        self.backbone_topology = TubeTopology(n * s + 1, self.sides)
        self.rack_topology = TubeTopology(s + 1, 8, n_tubes=n)
        self.platform_topology = TubeTopology(2, 40, n_tubes=n + 1)
        g = self.geometry(model.zero())
        self.backbone = scene.add_mesh_simple(
            f"{root}/backbone", g["backbone"], self.backbone_topology.faces,
            color=BACKBONE_COLOR)
        self.racks = [
            scene.add_mesh_simple(f"{root}/rack_{j + 1}", g["racks"][j], self.rack_topology.faces,
                                  color=RACK_COLORS[j])
            for j in range(3)]
        self.platforms = scene.add_mesh_simple(
            f"{root}/platforms", g["platforms"], self.platform_topology.faces,
            color=PLATFORM_COLOR)
        self.tip = scene.add_frame(f"{root}/tip", axes_length=0.05, axes_radius=0.003,
                                   origin_radius=0.006, position=g["tip_position"],
                                   wxyz=g["tip_wxyz"])

    def sample_frames(self, q: Array) -> Array:
        """Backbone frames (n, S+1, 4, 4): each segment sampled evenly in arc length."""
        m: DeltaModel = self.model  # type: ignore[assignment]
        r = m.robot
        ends = m.frames(q)  # (n+1, 4, 4)
        s = np.linspace(0.0, 1.0, self.samples_per_segment + 1)  # (S+1,)
        length = r.L0 + q[:, 2]  # (n,)
        # A constant-curvature sub-arc of arc fraction s bends s times as far: delta scales by s
        # in (dx, dy) and its length is s L, i.e. dL_s = s L - L0.
        sub = np.empty((len(q), len(s), 3))
        sub[..., :2] = q[:, None, :2] * s[None, :, None]
        sub[..., 2] = length[:, None] * s[None, :] - r.L0
        local = dk.segment_transform(sub, r.L0, r.d)  # (n, S+1, 4, 4)
        return np.einsum("nij,nsjk->nsik", ends[:-1], local)

    def geometry(self, q: Array) -> Geometry:
        m: DeltaModel = self.model  # type: ignore[assignment]
        r = m.robot
        frames = self.sample_frames(q)
        c, x, y = frames_from_matrices(frames)  # each (n, S+1, 3)
        def flat(a: Array) -> Array:  # (n, S+1, 3) -> (n S + 1, 3): shared segment ends once
            return np.concatenate([a[0, :1], a[:, 1:].reshape(-1, 3)])

        backbone = self.backbone_topology.vertices(flat(c), flat(x), flat(y),
                                                   self.backbone_radius)
        # Rack j runs on the offset arc at angle beta_j, radius d, around the backbone.
        centres = [c + r.d * (np.cos(b) * x + np.sin(b) * y) for b in self.beta]
        racks = [self.rack_topology.vertices(cj, x, y, self.rack_radius) for cj in centres]
        ends = m.frames(q)
        pc, px, py = frames_from_matrices(ends)
        pz = ends[:, :3, 2]
        t = self.platform_thickness
        lift = np.zeros(len(ends))
        lift[0] = t / 2  # the base platform sits on the table
        mid = pc + lift[:, None] * pz
        disc_c = np.stack([mid - t / 2 * pz, mid + t / 2 * pz], axis=1)
        platforms = self.platform_topology.vertices(
            disc_c, np.repeat(px[:, None], 2, 1), np.repeat(py[:, None], 2, 1), r.half_width)
        tip = ends[-1]
        return {"backbone": backbone, "racks": racks, "platforms": platforms,
                "rack_centres": centres,
                "tip_position": tip[:3, 3], "tip_wxyz": vtf.SO3.from_matrix(tip[:3, :3]).wxyz}

    def update(self, q: Array) -> None:
        g = self.geometry(q)
        self.backbone.vertices = g["backbone"]
        for handle, verts in zip(self.racks, g["racks"]):
            handle.vertices = verts
        self.platforms.vertices = g["platforms"]
        self.tip.position = g["tip_position"]
        self.tip.wxyz = g["tip_wxyz"]


def make_arm_view(scene: viser.SceneApi, model: ArmModel, root: str = "/arm") -> ArmView:
    """The view class matching the model's robot kind."""
    if isinstance(model, PlanarModel):
        return PlanarArmView(scene, model, root)
    if isinstance(model, DeltaModel):
        return DeltaArmView(scene, model, root)
    raise TypeError(f"no arm view for {type(model).__name__}")
