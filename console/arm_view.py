"""3D drawing of the selected arm, built once and then moved by a few numbers per frame.

:class:`ArmView` subclasses create their viser scene nodes in ``__init__``; :meth:`ArmView.update`
only assigns to them, so no node is ever re-created while the arm moves. Two ways to draw:

* ``method="skinned"`` (default): every tube is a skinned mesh sent once (``console.skin``); a
  frame sends its bone poses (27 for the soft arm's body). Rigid parts (segment rings,
  platforms) are batched meshes moved by one array of instance poses; the gripper (the paper's
  pleated finger, ``console.gripper_mesh``: open and closed, sent once) and the tip frame are
  nodes moved by a pose. About 1-3 KB per frame instead of ~25-60 KB.
* ``method="vertices"``: the tubes' whole vertex arrays every frame (the original drawing, kept
  for the viewer benchmark and as the reference the skinned tubes are tested against).

A dead band (:class:`DeadBand`: 0.5 mm, 0.5 deg, on the drawn frames averaged over up to 2 s
while they jitter; 0.1 mm, 0.1 deg while they move steadily) skips a frame when nothing drawn
moved more than it since the last one sent, so a still arm with measurement noise costs (almost)
nothing and a slow move is still drawn every frame; a held-back frame is sent when the display
goes idle. The geometry itself comes from pure ``geometry(q)`` / ``frames(q)`` methods
(vectorised numpy, no viser), which tests check against the kinematics without a server.

* Soft planar arm: the backbone as a tube lying on the table (z = half-width), dark rings at the
  segment boundaries, the pleated gripper in a contrasting colour (a plain rod in the
  ``"vertices"`` drawing) and the palm point w_t.
* Extensible arm (base at the origin, local z = world z up): a thin backbone, the three racks of
  every segment as tubes on their constant-curvature offset arcs (one colour per rack, matching
  the readout), platform discs at the base and every segment end, and a tip frame.
"""

from __future__ import annotations

import collections
import time
from abc import ABC, abstractmethod
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import viser
import viser.transforms as vtf

from console.dead_band import DeadBand, Steadiness
from console.gripper_mesh import GripperShape, gripper_vertices, load_asset
from console.model import ArmModel, DeltaModel, PlanarModel
from console.skin import TubeSkin, planar_matrices
from console.tube import TubeTopology, frames_from_matrices, planar_frames
from console.viser_fixes import set_bone_poses
from core.kinematics import delta as dk
from core.kinematics import planar as pk

Array = npt.NDArray[np.float64]
Geometry = dict[str, Any]
Method = Literal["skinned", "vertices"]
METHODS: tuple[Method, ...] = ("skinned", "vertices")

BODY_COLOR = (96, 178, 204)
RING_COLOR = (45, 62, 80)
MOUNT_COLOR = (120, 128, 140)
GRIPPER_COLOR = (236, 138, 44)
PALM_COLOR = (200, 40, 60)
RACK_COLORS = ((214, 82, 68), (74, 160, 88), (66, 110, 206))
PLATFORM_COLOR = (150, 160, 176)
BACKBONE_COLOR = (150, 160, 172)


def batched_color(rgb: tuple[int, int, int]) -> tuple[int, int, int]:
    """``rgb`` (sRGB, as every other colour here) for viser 1.1.1's batched meshes, whose client
    reads ``batched_colors`` as linear RGB (``new THREE.Color(r, g, b)``): without this the
    segment rings and platforms are drawn much lighter than the same colour on a mesh."""
    c = np.asarray(rgb, dtype=float) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return tuple(int(v) for v in np.round(linear * 255.0))  # type: ignore[return-value]


def wxyzs(frames: Array) -> Array:
    """(P, 4) unit quaternions of (P, 4, 4) frames."""
    return np.asarray(vtf.SO3.from_matrix(frames[:, :3, :3]).wxyz, dtype=float)


