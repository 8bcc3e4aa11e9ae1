"""Each browser's camera framed for its window (console.scene.window_fit,
camera.presets_for_window): in a tablet's tall 3D view and a phone's (the part above the sheet,
console.web.phone_sheet) the arm's reach is all in view, and so is what the operator plans (a far
object's approach circles and waypoints, console.scene.plan_frame); the extensible arm fills a
tall canvas; a camera the person moved is left alone."""

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
        self.clients: dict[int, _Client] = {}

    def on_client_connect(self, fn: Any) -> None:
        self.connect.append(fn)

    def on_client_disconnect(self, fn: Any) -> None:
        self.disconnect.append(fn)

    def get_clients(self) -> dict[int, Any]:
        return dict(self.clients)

    def join(self, client: _Client) -> None:
        self.clients[client.client_id] = client
        for fn in self.connect:
            fn(client)


@pytest.fixture
def fit() -> tuple[_Server, WindowFit, camera.CameraPose, Any]:
    span, table = arm_span(SOFT, "planar"), table_extent(SOFT, "planar")
    initial = camera.presets("planar", span, table)[0]

    def first(w: int, h: int) -> camera.CameraPose:
        return camera.presets_for_window("planar", span, table, w, h)[0]
    server = _Server()
    return (server, WindowFit(server, initial, lambda w, h: (first(w, h),)), initial,
            first)


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


def test_a_report_sent_before_the_last_framing_arrived_is_still_the_consoles_camera(fit):
    """Seen resizing a tablet page to a phone's: viser's layout passes through a 70 px wide
    canvas, the console framed the camera for it, and the browser's next report (the phone's
    390 x 422 canvas) still carried the pose before, which was taken for a camera the person
    had moved: the phone stayed framed for 70 px (the arm a quarter of its height)."""
    server, _, initial, first = fit
    tablet = _Client(1, initial, (496, 1180))
    server.join(tablet)
    tablet.camera.report()                                       # framed for the tablet
    at_tablet = np.array(tablet.camera.position)
    tablet.camera.report((70, 844))                              # the transient canvas
    np.testing.assert_allclose(tablet.camera.position, first(70, 844).position)
    tablet.camera.position, tablet.camera.look_at = at_tablet, np.array(
        first(496, 1180).look_at)                                # (that pose not there yet)
    tablet.camera.report((390, 422))                             # the phone's canvas
    assert tablet.moves == 3
    np.testing.assert_allclose(tablet.camera.position, first(390, 422).position)
    tablet.camera.position = np.asarray(tablet.camera.position) + 0.05  # the person orbits
    tablet.camera.report((392, 420))
    assert tablet.moves == 3                                     # and it stays theirs


def test_a_camera_left_at_an_earlier_framing_after_a_quick_resize_is_framed_again(fit):
    """Seen turning a phone page back into a tablet's (fresh clones' layout test): the canvas
    passed through 275 px, then 248 px wide; the console framed the camera for each, but the
    browser's camera stayed at the 275 px pose while the console counted it framed for 248 px,
    and a far object's circle was cut off at the left. A report for the framed canvas at a pose
    put before the newest gets the newest again; one the person moved stays theirs."""
    server, _, initial, first = fit
    tablet = _Client(1, initial, (275, 590))
    server.join(tablet)
    tablet.camera.report()                                       # framed for 275 px
    at_275 = first(275, 590)
    tablet.camera.report((248, 590))                             # framed for 248 px
    assert tablet.moves == 2
    tablet.camera.position, tablet.camera.look_at = (np.array(at_275.position),
                                                     np.array(at_275.look_at))
    tablet.camera.report()                                       # ... but left at 275 px's
    assert tablet.moves == 3
    np.testing.assert_allclose(tablet.camera.position, first(248, 590).position)
    np.testing.assert_allclose(tablet.camera.look_at, first(248, 590).look_at)
    tablet.camera.report()                                       # where it was put: nothing
    assert tablet.moves == 3
    tablet.camera.position = np.asarray(tablet.camera.position) + 0.05  # the person orbits
    tablet.camera.report()
    assert tablet.moves == 3                                     # and it stays theirs


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


# -- what the operator plans: a far object's approach circles and waypoints ------------------

SIZES = {"desktop": (1276, 1000), "tablet": (496, 1180), "phone": (390, 422)}


def _circle(cx: float, cy: float, r: float, z: float, n: int = 72) -> list[tuple[float, ...]]:
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return [(cx + r * math.cos(t), cy + r * math.sin(t), z) for t in a]


