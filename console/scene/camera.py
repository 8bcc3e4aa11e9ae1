"""Camera presets as data, so the first view and every "View" button frame the arm the same way.

A :class:`CameraPose` is where a camera stands, what it looks at and its field of view.
:func:`presets` gives each robot kind's named poses (soft arm: *Perspective* and *Top-down*;
extensible arm: *Perspective*, *Front*, *Side* and *Top-down*); the first one is the console's
initial camera (``console.scene.stage.setup_camera``) and *Reset view* goes back to it. Poses are
computed from the robot's reach (``span``, m) and the table rectangle, for a canvas of a given
aspect ratio; the control panel never covers the canvas (docked beside it, ``static/theme.toml``;
on a phone the canvas is the part above viser's bottom sheet, ``console.web.phone_sheet``).
:func:`presets_for_window` takes a browser's canvas size in pixels, and
``console.scene.window_fit`` re-frames each browser's camera for its own window. Both take
``extra`` points (m) the soft arm's views must show besides its reach: the objects, the bin and
the plans' approach circles and waypoints (``console.scene.plan_frame``); a plan that reaches
past the arm's reach (a far object's outer circles) widens the view to show it all. For the
extensible arm the ``extra`` points are the arm's own: its views frame the working volume of
an arm as tall as it is plus :data:`HEADROOM` (:func:`working_volume`), and the console
re-frames them when the arm grows out of that (``ConsoleApp.follow_arm``).

Pure numpy: no viser here; :func:`apply` sets a browser's camera from a pose.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal, Sequence

import numpy as np
import numpy.typing as npt

Vec3 = tuple[float, float, float]
Kind = Literal["planar", "delta"]
FOV = math.radians(50.0)          # vertical field of view of every preset
DEFAULT_ASPECT = 1.28             # the 3D view of a 1600 x 1000 window beside the docked panel
MARGIN = 1.08                     # framed region plus this much room around it
NARROWEST = 0.45                  # the extensible arm's framed volume: narrowest width, of a ball
HEADROOM = 0.15                   # the extensible arm's framed volume: room above the arm, of span


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


def _axes(direction: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], ...]:
    """Unit (back, forward, right, up) of a camera looking along ``-direction``, +z up."""
    back = np.asarray(direction, dtype=float)
    back = back / np.linalg.norm(back)                                 # centre -> eye
    forward = -back
    right = np.cross(forward, (0.0, 0.0, 1.0))
    if np.linalg.norm(right) < 1e-9:                                  # looking straight down
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    return back, forward, right, np.cross(right, forward)


def _fit(points: npt.ArrayLike, direction: npt.ArrayLike, aspect: float,
         fov: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The nearest camera looking along ``-direction`` that shows every point in the canvas
    (shrunk by :data:`MARGIN` about its centre): (eye, orbit centre). The orbit centre is the
    point of the view axis nearest the points' centre.

    At a distance ``D`` behind the points' centre ``c`` and moved ``(sx, sy)`` sideways, a point
    with offsets ``(u, v, w)`` along (right, up, forward) from ``c`` is at screen x
    ``(u - sx) / ((w + D) tan_h)``: each point bounds ``sx`` (and ``sy``) to an interval, and the
    points fit when those intervals meet; the smallest such ``D`` is found by bisection and the
    camera moved to the middle of the intervals there.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    c = (pts.min(0) + pts.max(0)) / 2
    back, forward, right, up = _axes(direction)
    rel = pts - c
    u, v, w = rel @ right, rel @ up, rel @ forward
    tan_v = math.tan(fov / 2)
    tan_h = tan_v * aspect
    edge = 1.0 / MARGIN                                               # of the half-width

    def shifts(dist: float) -> tuple[float, float] | None:
        depth = w + dist
        if np.any(depth <= 1e-6):
            return None
        kx, ky = depth * tan_h * edge, depth * tan_v * edge
        sx_lo, sx_hi = np.max(u - kx), np.min(u + kx)
        sy_lo, sy_hi = np.max(v - ky), np.min(v + ky)
        if sx_lo > sx_hi or sy_lo > sy_hi:
            return None
        return (float(sx_lo + sx_hi) / 2, float(sy_lo + sy_hi) / 2)

    size = float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0
    lo, hi = 0.0, size
    while shifts(hi) is None:
        lo, hi = hi, hi * 2
        if hi > 1e4 * size:
            raise ValueError("cannot frame these points")
    for _ in range(50):
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if shifts(mid) is not None else (mid, hi)
    sx, sy = shifts(hi) or (0.0, 0.0)
    look = c + right * sx + up * sy
    return look + back * hi, look


def in_view(pose: CameraPose, points: npt.ArrayLike, aspect: float) -> bool:
    """Whether every point is in front of ``pose`` and inside its canvas of ``aspect`` (width /
    height) shrunk by :data:`MARGIN` about its centre (where :func:`frame_points` puts them)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) == 0:
        return True
    eye = np.asarray(pose.position, float)
    forward = pose.forward
    right = np.cross(forward, np.asarray(pose.up, float))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = pts - eye
    depth = rel @ forward
    if np.any(depth <= 1e-6):
        return False
    tan_v = math.tan(pose.fov / 2)
    x = (rel @ right) / (depth * tan_v * aspect)
    y = (rel @ up) / (depth * tan_v)
    edge = 1.0 / MARGIN + 1e-6
    return bool(np.all(np.abs(x) <= edge) and np.all(np.abs(y) <= edge))