def add_skinned_tube(scene: viser.SceneApi, name: str, skin: TubeSkin, topology: TubeTopology,
                     radius: float, color: tuple[int, int, int], each: bool = False,
                     segments: int = 0) -> viser.MeshSkinnedHandle:
    """A straight tube bound to ``skin``'s bones (bind pose); move it with :func:`pose_bones`.

    ``each``: every tube of ``topology`` gets bones of its own (``TubeSkin.bind_each``);
    ``segments``: one tube of that many pieces, a bone set each (``TubeSkin.bind_segments``);
    otherwise the tubes are consecutive pieces of one skin.
    """
    if segments:
        vertices, weights, bind = skin.bind_segments(topology, segments, radius)
    elif each:
        vertices, weights, bind = skin.bind_each(topology, radius)
    else:
        first = topology.n_rings * np.arange(topology.n_tubes) - np.arange(topology.n_tubes)
        vertices, weights = skin.bind(topology, first, radius)
        bind = skin.bind_poses()
    return scene.add_mesh_skinned(name, vertices, topology.faces, bone_wxyzs=wxyzs(bind),
                                  bone_positions=bind[:, :3, 3], skin_weights=weights,
                                  color=color)


def quantize(x: Array, step: float = 2.0**-16) -> Array:
    """``x`` on a binary grid (2^-16 ~ 15 um, 3e-5 rad): viser sends bone poses as msgpack
    float64s, whose then-zero low mantissa bytes its zstd compression squeezes out."""
    return np.round(np.asarray(x) / step) * step


def pose_bones(handle: viser.MeshSkinnedHandle, poses: Array) -> None:
    """Assign (B, 4, 4) bone poses (viser sends only the bones that changed; one vectorised
    comparison for all of them, ``viser_fixes.set_bone_poses``)."""
    set_bone_poses(handle, quantize(wxyzs(poses)), quantize(poses[:, :3, 3]))


class ArmView(ABC):
    """Scene nodes of one arm under ``root``; call :meth:`update` from one thread only.

    Args:
        scene: Where to draw.
        model: The arm.
        root: Scene path of the arm's nodes.
        method: ``"skinned"`` (poses per frame) or ``"vertices"`` (vertex arrays per frame).
        dead_band: Skip frames that moved less than this; None draws every frame.
    """

    def __init__(self, scene: viser.SceneApi, model: ArmModel, root: str = "/arm",
                 method: Method = "skinned", dead_band: DeadBand | None = DeadBand()) -> None:
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self.scene = scene
        self.model = model
        self.root = root
        self.method: Method = method
        self.dead_band = dead_band
        self.frames_sent = 0
        # When the newest frames were sent (time.monotonic()): what a benchmark reads to tell
        # the update rate while the arm moves from the pauses the dead band leaves unsent.
        self.sent_at: collections.deque[float] = collections.deque(maxlen=2048)
        self._sent: Array | None = None  # the (averaged) frames when the last frame was sent
        self._mean: Array | None = None
        self._mean_at = 0.0
        self._steadiness = Steadiness()
        self._held: Array | None = None  # the newest configuration not sent
        self._last_q: Array | None = None  # the configuration of the previous update
        self._sent_q: Array | None = None  # the configuration last drawn

    def set_gripper_closed(self, closed: bool) -> None:
        """Show the gripper open or closed (arms without a gripper ignore it)."""

    @abstractmethod
    def geometry(self, q: Array) -> Geometry:
        """Every vertex array the ``"vertices"`` method assigns, from configuration ``q`` (pure)."""

    @abstractmethod
    def frames(self, q: Array) -> Array:
        """(P, 4, 4) frames of everything drawn at ``q`` (pure): what the dead band compares."""

    @abstractmethod
    def _send(self, q: Array, frames: Array) -> None:
        """Assign the drawing of ``q`` to the handles."""

    def update(self, q: Array) -> bool:
        """Redraw for configuration ``q`` unless the drawn frames stayed within the dead band
        of the last sent frame; returns whether anything was assigned."""
        q = np.asarray(q, dtype=float)
        frames = self.frames(q)
        band = self.dead_band
        if band is None:
            self._draw(q, frames, frames)
            return True
        now = time.monotonic()
        dt = now - self._mean_at
        steady = self._steadiness.update(frames, dt)
        self._mean = band.average(self._mean, frames, dt, steady)
        self._mean_at = now
        settled = self._last_q is not None and np.array_equal(q, self._last_q)
        self._last_q = q
        moving = steady if self._steadiness.steps >= band.moving_steps else 0.0
        if self._sent is not None and not band.moved(self._sent, self._mean, moving):
            if settled and not np.array_equal(q, self._sent_q):
                # The arm stopped exactly here (a source that keeps reporting the same state
                # never lets the display go idle): draw where it ended, once.
                self._mean = frames.copy()
                self._draw(q, frames, frames)
                return True
            self._held = q
            return False
        self._draw(q, frames, self._mean)
        return True

    def flush(self) -> bool:
        """Send the configuration the dead band held back, if any (call when the display is
        idle, so the drawn arm always ends on the newest state); returns whether it sent."""
        q, self._held = self._held, None
        if q is None:
            return False
        frames = self.frames(q)
        self._mean, self._mean_at = frames.copy(), time.monotonic()
        self._draw(q, frames, frames)
        return True

    def _draw(self, q: Array, frames: Array, reference: Array) -> None:
        self._send(q, frames)
        self._sent = reference.copy()
        self._sent_q = q.copy()
        self._held = None
        self.frames_sent += 1
        self.sent_at.append(time.monotonic())