@pytest.fixture(scope="module")
def plans() -> dict[str, Any]:
    """The grasp session's snapshots (console.core.grasp_state.SessionView) of a table with
    Object 1 at (-200, 200) mm and Object 2 at (-300, 80) mm (the issue's far object), each
    selected with its plan (the other object kept clear of), and the points a person must see
    for each: both objects and the plan's approach circles and waypoints, drawn here from the
    plan itself (not from console.scene.plan_frame)."""
    from console.core.grasp_state import Outcome, SessionView
    from console.core.table_scene import TableObject
    from core.planning.obstacles import with_other_objects
    from core.planning.sides import SidedPlanner

    r = SOFT.capture.nominal_object_radius
    objects = (TableObject("Object 1", -0.20, 0.20, r), TableObject("Object 2", -0.30, 0.08, r))
    planner = SidedPlanner(SOFT)
    out: dict[str, Any] = {}
    for obj in objects:
        others = [o for o in objects if o is not obj]
        plan = planner.plan(np.zeros(SOFT.n_segments), (obj.x, obj.y), obj.r,
                            obstacles=with_other_objects((), others), clearance=0.01)
        view = SessionView(objects, obj.name, Outcome(obj, plan, None, 1), 0, False, 2.0, True,
                           "off")
        must = [p for o in objects for p in _circle(o.x, o.y, o.r, 0.0)]
        for radius in np.asarray(plan.radii, float):
            must += _circle(float(plan.center[0]), float(plan.center[1]), float(radius), 0.03)
        must += [(float(x), float(y), 0.03) for x, y, _ in np.asarray(plan.palm_poses)]
        out[obj.name] = (view, np.array(must))
    return out


def _outside(pose: camera.CameraPose, points: Any, aspect: float) -> int:
    """How many of ``points`` are off the canvas seen through ``pose``."""
    xy = np.array([ndc(pose, p, aspect) for p in points])
    return int(np.sum(np.any(np.abs(xy) > 1.0, axis=1)))


@pytest.mark.parametrize("size", list(SIZES.values()), ids=list(SIZES))
def test_every_preset_shows_a_far_objects_approach_circles_and_waypoints(plans, size):
    """Issue 31: an object at (-300, 80) mm has approach circles reaching past the arm's reach:
    the views framed only the reach cut them off; framed with what is planned, every preset
    shows the circles, the waypoints, both objects and still the arm's reach."""
    from console.scene.plan_frame import plan_points

    width, height = size
    aspect = width / height
    span, table = arm_span(SOFT, "planar"), table_extent(SOFT, "planar")
    view, must = plans["Object 2"]
    old = camera.presets_for_window("planar", span, table, width, height)[0]
    assert _outside(old, must, aspect) > 0            # what the reach's framing left out
    for pose in camera.presets_for_window("planar", span, table, width, height,
                                          plan_points(view)):
        assert _outside(pose, must, aspect) == 0, pose.name
        assert _outside(pose, arm_points(SOFT), aspect) == 0, pose.name


def test_a_plan_already_in_view_leaves_the_view_as_it_was(plans):
    """Object 1's plan is inside the reach's view: no preset moves for it (a plan does not
    shake the camera), and the desktop still opens with the long-standing camera."""
    from console.scene.plan_frame import plan_points

    span, table = arm_span(SOFT, "planar"), table_extent(SOFT, "planar")
    view, must = plans["Object 1"]
    for width, height in SIZES.values():
        plain = camera.presets_for_window("planar", span, table, width, height)
        framed = camera.presets_for_window("planar", span, table, width, height,
                                           plan_points(view))
        assert _outside(plain[0], must, width / height) == 0
        assert framed[0] == plain[0]
    assert camera.presets_for_window("planar", span, table, 1276, 1000,
                                     plan_points(view))[0] == camera.presets("planar", span,
                                                                             table)[0]


def _planned_fit() -> tuple[_Server, WindowFit, camera.CameraPose, list[Any]]:
    """A soft-arm WindowFit whose presets frame ``planned[0]`` (plan points; None: nothing
    planned): (server, fit, the initial pose, planned)."""
    span, table = arm_span(SOFT, "planar"), table_extent(SOFT, "planar")
    initial = camera.presets("planar", span, table)[0]
    planned: list[Any] = [None]
    server = _Server()
    fit = WindowFit(server, initial, lambda w, h: camera.presets_for_window(
        "planar", span, table, w, h, planned[0]))
    return server, fit, initial, planned


