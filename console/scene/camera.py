"""Camera presets as data, so the first view and every "View" button frame the arm the same way.

A :class:`CameraPose` is where a camera stands, what it looks at and its field of view.
:func:`presets` gives each robot kind's named poses (soft arm: *Perspective* and *Top-down*;
extensible arm: *Perspective*, *Front* and *Side*); the first one is the console's initial
camera (``console.scene.stage.setup_camera``) and *Reset view* goes back to it. Poses are computed from
the robot's reach (``span``, m) and the table rectangle, for a canvas of a given aspect ratio.
The control panel is docked beside the canvas (``console.scene.stage.setup_theme``), so the
whole canvas is free (:data:`PANEL_FRACTION` 0; a panel floating over the canvas's right
would need the look-at point shifted right by that share).

Pure numpy: no viser here; :func:`apply` sets a browser's camera from a pose.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

Vec3 = tuple[float, float, float]
Kind = Literal["planar", "delta"]
FOV = math.radians(50.0)          # vertical field of view of every preset
DEFAULT_ASPECT = 1.28             # the 3D view of a 1600 x 1000 window beside the docked panel
PANEL_FRACTION = 0.0              # share of the canvas under the control panel: none, docked
MARGIN = 1.08                     # framed region plus this much room around it


@dataclasses.dataclass(frozen=True)
class CameraPose:
    """One camera: eye position, look-at point, up vector (world +z) and vertical fov (rad)."""

    name: str
    position: Vec3
    look_at: Vec3
    up: Vec3 = (0.0, 0.0, 1.0)
    fov: float = FOV

    @property
    def forward(self) -> npt.NDArray[np.float64]:
        """Unit vector from the eye to the look-at point."""
        d = np.subtract(self.look_at, self.position)
        return d / np.linalg.norm(d)


def _vec(v: npt.ArrayLike) -> Vec3:
    a = np.asarray(v, dtype=float)
    return (float(a[0]), float(a[1]), float(a[2]))


def free_fraction(aspect: float) -> float:
    """Share of the canvas width the docked control panel leaves free (all of a tall canvas's
    is not free either: viser's panel keeps its width, so a narrow window loses more)."""
    return max(0.55, 1.0 - PANEL_FRACTION * DEFAULT_ASPECT / max(aspect, 0.5))


def frame_sphere(name: str, centre: npt.ArrayLike, radius: float, direction: npt.ArrayLike,
                 aspect: float = DEFAULT_ASPECT, fov: float = FOV) -> CameraPose:
    """A pose looking along ``-direction`` (from the eye towards ``centre``) at which a sphere of
    ``radius`` around ``centre`` fits in the canvas left of the control panel."""
    c = np.asarray(centre, dtype=float)
    back = np.asarray(direction, dtype=float)
    back = back / np.linalg.norm(back)                                 # centre -> eye
    free = free_fraction(aspect)
    tan_v = math.tan(fov / 2)
    tan_h = tan_v * aspect * free                                      # half-width left free
    dist = MARGIN * radius / math.sin(math.atan(min(tan_v, tan_h)))
    forward = -back
    right = np.cross(forward, (0.0, 0.0, 1.0))
    if np.linalg.norm(right) < 1e-9:                                  # looking straight down
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    # The free part's centre is (1 - free) of a half-width left of the canvas centre: look that
    # far right of the sphere's centre so the sphere appears there.
    shift = (1.0 - free) * dist * tan_v * aspect
    look = c + right * shift
    return CameraPose(name, _vec(look + back * dist), _vec(look), fov=fov)


def frame_points(name: str, points: npt.ArrayLike, direction: npt.ArrayLike,
                 aspect: float = DEFAULT_ASPECT, fov: float = FOV,
                 table: tuple[float, float, float, float] | None = None) -> CameraPose:
    """The nearest pose looking along ``-direction`` that shows every point of ``points`` in
    the canvas left of the control panel (a bisection on the distance). With ``table``, the
    look-at point (the orbit centre) is kept on the table, the view moved along with it."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    c = (pts.min(0) + pts.max(0)) / 2
    back = np.asarray(direction, dtype=float)
    back = back / np.linalg.norm(back)
    forward = -back
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    free = free_fraction(aspect)
    tan_v = math.tan(fov / 2)
    x_max = 1.0 - 2.0 * (1.0 - free)

    def pose_at(dist: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        look = c + right * (1.0 - free) * dist * tan_v * aspect
        return look + back * dist, look

    def fits(dist: float) -> bool:
        eye, _ = pose_at(dist)
        d = pts - eye
        depth = d @ forward
        if np.any(depth <= 1e-6):
            return False
        x = (d @ right) / (depth * tan_v * aspect)
        y = (d @ up) / (depth * tan_v)
        return bool(np.all(np.abs(y) <= 1 / MARGIN) and np.all(x >= -1 / MARGIN)
                    and np.all(x <= x_max - (1 - 1 / MARGIN)))

    size = float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0
    lo, hi = 0.0, size
    while not fits(hi):
        hi *= 2
        if hi > 1e3 * size:
            break
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if fits(mid) else (mid, hi)
    eye, look = pose_at(hi)
    if table is not None:
        x0, x1, y0, y1 = table
        moved = np.array([min(max(look[0], x0), x1), min(max(look[1], y0), y1), look[2]])
        eye, look = eye + (moved - look), moved
    return CameraPose(name, _vec(eye), _vec(look), fov=fov)


def frame_top_down(name: str, x: tuple[float, float], y: tuple[float, float],
                   aspect: float = DEFAULT_ASPECT, fov: float = FOV) -> CameraPose:
    """Straight down on the table rectangle ``x`` by ``y`` (+y up on screen), fitted into the
    canvas left of the control panel."""
    w, h = x[1] - x[0], y[1] - y[0]
    free = free_fraction(aspect)
    tan_v = math.tan(fov / 2)
    height = MARGIN * max(h / 2 / tan_v, w / 2 / (tan_v * aspect * free))
    shift = (1.0 - free) * height * tan_v * aspect
    look = np.array([(x[0] + x[1]) / 2 + shift, (y[0] + y[1]) / 2, 0.0])
    # A hair south of the vertical: the view direction and +z up then define the screen's up
    # as +y (exactly vertical, viser and the orbit controls pick one of their own).
    eye = look + np.array([0.0, -1e-3 * height, height])
    return CameraPose(name, _vec(eye), _vec(look), fov=fov)


def presets(kind: Kind | str, span: float, table: tuple[float, float, float, float],
            aspect: float = DEFAULT_ASPECT) -> tuple[CameraPose, ...]:
    """The named poses for a robot kind; the first is the initial camera ("Reset view").

    Args:
        kind: ``"planar"`` (soft arm, lies on the table) or ``"delta"`` (extensible, stands up).
        span: Largest distance of any arm point from its base (m).
        table: Table rectangle ``(x0, x1, y0, y1)`` (m).
        aspect: The canvas's width / height.
    """
    if span <= 0 or not math.isfinite(span):
        raise ValueError(f"span must be a positive length, got {span}")
    x0, x1, y0, y1 = table
    if kind == "planar":
        # The initial view is the console's long-standing one (the browser tests project clicks
        # with it): the reachable half-disc from the front right, look-at right of its centre.
        perspective = CameraPose("Perspective", (0.55 * span, -1.25 * span, 1.75 * span),
                                 (0.3 * span, 0.32 * span, 0.0))
        if abs(aspect - DEFAULT_ASPECT) > 0.05:
            # Another window shape: the same direction, fitted to the reach (the initial
            # camera cannot know the window; "Reset view" still goes back to it).
            reach = [(sx * span, sy * span, 0.0) for sx in (-1, 1) for sy in (-0.25, 1)]
            perspective = frame_points("Perspective", reach, np.subtract(
                perspective.position, perspective.look_at), aspect, table=table)
        # Top-down: the arm's reach, x in [-span, span], y from just behind the base to span.
        top = frame_top_down("Top-down", (-span, span), (-0.25 * span, span), aspect)
        return (perspective, top)
    # The extensible arm stands at the origin and reaches up to ``span``; it starts straight at
    # mid-range racks (about half of that tall) and bends from there. Frame that working volume
    # (full extension just fits), so the arm fills a good part of the view, not the whole table.
    centre = (0.0, 0.0, 0.45 * span)
    radius = 0.52 * span
    return (frame_sphere("Perspective", centre, radius, (0.75, -1.0, 0.55), aspect),
            frame_sphere("Front", centre, radius, (0.0, -1.0, 0.12), aspect),
            frame_sphere("Side", centre, radius, (1.0, 0.0, 0.12), aspect),
            frame_top_down("Top-down", (max(x0, -0.55 * span), min(x1, 0.55 * span)),
                           (max(y0, -0.55 * span), min(y1, 0.55 * span)), aspect))


def preset(kind: Kind | str, name: str, span: float, table: tuple[float, float, float, float],
           aspect: float = DEFAULT_ASPECT) -> CameraPose:
    """The pose called ``name`` (ValueError naming the choices if there is none)."""
    poses = presets(kind, span, table, aspect)
    for pose in poses:
        if pose.name == name:
            return pose
    raise ValueError(f"no camera preset {name!r}; presets: {', '.join(p.name for p in poses)}")


def apply(camera: Any, pose: CameraPose) -> None:
    """Point a viser camera (a browser's ``client.camera``, or ``server.initial_camera``) at
    ``pose``. The position goes first: viser moves the look-at point along with it."""
    camera.fov = pose.fov
    camera.position = pose.position
    camera.look_at = pose.look_at
    if hasattr(camera, "up_direction"):  # a browser's camera
        camera.up_direction = pose.up
    else:                                # the initial camera
        camera.up = pose.up