class PlanarArmView(ArmView):
    """Soft planar arm lying on the table plane."""

    samples_per_segment = 16
    sides = 20
    bone_stride = 4  # samples between bones: 4 bones per segment, 27 in all
    ring_half_length = 0.003

    def __init__(self, scene: viser.SceneApi, model: PlanarModel, root: str = "/arm",
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
        shapes = getattr(self, "gripper_shapes", None)
        closed = bool(closed)
        if shapes is None or closed == self.gripper_closed:
            return
        self.gripper_closed = closed
        shapes[closed].visible = True
        shapes[not closed].visible = False

    def _frames_at_ends(self, frames: Array) -> Array:
        return frames[self.samples_per_segment::self.samples_per_segment]

    def frames(self, q: Array) -> Array:
        """(n S + 1, 4, 4) backbone frames at the table height (tangent = local z)."""
        m: PlanarModel = self.model  # type: ignore[assignment]
        r = m.robot
        backbone = pk.sample_backbone(q, r.lengths, self.samples_per_segment, r.base_pose)
        return planar_matrices(backbone, self.z)

    def geometry(self, q: Array) -> Geometry:
        m: PlanarModel = self.model  # type: ignore[assignment]
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

    def _palm(self, tip_frame: Array) -> Array:
        m: PlanarModel = self.model  # type: ignore[assignment]
        heading = np.arctan2(tip_frame[1, 2], tip_frame[0, 2])
        palm_xy = m.palm_point(np.array([tip_frame[0, 3], tip_frame[1, 3], heading]))
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


class DeltaArmView(ArmView):
    """Extensible tri-rack arm standing on the table."""

    samples_per_segment = 32
    sides = 12
    backbone_radius = 0.005
    rack_radius = 0.0035
    platform_thickness = 0.008

    bone_stride = 8  # samples between bones: 4 bones per segment

    def __init__(self, scene: viser.SceneApi, model: DeltaModel, root: str = "/arm",
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
        m: DeltaModel = self.model  # type: ignore[assignment]
        out = frames.copy()
        b = self.beta[j]
        out[:, :3, 3] += m.robot.d * (np.cos(b) * frames[:, :3, 0] + np.sin(b) * frames[:, :3, 1])
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
        self.tip.wxyz = wxyzs(tip[None])[0]


def make_arm_view(scene: viser.SceneApi, model: ArmModel, root: str = "/arm",
                  method: Method = "skinned",
                  dead_band: DeadBand | None = DeadBand()) -> ArmView:
    """The view class matching the model's robot kind."""
    if isinstance(model, PlanarModel):
        return PlanarArmView(scene, model, root, method, dead_band)
    if isinstance(model, DeltaModel):
        return DeltaArmView(scene, model, root, method, dead_band)
    raise TypeError(f"no arm view for {type(model).__name__}")