def test_a_new_plan_reframes_the_browsers_the_console_framed_and_not_a_moved_camera(plans):
    from console.scene.plan_frame import plan_points

    server, fit, initial, planned = _planned_fit()
    desk = _Client(1, initial, SIZES["desktop"])
    tablet = _Client(2, initial, SIZES["tablet"])
    moved = _Client(3, initial, SIZES["desktop"])
    for c in (desk, tablet, moved):
        server.join(c)
        c.camera.report()
    assert (desk.moves, tablet.moves, moved.moves) == (0, 1, 0)
    moved.camera.position = moved.camera.position + 0.05            # the person orbits
    theirs = moved.camera.position.copy()
    assert fit.refit() == []                                          # nothing new planned
    far, must = plans["Object 2"]
    planned[0] = plan_points(far)                                     # the far object's plan
    assert sorted(fit.refit()) == [1, 2]
    for c, (w, h) in ((desk, SIZES["desktop"]), (tablet, SIZES["tablet"])):
        pose = fit.framed_pose(c.client_id)
        np.testing.assert_allclose(c.camera.position, pose.position)
        assert _outside(pose, must, w / h) == 0
    np.testing.assert_allclose(moved.camera.position, theirs)        # theirs stays theirs
    assert fit.refit() == []                                          # the same plan again
    planned[0] = plan_points(plans["Object 1"][0])                    # back to a near plan
    assert sorted(fit.refit()) == [1, 2]
    np.testing.assert_allclose(desk.camera.position, initial.position)
    # A preset the person chose (View: Top-down) is the one kept framed.
    fit.put(desk, "Top-down")
    assert np.asarray(desk.camera.look_at)[2] < np.asarray(desk.camera.position)[2]
    planned[0] = plan_points(far)
    assert sorted(fit.refit()) == [1, 2]
    top = fit.framed_pose(1)
    assert top.name == "Top-down" and top.forward[2] < -0.999
    assert _outside(top, must, SIZES["desktop"][0] / SIZES["desktop"][1]) == 0
    fit.put(desk)                                                     # Reset view
    assert fit.framed_pose(1).name == "Perspective"


def test_a_resize_reported_while_a_refit_is_in_flight_is_framed_for_the_new_canvas(plans):
    """fresh85's layout failure: a phone page re-framed for the far plan, then turned into a
    tablet's at once. The browser's first report of the tablet's canvas came while the refit's
    pose was half applied (viser sets the position first and moves the look-at point along;
    the look-at follows), at no pose the console put: taken for the person's camera, the
    tablet's size was recorded with the phone's pose, and when the camera arrived there the
    console counted it framed for the tablet (the far plan's circles cut off at the left). A
    report at no pose the console put changes nothing; the next one at its pose is framed."""
    from console.scene.plan_frame import plan_points

    server, fit, initial, planned = _planned_fit()
    page = _Client(1, initial, SIZES["phone"])
    server.join(page)
    page.camera.report()                                              # framed for the phone
    near = fit.framed_pose(1)
    far, must = plans["Object 2"]
    planned[0] = plan_points(far)
    assert fit.refit() == [1]                                         # the far plan
    phone_far, moves = fit.framed_pose(1), page.moves
    # The browser, turned into a tablet, reports the refit half applied ...
    page.camera.position = np.array(phone_far.position)
    page.camera.look_at = np.array(near.look_at) + np.subtract(phone_far.position,
                                                               near.position)
    page.camera.report(SIZES["tablet"])
    assert page.moves == moves                                        # (the person's, maybe)
    # ... then arrives at the refit's pose: the console's, framed for the tablet.
    page.camera.look_at = np.array(phone_far.look_at)
    page.camera.report()
    assert page.moves == moves + 1 and fit.framed_size(1) == SIZES["tablet"]
    tablet_far = fit.framed_pose(1)
    assert tablet_far != phone_far
    np.testing.assert_allclose(page.camera.position, tablet_far.position)
    assert _outside(tablet_far, must, SIZES["tablet"][0] / SIZES["tablet"][1]) == 0
    assert _outside(phone_far, must, SIZES["tablet"][0] / SIZES["tablet"][1]) > 0  # (was left)


# -- the extensible arm framed as tall as it is ---------------------------------------------

def _extensible_q(extension: float) -> np.ndarray:
    """The extensible arm straight, every segment at ``extension`` of its rack travel (0.5:
    mid-range racks, where the console starts)."""
    q = np.zeros((EXT.n_segments, 3))
    q[:, 2] = EXT.rack_min + extension * (EXT.rack_max - EXT.rack_min) - EXT.L0
    return q


def _spine(q: np.ndarray) -> np.ndarray:
    """The straight arm's axis from its base to its tip (m): an independent reader of its
    height (segment lengths L0 + δL stacked)."""
    top = float(np.sum(EXT.L0 + q[:, 2]))
    return np.array([(0.0, 0.0, z) for z in np.linspace(0.0, top, 11)])


