"""The extensible arm's drawing, apart from the pacing and the tubes every arm view shares.

* Extensible arm (base at the origin, local z = world z up): a thin backbone, the three racks of
  every segment as tubes on their constant-curvature offset arcs (one colour per rack, matching
  the readout), platform discs at the base and every segment end, and a tip frame.

:func:`console.scene.arm_view_factory.make_arm_view` builds it for a
:class:`console.core.model.ExtensibleModel`; how it is drawn and
paced (``"skinned"`` / ``"vertices"``, the dead band): :mod:`console.scene.arm_view`.
"""

from __future__ import annotations

import numpy as np
import viser
import viser.transforms as vtf

from console.scene.arm_view import (BACKBONE_COLOR, PLATFORM_COLOR, RACK_COLORS, ArmView, Array,
                                    Geometry, Method, add_skinned_tube, batched_color,
                                    merge_meshes, quantize, wxyzs)
from console.scene.dead_band import DeadBand
from console.core.model import ExtensibleModel
from console.scene.skin import TubeSkin
from console.scene.tube import TubeTopology, frames_from_matrices
from console.web.shared_sends import set_bone_poses
from core.kinematics import delta as dk


class ExtensibleArmView(ArmView[ExtensibleModel]):
    """Extensible tri-rack arm standing on the table."""

    samples_per_segment = 32
    sides = 12
    backbone_radius = 0.005
    rack_radius = 0.0035
    platform_thickness = 0.008

    bone_stride = 8  # samples between bones: 4 bones per segment

    def __init__(self, scene: viser.SceneApi, model: ExtensibleModel, root: str = "/arm",
                 method: Method = "skinned", dead_band: DeadBand | None = DeadBand()) -> None:
        super().__init__(scene, model, root, method, dead_band)
        r = model.robot
        n, s = r.n_segments, self.samples_per_segment
        self.beta = dk.rack_angles(r.phi)
        self.backbone_topology = TubeTopology(n * s + 1, self.sides)
        self.rack_topology = TubeTopology(s + 1, 8, n_tubes=n)
        self.platform_topology = TubeTopology(2, 40, n_tubes=n + 1)
        q0 = model.zero()
        # A bone set per segment (backbone and racks): the bend changes sharply at a
        # platform, and the racks' ends stay on it.
        self.skin = TubeSkin(s + 1, self.bone_stride,
                             float(r.L0 + np.mean(q0[:, 2])) / s * self.bone_stride)
        g = self.geometry(q0)
        if method == "vertices":
            self.backbone = scene.add_mesh_simple(
                f"{root}/backbone", g["backbone"], self.backbone_topology.faces,
                color=BACKBONE_COLOR)
            self.racks = [
                scene.add_mesh_simple(f"{root}/rack_{j + 1}", g["racks"][j],
                                      self.rack_topology.faces, color=RACK_COLORS[j])
                for j in range(3)]
            self.platforms = scene.add_mesh_simple(
                f"{root}/platforms", g["platforms"], self.platform_topology.faces,
                color=PLATFORM_COLOR)
        else:
            self.backbone = add_skinned_tube(scene, f"{root}/backbone", self.skin,
                                             self.backbone_topology, self.backbone_radius,
                                             BACKBONE_COLOR, segments=n)
            self.racks = [
                add_skinned_tube(scene, f"{root}/rack_{j + 1}", self.skin,
                                 self.rack_topology, self.rack_radius, RACK_COLORS[j],
                                 each=True)
                for j in range(3)]
            disc = TubeTopology(2, 40)
            t = self.platform_thickness
            ends = self._platform_frames(self.frames(q0))
            self.platforms = scene.add_batched_meshes_simple(
                f"{root}/platforms",
                disc.vertices([[0, 0, -t / 2], [0, 0, t / 2]], [[1, 0, 0]] * 2, [[0, 1, 0]] * 2,
                              r.half_width),
                disc.faces, wxyzs(ends), ends[:, :3, 3],
                batched_colors=batched_color(PLATFORM_COLOR), lod="off")
        self.tip = scene.add_frame(f"{root}/tip", axes_length=0.05, axes_radius=0.003,
                                   origin_radius=0.006, position=g["tip_position"],
                                   wxyz=g["tip_wxyz"])
        self.update(q0)

    def frames(self, q: Array) -> Array:
        """(n S + 1, 4, 4) backbone frames, segment ends once (tangent = local z)."""
        f = self.sample_frames(q)
        return np.concatenate([f[0, :1], f[:, 1:].reshape(-1, 4, 4)])

    def rack_frames(self, frames: Array, j: int) -> Array:
        """Frames of rack ``j``'s centre line: the backbone's, moved out to radius d."""
        out = frames.copy()
        b = self.beta[j]
        out[:, :3, 3] += self.model.robot.d * (np.cos(b) * frames[:, :3, 0]
                                               + np.sin(b) * frames[:, :3, 1])
        return out

    def rack_bone_poses(self, frames: Array, j: int) -> Array:
        """Bone poses of rack ``j``: one bone set per segment, on the rack's centre line."""
        return self.skin.bone_poses_segments(self.rack_frames(frames, j),
                                                  (len(frames) - 1) // self.samples_per_segment)

    def _platform_frames(self, frames: Array) -> Array:
        ends = frames[::self.samples_per_segment].copy()
        ends[0, :3, 3] += self.platform_thickness / 2 * ends[0, :3, 2]  # base disc on the table
        return ends

    def sample_frames(self, q: Array) -> Array:
        """Backbone frames (n, S+1, 4, 4): each segment sampled evenly in arc length."""
        m = self.model
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
        m = self.model
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

    def ghost_mesh(self, q: Array) -> tuple[Array, Array]:
        """Backbone, racks and platforms at ``q`` as one mesh."""
        g = self.geometry(q)
        parts = [(g["backbone"], self.backbone_topology.faces)]
        parts += [(r, self.rack_topology.faces) for r in g["racks"]]
        parts.append((g["platforms"], self.platform_topology.faces))
        return merge_meshes(parts)

    def _send(self, q: Array, frames: Array) -> None:
        if self.method == "vertices":
            g = self.geometry(q)
            self.backbone.vertices = g["backbone"]
            for handle, verts in zip(self.racks, g["racks"]):
                handle.vertices = verts
            self.platforms.vertices = g["platforms"]
        else:
            # The backbone and the three racks posed in one vectorised step, their
            # quaternions in one conversion (per tube, these were half the render's time).
            tubes = np.stack([frames, *(self.rack_frames(frames, j) for j in range(3))])
            poses = self.skin.bone_poses_segments(tubes, len(q))  # (4, B, 4, 4)
            quats = quantize(wxyzs(poses.reshape(-1, 4, 4))).reshape(len(tubes), -1, 4)
            positions = quantize(poses[..., :3, 3])
            for handle, wxyz, position in zip((self.backbone, *self.racks), quats, positions):
                set_bone_poses(handle, wxyz, position)
            ends = self._platform_frames(frames)
            self.platforms.batched_wxyzs = wxyzs(ends)
            self.platforms.batched_positions = ends[:, :3, 3]
        tip = frames[-1]
        self.tip.position = tip[:3, 3]
