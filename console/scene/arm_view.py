"""3D drawing of the selected arm, built once and then moved by a few numbers per frame.

:class:`ArmView` subclasses create their viser scene nodes in ``__init__``; :meth:`ArmView.update`
only assigns to them, so no node is ever re-created while the arm moves. Two ways to draw:

* ``method="skinned"`` (default): every tube is a skinned mesh sent once (``console.scene.skin``); a
  frame sends its bone poses (27 for the soft arm's body). Rigid parts (segment rings,
  platforms) are batched meshes moved by one array of instance poses; the gripper (the paper's
  pleated finger, ``console.scene.gripper_mesh``: open and closed, sent once) and the tip frame are
  nodes moved by a pose. About 1-3 KB per frame instead of ~25-60 KB.
* ``method="vertices"``: the tubes' whole vertex arrays every frame (the original drawing, kept
  for the viewer benchmark and as the reference the skinned tubes are tested against).

A dead band (:class:`DeadBand`: 1 mm, 1 deg, on the drawn frames averaged over up to 4 s
while they jitter; 0.1 mm, 0.1 deg while they move steadily) skips a frame when nothing drawn
moved more than it since the last one sent, so a still arm with measurement noise costs (almost)
nothing and a slow move is still drawn every frame; a held-back frame is sent when the display
goes idle. The geometry itself comes from pure ``geometry(q)`` / ``frames(q)`` methods
(vectorised numpy, no viser), which tests check against the kinematics without a server.

The arms' own drawings: :mod:`console.scene.soft_arm_view` (soft arm) and
:mod:`console.scene.extensible_arm_view` (extensible arm); this module holds what they share.
:func:`console.scene.arm_view_factory.make_arm_view` picks one by the model's kind. ``ArmView``
is generic in its model (``ArmView[SoftArmModel]``, ``ArmView[ExtensibleModel]``), so a view's
``model`` has its arm's type and a caller holding any ``ArmView`` needs no test of the kind.
"""

from __future__ import annotations

import collections
import time
from abc import ABC, abstractmethod
from typing import Any, Generic, Literal, TypeVar

import numpy as np
import numpy.typing as npt
import viser
import viser.transforms as vtf

from console.scene.dead_band import DeadBand, Steadiness
from console.core.model import ArmModel
from console.scene.skin import TubeSkin
from console.scene.tube import TubeTopology
from console.web.shared_sends import set_bone_poses

Array = npt.NDArray[np.float64]
Geometry = dict[str, Any]
Method = Literal["skinned", "vertices"]
METHODS: tuple[Method, ...] = ("skinned", "vertices")
Rgb = tuple[int, int, int]
# The arm's model; covariant: a SoftArmView is an ArmView[ArmModel] too (the model is only read).
ModelT = TypeVar("ModelT", bound=ArmModel, covariant=True)

BODY_COLOR = (96, 178, 204)
RING_COLOR = (45, 62, 80)
MOUNT_COLOR = (120, 128, 140)
GRIPPER_COLOR = (236, 138, 44)
PALM_COLOR = (200, 40, 60)
RACK_COLORS = ((214, 82, 68), (74, 160, 88), (66, 110, 206))
PLATFORM_COLOR = (150, 160, 176)
BACKBONE_COLOR = (150, 160, 172)


def merge_meshes(parts: list[tuple[Array, npt.NDArray[Any]]]) -> tuple[Array, Array]:
    """(vertices, faces) pairs as one mesh: stacked vertices, faces re-indexed, uint32."""
    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.vstack(verts), np.vstack(faces).astype(np.uint32)


def batched_color(rgb: Rgb) -> Rgb:
    """``rgb`` (sRGB, as every other colour here) for viser 1.1.1's batched meshes, whose client
    reads ``batched_colors`` as linear RGB (``new THREE.Color(r, g, b)``): without this the
    segment rings and platforms are drawn much lighter than the same colour on a mesh."""
    c = np.asarray(rgb, dtype=float) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    r, g, b = (int(v) for v in np.round(linear * 255.0))
    return r, g, b


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
    comparison for all of them, ``shared_sends.set_bone_poses``)."""
    set_bone_poses(handle, quantize(wxyzs(poses)), quantize(poses[:, :3, 3]))


class ArmView(ABC, Generic[ModelT]):
    """Scene nodes of one arm under ``root``; call :meth:`update` from one thread only.

    Args:
        scene: Where to draw.
        model: The arm.
        root: Scene path of the arm's nodes.
        method: ``"skinned"`` (poses per frame) or ``"vertices"`` (vertex arrays per frame).
        dead_band: Skip frames that moved less than this; None draws every frame.
    """

    def __init__(self, scene: viser.SceneApi, model: ModelT, root: str = "/arm",
                 method: Method = "skinned", dead_band: DeadBand | None = DeadBand()) -> None:
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self.scene = scene
        self.model: ModelT = model
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
        self._steadiness: Steadiness | None = None  # measured over the band's steadiness_s
        self._steady_run = 0  # updates in a row at the band's moving steadiness or more
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
    def ghost_mesh(self, q: Array) -> tuple[Array, Array]:
        """The arm at ``q`` as one static mesh (vertices, uint32 faces): a translucent "ghost"
        along a planned path (pure)."""

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
        jumped = self._mean is not None and band.jumped(self._mean, frames)
        if jumped:
            self._mean = None  # a jump, not noise or a move: average from here (DeadBand.jump)
        if jumped or self._steadiness is None or self._steadiness.tau != band.steadiness_s:
            self._steadiness, self._steady_run = Steadiness(band.steadiness_s), 0
        steady = self._steadiness.update(frames, dt)
        self._mean = band.average(self._mean, frames, dt, steady)
        self._mean_at = now
        settled = self._last_q is not None and np.array_equal(q, self._last_q)
        self._last_q = q
        self._steady_run = self._steady_run + 1 if steady >= band.moving_steadiness else 0
        known = (self._steadiness.steps >= band.moving_steps
                 and self._steady_run >= band.moving_frames)
        moving = steady if known else 0.0
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