@pytest.mark.parametrize("size", [(496, 1180), (390, 422), (1276, 1000)],
                         ids=["tablet", "phone", "desktop"])
def test_the_extensible_arm_at_rest_fills_most_of_the_canvas_height_with_room_above(size):
    """Issue 31: framed with room for the full extension, the arm at mid-range racks (its
    start) was 0.42 of a tablet's canvas high and 0.44 of a phone's. Framed as tall as it is
    plus HEADROOM of its span, it is more than half as high as the canvas, and its top raised
    by that headroom is still in view."""
    width, height = size
    aspect = width / height
    span, table = arm_span(EXT, "delta"), table_extent(EXT, "delta")
    spine = _spine(_extensible_q(0.5))
    pose = camera.presets_for_window("delta", span, table, width, height, spine)[0]
    ys = [ndc(pose, p, aspect)[1] for p in spine]
    assert (max(ys) - min(ys)) / 2 > 0.55
    above = spine[-1] + (0.0, 0.0, camera.HEADROOM * span)
    assert camera.in_view(pose, np.vstack([spine, above]), aspect)
    # Without the arm's points: the volume of the fully extended arm (as before)
    full = camera.presets_for_window("delta", span, table, width, height)[0]
    ys = [ndc(full, p, aspect)[1] for p in spine]
    assert (max(ys) - min(ys)) / 2 < 0.5
    assert camera.in_view(full, _spine(_extensible_q(1.0)), aspect)


def test_the_extensible_arms_views_are_reframed_when_it_grows_out_of_them(server):
    """ConsoleApp.follow_arm: the tip rising to within 2 cm of the top the views were framed
    for re-frames them once (WindowFit.refit), for the arm as tall as it is then; moving below
    that top, or the soft arm, re-frames nothing."""
    from tests.fakes import FakeRunner, console_app

    app = console_app(EXT, server, extensible_runner=FakeRunner(), panels=())
    refits: list[int] = []
    app.window_fit.refit = lambda: refits.append(1) or []           # (counted, not run)
    span = arm_span(EXT, "delta")
    rest, full = _extensible_q(0.5), _extensible_q(1.0)
    np.testing.assert_allclose(app.store.display.q, rest, atol=1e-9)  # (where it starts)
    app.framed_points()                                            # a browser framed at rest
    top = float(np.sum(EXT.L0 + rest[:, 2]))
    assert app._framed_top == pytest.approx(top + camera.HEADROOM * span, abs=0.02)
    assert app.follow_arm(rest) == [] and refits == []
    a_bit = _extensible_q(0.55)                                       # 1.8 cm taller: in view
    assert float(np.sum(EXT.L0 + a_bit[:, 2])) < app._framed_top - 0.02
    app.follow_arm(a_bit)
    assert refits == []
    app.follow_arm(full)                                              # out of it: re-framed
    assert refits == [1] and app._framed_top == pytest.approx(span)
    app.follow_arm(full)                                              # once
    assert refits == [1]


def test_a_typed_target_above_the_framed_top_reframes_the_views_to_show_it(server):
    """ConsoleApp.keep_in_view (the Tip target panel's typed target, drawn as a dimmed ball
    until Go): above the top the views were framed for, it re-frames them and every preset
    then shows it; one already in view, or the soft arm, re-frames nothing."""
    from tests.fakes import FakeRunner, console_app

    app = console_app(EXT, server, extensible_runner=FakeRunner(), panels=())
    refits: list[int] = []
    app.window_fit.refit = lambda: refits.append(1) or []           # (counted, not run)
    span, table = arm_span(EXT, "delta"), table_extent(EXT, "delta")
    rest = _extensible_q(0.5)
    app.framed_points()                                            # a browser framed at rest
    top = app._framed_top
    below = np.array([0.02, -0.01, top - 0.1])
    assert app.keep_in_view(below) == [] and refits == []
    above = np.array([0.06, -0.04, top + 0.05])                    # the demo's typed target
    pose = camera.presets_for_window("delta", span, table, 1276, 1000,
                                     _spine(rest))[0]
    assert not camera.in_view(pose, above[None], 1276 / 1000)      # was drawn off the top
    app.keep_in_view(above)
    assert refits == [1] and app._framed_top > above[2]
    for width, height in ((1276, 1000), (496, 1180), (390, 422)):
        pose = camera.presets_for_window("delta", span, table, width, height,
                                         app.framed_points())[0]
        assert camera.in_view(pose, np.vstack([_spine(rest), above]), width / height)
    app.keep_in_view(None)                                          # Go / discarded: no point
    assert not np.any(np.all(np.isclose(app.framed_points(), above), axis=1))
