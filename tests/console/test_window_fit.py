"""Each browser's camera framed for its window (console.scene.window_fit,
camera.presets_for_window): in a tablet's tall 3D view and a phone's (the part above the sheet,
console.web.phone_sheet) the arm's reach is all in view; a camera the person moved is left
alone."""

from __future__ import annotations

import contextlib
import math
from typing import Any, Iterator

import numpy as np
import pytest

from console.core.table_area import arm_span, table_extent
from console.scene import camera
from console.scene.window_fit import WindowFit
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")


def ndc(pose: camera.CameraPose, point: Any, aspect: float) -> tuple[float, float]:
    """Normalised device coordinates (x right, y up, [-1, 1] in view) of a world point."""
    eye, f = np.array(pose.position), pose.forward
    r = np.cross(f, pose.up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = np.asarray(point, float) - eye
    t = math.tan(pose.fov / 2)
    return (d @ r) / ((d @ f) * t * aspect), (d @ u) / ((d @ f) * t)


def arm_points(robot: Any) -> list[tuple[float, float, float]]:
    """Points that must be in view: the soft arm's reach on the table (the half-disc in front
    of its base) and its mount behind the base, the extensible arm's base, start pose's top and
    fully extended top."""
    span = arm_span(robot, robot.kind)
    if robot.kind == "planar":
        a = np.linspace(0.0, math.pi, 19)
        return [(span * math.cos(t), span * math.sin(t), 0.0) for t in a] + [(0.0, -0.05, 0.0)]
    return [(0.0, 0.0, 0.0), (0.0, 0.0, 0.5 * span), (0.0, 0.0, 0.9 * span),
            (0.1, 0.1, 0.3 * span), (-0.1, -0.1, 0.3 * span)]


@pytest.mark.parametrize("robot", [SOFT, EXT], ids=["soft-arm", "extensible"])
@pytest.mark.parametrize("size", [(496, 1180), (390, 422), (1276, 1000), (360, 370),
                                  (1900, 600)])
def test_every_preset_shows_the_arm_in_the_canvas(robot, size):
    width, height = size
    aspect = width / height
    span, table = arm_span(robot, robot.kind), table_extent(robot, robot.kind)
    for pose in camera.presets_for_window(robot.kind, span, table, width, height):
        assert pose.position[2] > 0, pose
        x0, x1, y0, y1 = table
        assert x0 <= pose.look_at[0] <= x1 and y0 <= pose.look_at[1] <= y1, pose
        for p in arm_points(robot) + [(0.0, 0.0, 0.0)]:
            x, y = ndc(pose, p, aspect)
            assert -1 <= x <= 1 and -1 <= y <= 1, (pose.name, p, x, y)


def test_a_tall_window_shows_the_soft_arms_reach_larger_than_fitted_for_a_wide_one():
    """The tablet's view is framed for its canvas: its reach spans at least 80 % of the
    canvas's width (the wide window's pose in that canvas cut the reach off at both sides)."""
    span, table = arm_span(SOFT, "planar"), table_extent(SOFT, "planar")
    aspect = 496 / 1180
    pose = camera.presets_for_window("planar", span, table, 500, 1180)[0]
    xs = [ndc(pose, p, aspect)[0] for p in arm_points(SOFT)]
    assert max(xs) - min(xs) >= 1.6
    wide = camera.presets("planar", span, table)[0]
    xs = [ndc(wide, p, aspect)[0] for p in arm_points(SOFT)]
    assert min(xs) < -1 or max(xs) > 1                              # what the old view did


# -- WindowFit with a browser's camera reports -----------------------------------------------

class _Camera:
    def __init__(self, pose: camera.CameraPose, size: tuple[int, int]) -> None:
        self.image_width, self.image_height = size
        self.position = np.array(pose.position)
        self.look_at = np.array(pose.look_at)
        self.fov = pose.fov
        self.up_direction = np.array(pose.up)
        self.callbacks: list[Any] = []

    def on_update(self, fn: Any) -> None:
        self.callbacks.append(fn)

    def report(self, size: tuple[int, int] | None = None) -> None:
        if size is not None:
            self.image_width, self.image_height = size
        for fn in self.callbacks:
            fn(self)


class _Client:
    def __init__(self, cid: int, pose: camera.CameraPose, size: tuple[int, int]) -> None:
        self.client_id = cid
        self.camera = _Camera(pose, size)
        self.moves = 0

    @contextlib.contextmanager
    def atomic(self) -> Iterator[None]:
        self.moves += 1
        yield


class _Server:
    def __init__(self) -> None:
        self.connect: list[Any] = []
        self.disconnect: list[Any] = []

    def on_client_connect(self, fn: Any) -> None:
        self.connect.append(fn)

    def on_client_disconnect(self, fn: Any) -> None:
        self.disconnect.append(fn)

    def get_clients(self) -> dict[int, Any]:
        return {}

    def join(self, client: _Client) -> None:
        for fn in self.connect:
            fn(client)


@pytest.fixture
def fit() -> tuple[_Server, WindowFit, camera.CameraPose, Any]:
    span, table = arm_span(SOFT, "planar"), table_extent(SOFT, "planar")
    initial = camera.presets("planar", span, table)[0]

    def first(w: int, h: int) -> camera.CameraPose:
        return camera.presets_for_window("planar", span, table, w, h)[0]
    server = _Server()
    return server, WindowFit(server, initial, first), initial, first


def test_a_tablet_browser_is_framed_for_its_canvas_once(fit):
    server, _, initial, first = fit
    tablet = _Client(1, initial, (496, 1180))
    server.join(tablet)
    tablet.camera.report()
    assert tablet.moves == 1
    np.testing.assert_allclose(tablet.camera.position, first(496, 1180).position)
    np.testing.assert_allclose(tablet.camera.look_at, first(496, 1180).look_at)
    tablet.camera.report()                                       # the same canvas again
    assert tablet.moves == 1
    tablet.camera.report((390, 422))                             # turned into a phone's
    assert tablet.moves == 2
    np.testing.assert_allclose(tablet.camera.position, first(390, 422).position)


def test_a_desktop_browser_keeps_the_initial_camera_and_a_moved_camera_stays(fit):
    server, window_fit, initial, _ = fit
    desk = _Client(1, initial, (1280, 1000))
    server.join(desk)
    desk.camera.report()
    assert desk.moves == 0                                      # already framed for it
    assert window_fit.framed_size(1) == (1280, 1000)
    desk.camera.position = desk.camera.position + 0.05         # the person orbits
    desk.camera.report((496, 1180))
    assert desk.moves == 0                                      # their camera stays theirs
    unknown = _Client(2, initial, (0, 0))                        # no size reported yet
    server.join(unknown)
    unknown.camera.report()
    assert unknown.moves == 0 and window_fit.framed_size(2) is None