def _points(extra: npt.ArrayLike | None) -> npt.NDArray[np.float64]:
    """``extra`` as an (n, 3) array (none: (0, 3))."""
    if extra is None:
        return np.zeros((0, 3))
    return np.asarray(extra, dtype=float).reshape(-1, 3)


def frame_points(name: str, points: npt.ArrayLike, direction: npt.ArrayLike,
                 aspect: float = DEFAULT_ASPECT, fov: float = FOV) -> CameraPose:
    """The nearest pose looking along ``-direction`` that shows every point of ``points`` in
    the canvas. Its look-at point (the orbit centre) is on the view axis, nearest the points."""
    eye, look = _fit(points, direction, aspect, fov)
    return CameraPose(name, _vec(eye), _vec(look), fov=fov)


def _sphere(centre: npt.ArrayLike, radius: float, n: int = 96) -> npt.NDArray[np.float64]:
    """``n`` points spread evenly over a sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z * z)
    return np.asarray(centre, float) + radius * np.stack(
        [r * np.cos(phi), r * np.sin(phi), z], -1)


def frame_top_down(name: str, x: tuple[float, float], y: tuple[float, float],
                   aspect: float = DEFAULT_ASPECT, fov: float = FOV) -> CameraPose:
    """Straight down on the table rectangle ``x`` by ``y`` (+y up on screen), fitted into the
    canvas."""
    corners = [(xi, yi, 0.0) for xi in x for yi in y]
    # A hair south of the vertical: the view direction and +z up then define the screen's up
    # as +y (exactly vertical, viser and the orbit controls pick one of their own).
    return frame_points(name, corners, (0.0, -1e-3, 1.0), aspect, fov)


def presets(kind: Kind | str, span: float, table: tuple[float, float, float, float],
            aspect: float = DEFAULT_ASPECT,
            extra: npt.ArrayLike | None = None) -> tuple[CameraPose, ...]:
    """The named poses for a robot kind; the first is the initial camera ("Reset view").

    Args:
        kind: ``"planar"`` (soft arm, lies on the table) or ``"delta"`` (extensible, stands up).
        span: Largest distance of any arm point from its base (m).
        table: Table rectangle ``(x0, x1, y0, y1)`` (m).
        aspect: The canvas's width / height.
        extra: World points (m) the soft arm's poses show besides its reach (what the operator
            plans: objects, bin, approach circles, waypoints); a pose that would leave one out
            is widened, in the same direction, to show them all. For the extensible arm:
            the arm's own points (as drawn now), which size its working volume
            (:func:`working_volume`); none: the volume of the fully extended arm.
    """
    if span <= 0 or not math.isfinite(span):
        raise ValueError(f"span must be a positive length, got {span}")
    if not aspect > 0 or not math.isfinite(aspect):
        raise ValueError(f"aspect must be a positive ratio, got {aspect}")
    x0, x1, y0, y1 = table
    if kind == "planar":
        more = _points(extra)
        # The initial view is the console's long-standing one (the browser tests project clicks
        # with it): the reachable half-disc from the front right, look-at right of its centre.
        perspective = CameraPose("Perspective", (0.55 * span, -1.25 * span, 1.75 * span),
                                 (0.3 * span, 0.32 * span, 0.0))
        direction = np.subtract(perspective.position, perspective.look_at)
        reach = np.array([(sx * span, sy * span, 0.0) for sx in (-1, 1) for sy in (-0.25, 1)])
        if abs(aspect - DEFAULT_ASPECT) > 0.05:
            # Another window shape: the same direction, fitted to the reach (the initial
            # camera cannot know the window; console.scene.window_fit re-frames each
            # browser's camera with its own).
            perspective = frame_points("Perspective", reach, direction, aspect)
        if not in_view(perspective, more, aspect):
            # A plan reaching past this view (a far object's outer approach circles): the
            # same direction, fitted to the reach and everything planned.
            perspective = frame_points("Perspective", np.vstack([reach, more]), direction,
                                       aspect)
        # Top-down: the arm's reach, x in [-span, span], y from just behind the base to span,
        # widened to what is planned.
        box = np.vstack([reach[:, :2], more[:, :2]])
        top = frame_top_down("Top-down", (float(box[:, 0].min()), float(box[:, 0].max())),
                             (float(box[:, 1].min()), float(box[:, 1].max())), aspect)
        return (perspective, top)
    # The extensible arm stands at the origin and reaches up to ``span``; it starts straight at
    # mid-range racks (about half of that tall) and bends from there. Frame the working volume
    # of an arm as tall as this one plus some headroom (the console re-frames the view when the
    # arm grows out of it: ConsoleApp.follow_arm), so the arm fills a good part of the view.
    volume = working_volume(span, aspect, _points(extra))
    return (frame_points("Perspective", volume, (0.75, -1.0, 0.55), aspect),
            frame_points("Front", volume, (0.0, -1.0, 0.12), aspect),
            frame_points("Side", volume, (1.0, 0.0, 0.12), aspect),
            frame_top_down("Top-down", (max(x0, -0.55 * span), min(x1, 0.55 * span)),
                           (max(y0, -0.55 * span), min(y1, 0.55 * span)), aspect))


def volume_top(span: float, arm: npt.ArrayLike | None = None) -> float:
    """The height (m) up to which the extensible arm's views frame its working volume: the
    arm's highest point plus :data:`HEADROOM` of ``span``, at most ``span`` (the fully extended
    top); ``span`` without ``arm`` points."""
    pts = _points(arm)
    if len(pts) == 0:
        return span
    return float(min(span, max(0.0, float(pts[:, 2].max())) + HEADROOM * span))


def working_volume(span: float, aspect: float = DEFAULT_ASPECT,
                   arm: npt.ArrayLike | None = None) -> npt.NDArray[np.float64]:
    """Points bounding what the extensible arm's views frame, for a canvas of ``aspect``.

    An ellipsoid about the arm's axis, from just below the table to ``span`` high (the fully
    extended top on it). In a wide canvas it is a ball of radius 0.52 ``span`` (the tip bent
    sideways at half extension); a tall canvas (a tablet's, a phone's) is limited by its width,
    and that ball framed by the width left the arm a third of the canvas high, so there the
    ellipsoid narrows with the canvas (down to :data:`NARROWEST` of the ball's width) and the
    arm's height fills the canvas instead. Given the ``arm``'s points (m, as drawn now), the
    volume is that of an arm :func:`volume_top` tall (scaled about the base: the arm at
    mid-range racks, about half of ``span`` tall, framed with room for the full extension was
    two fifths of a tall canvas high), and the arm's points are in it.
    """
    squeeze = min(1.0, max(NARROWEST, aspect / DEFAULT_ASPECT))
    ball = _sphere((0.0, 0.0, 0.45 * span), 0.52 * span)
    ball[:, :2] *= squeeze
    volume = np.vstack([ball, [(0.0, 0.0, span)]]) * (volume_top(span, arm) / span)
    return np.vstack([volume, _points(arm)])


def presets_for_window(kind: Kind | str, span: float, table: tuple[float, float, float, float],
                       width_px: float, height_px: float,
                       extra: npt.ArrayLike | None = None) -> tuple[CameraPose, ...]:
    """:func:`presets` for a browser canvas of ``width_px`` x ``height_px`` (0 x 0: not known
    yet, the wide window's presets), showing ``extra`` too (see :func:`presets`). The control
    panel never covers the canvas (docked beside it; on phones the canvas is above the sheet:
    ``console.web.phone_sheet``), so the canvas's aspect is all a pose needs."""
    if width_px > 0 and height_px > 0 and math.isfinite(width_px / height_px):
        return presets(kind, span, table, width_px / height_px, extra)
    return presets(kind, span, table, extra=extra)


def preset(kind: Kind | str, name: str, span: float, table: tuple[float, float, float, float],
           aspect: float = DEFAULT_ASPECT) -> CameraPose:
    """The pose called ``name`` (ValueError naming the choices if there is none)."""
    return pick(presets(kind, span, table, aspect), name)


def pick(poses: Sequence[CameraPose], name: str) -> CameraPose:
    """The pose of ``poses`` called ``name`` (ValueError naming the choices if there is none)."""
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
