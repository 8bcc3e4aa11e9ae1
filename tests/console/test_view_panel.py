"""The View panel and what it stands on: click rays on the table, measurements, camera presets,
the trail caps, and measuring clicks that place nothing (for the measuring browser only)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from console.scene import camera
from console.scene.measure import Measurement, NotOnTable, table_hit
from console.panels.extensible.path_scene import trail_tail
from console.scene.plan_view import (GHOST_COLOR, TABLE_TINT, TRAIL_WAYPOINTS, plan_geometry,
                               plan_labels, trail_colors, trail_mask)
from core.planning.grasp import plan_grasp
from core.robots import load
from tests.fakes import FakeClient
from tests.ws_client import wait_for

SOFT, EXT = load("soft-arm"), load("extensible")


def span_and_table(robot) -> tuple[float, tuple[float, float, float, float]]:
    """What ConsoleApp.arm_reach / table_rectangle give (written out: an independent expectation)."""
    if robot.kind == "planar":
        s = robot.n_segments * robot.segment_length + robot.gripper.length
        return s, (-s, s, -0.4 * s, 1.15 * s)
    s = robot.n_segments * robot.rack_max
    return s, (-0.75 * s, 0.75 * s, -0.75 * s, 0.75 * s)


# -- rays, points, distances --------------------------------------------------------------------

def test_a_click_ray_meets_the_table_where_the_closed_form_says():
    rng = np.random.default_rng(7)
    for _ in range(200):
        eye = rng.uniform((-1, -1, 0.2), (1, 1, 2))
        target = np.r_[rng.uniform(-0.4, 0.4, 2), 0.0]
        d = (target - eye) * rng.uniform(0.1, 5)                    # any length
        assert table_hit(eye, d) == pytest.approx(tuple(target[:2]), abs=1e-12)
    # 45 degrees down from 1 m above the origin: 1 m further along x.
    assert table_hit((0, 0, 1), (1, 0, -1)) == pytest.approx((1.0, 0.0))


def test_rays_parallel_to_away_from_or_off_the_table_are_refused():
    with pytest.raises(NotOnTable, match="parallel"):
        table_hit((0, 0, 0.5), (1, 0, 0))
    with pytest.raises(NotOnTable, match="parallel"):
        table_hit((0, 0, 0.5), (1, 0, 1e-9))
    with pytest.raises(NotOnTable, match="away"):
        table_hit((0, 0, 0.5), (0, 0, 1))
    with pytest.raises(NotOnTable, match="off the table"):
        table_hit((0, 0, 1), (2, 0, -1), table=(-1, 1, -1, 1))      # meets z = 0 at x = 2
    with pytest.raises(NotOnTable):
        table_hit((0, 0, 1), (np.nan, 0, -1))
    assert table_hit((0, 0, 1), (0.5, 0.5, -1), table=(-1, 1, -1, 1)) == (0.5, 0.5)


def test_a_measurement_is_the_euclidean_distance_in_mm():
    m = Measurement((0.1, 0.2), (0.4, 0.6))                         # a 3-4-5 triangle
    assert m.distance == pytest.approx(0.5)
    assert m.label == "500.0 mm"
    assert m.midpoint == pytest.approx((0.25, 0.4))
    assert Measurement((0, 0), (0.12345, 0)).label == "123.5 mm"
    np.testing.assert_allclose(m.segment(0.01), [[[0.1, 0.2, 0.01], [0.4, 0.6, 0.01]]])


# -- camera presets ------------------------------------------------------------------------------

def ndc(pose: camera.CameraPose, point, aspect: float) -> tuple[float, float]:
    """Normalised device coordinates of a world point (x, y in [-1, 1] when in view)."""
    eye, f = np.array(pose.position), pose.forward
    r = np.cross(f, pose.up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = np.asarray(point, float) - eye
    t = math.tan(pose.fov / 2)
    return (d @ r) / ((d @ f) * t * aspect), (d @ u) / ((d @ f) * t)


@pytest.mark.parametrize("robot", [SOFT, EXT], ids=["soft-arm", "extensible"])
@pytest.mark.parametrize("aspect", [1.6, 820 / 1180, 2.2])
def test_presets_look_at_the_table_and_keep_the_arm_in_view(robot, aspect):
    span, table = span_and_table(robot)
    poses = camera.presets(robot.kind, span, table, aspect)
    names = [p.name for p in poses]
    assert len(set(names)) == len(names)
    assert {"Perspective", "Top-down"} <= set(names)
    if robot.kind == "delta":
        assert {"Front", "Side"} <= set(names)
    for pose in poses:
        x0, x1, y0, y1 = table
        assert x0 <= pose.look_at[0] <= x1 and y0 <= pose.look_at[1] <= y1, pose
        assert pose.position[2] > 0                                 # above the table
    top = camera.preset(robot.kind, "Top-down", span, table, aspect)
    assert top.forward[2] < -0.999                                  # looks straight down
    # The base and the arm's reach in the canvas (the panel is docked beside it), also in a
    # tall window (the old camera cut a tablet's reach off at the sides).
    if robot.kind == "planar":
        corners = [(sx * span, sy * span, 0.0) for sx in (-1, 1) for sy in (-0.25, 1)]
        for pose in (top, poses[0]):
            for c in corners + [(0.0, 0.0, 0.0)]:
                x, y = ndc(pose, c, aspect)
                assert -1 <= x <= 1 and -1 <= y <= 1, (pose.name, c)
    else:
        from console.core.model import ExtensibleModel
        from core.kinematics import delta as dk
        start = tuple(dk.tip_position(robot, ExtensibleModel(robot).initial()))  # start pose's tip
        rest = (0.0, 0.0, robot.n_segments * robot.rack_min)       # the retracted arm's top
        for pose in poses:
            for p in ((0.0, 0.0, 0.0), rest, start, (0.1, 0.1, 0.3 * span),
                      (-0.1, -0.1, 0.3 * span)):
                x, y = ndc(pose, p, aspect)
                assert -1 <= x <= 1 and -1 <= y <= 1, (pose.name, p)
        persp = poses[0]
        if aspect > 1.2:  # a wide window also shows the fully extended arm's top
            assert -1 <= ndc(persp, (0.0, 0.0, span), aspect)[1] <= 1
        # ... and the arm is not tiny: in a wide window the arm at its start pose spans >= 30 %
        # of the canvas height (the old camera: under 15 %).
        h = abs(ndc(persp, start, aspect)[1] - ndc(persp, (0.0, 0.0, 0.0), aspect)[1]) / 2
        assert h >= (0.30 if aspect > 1.2 else 0.1), h
    with pytest.raises(ValueError, match="no camera preset 'Upside-down'"):
        camera.preset(robot.kind, "Upside-down", span, table)
    with pytest.raises(ValueError):
        camera.presets(robot.kind, 0.0, table)


def test_the_planar_arm_opens_with_the_camera_the_browser_tests_project_with():
    span, table = span_and_table(SOFT)
    first = camera.presets("planar", span, table)[0]
    assert first.position == pytest.approx((0.55 * span, -1.25 * span, 1.75 * span))
    assert first.look_at == pytest.approx((0.3 * span, 0.32 * span, 0.0))
    assert first.fov == pytest.approx(math.radians(50.0))


# -- trails ----------------------------------------------------------------------------------

def test_the_waypoint_trail_is_capped_fades_and_clears():
    n = 11
    shown = trail_mask(n, 10, True)
    assert np.nonzero(shown)[0].tolist() == list(range(10 - TRAIL_WAYPOINTS, 10))
    assert np.nonzero(trail_mask(n, 2, True))[0].tolist() == [0, 1]
    assert not trail_mask(n, 10, False).any()
    assert np.nonzero(trail_mask(n, 10, True, trail_from=8))[0].tolist() == [8, 9]
    assert not trail_mask(n, 8, True, trail_from=8).any()           # just cleared
    colors = trail_colors(shown, 10).astype(float)
    assert colors[-1] == pytest.approx(GHOST_COLOR)                  # the newest: full colour
    dist = np.linalg.norm(colors - TABLE_TINT, axis=1)
    assert np.all(np.diff(dist) > 0)                                 # older: closer to the table
    plan = plan_grasp(SOFT, np.zeros(6), (0.3, 0.1), 0.0165)         # 11 waypoints
    assert plan.n > TRAIL_WAYPOINTS + 1
    g = plan_geometry(SOFT, plan, plan.n - 1, trail=True)
    per = len(plan_geometry(SOFT, plan, 1, trail=True)["ghosts"])    # one ghost arm's segments
    assert len(g["ghosts"]) == TRAIL_WAYPOINTS * per
    assert len(g["ghost_colors"]) == len(g["ghosts"])
    assert len(plan_geometry(SOFT, plan, plan.n - 1, True, trail_from=plan.n - 2)["ghosts"]) \
        == per


def test_the_measured_path_trace_keeps_its_last_seconds():
    t = np.arange(0, 100.0 + 1e-9, 0.01)
    pts = np.c_[t, t, t]
    tail = trail_tail(t, pts, 30.0)
    assert tail[0, 0] == pytest.approx(70.0) and tail[-1, 0] == pytest.approx(100.0)
    assert len(tail) == pytest.approx(3001, abs=1)
    assert len(trail_tail(t[:50], pts[:50], 30.0)) == 50             # a short run: all of it
    assert len(trail_tail(t[:0], pts[:0], 30.0)) == 0


def test_labels_name_each_circle_and_waypoint_away_from_the_arm():
    plan = plan_grasp(SOFT, np.zeros(6), (-0.2, 0.2), 0.0165)
    labels = plan_labels(SOFT, plan)
    assert [t for t, _, _ in labels["waypoints"]] == [str(k + 1) for k in range(plan.n)]
    for (text, pos, anchor), r in zip(labels["circles"], plan.radii):
        assert text.endswith(f" {round(r * 1e3):.0f} mm")  # mm, like every label (issue 18)
        # just outside the circle, on the far side from the base (further from it than the
        # centre), the text running outwards (the object is left of the base: to the left)
        assert r < math.hypot(pos[0] - plan.center[0], pos[1] - plan.center[1]) < r + 0.01
        assert math.hypot(*pos[:2]) > math.hypot(*plan.center[:2])
        assert anchor == "center-right"
    for (_, pos, _), palm in zip(labels["waypoints"], plan.palm_poses):
        assert 0.005 < math.hypot(pos[0] - palm[0], pos[1] - palm[1]) < 0.03


# -- the panel in a console -------------------------------------------------------------------

def click(server, client, ray_origin, ray_direction) -> None:
    """What viser 1.1.1 does with a browser's click: one event to every click callback."""
    import viser

    event = viser.SceneClickEvent(client, client.client_id, tuple(ray_origin),
                                  tuple(ray_direction), (0.5, 0.5), None)
    for entry in list(server.scene._scene_pointer_cb):              # (viser internals, checked)
        if entry.event_type == "click":
            entry.callback(event)


@pytest.fixture
def planar_console(server, monkeypatch):
    from console.panels.soft_arm import panel_set, planner
    from console.panels.common.view import ViewPanel
    from tests.fakes import console_app

    monkeypatch.setattr(planner.GraspSession, "compute_reach", False)
    app = console_app(SOFT, server, panels=(*panel_set.grasp_panels(), ViewPanel))
    try:
        yield app
    finally:
        app.grasp_session.close()
        app.grasp_session._thread.join(5)


def test_measuring_clicks_measure_and_place_nothing_other_browsers_still_place(planar_console):
    from console.panels.common.view import ViewPanel

    app = planar_console
    view, session = app.panel(ViewPanel), app.grasp_session
    operator, other = FakeClient(31), FakeClient(32)
    app.access.take(operator.client_id, None, name="Alice")
    late: list = []
    app.server.scene.on_click()(late.append)                        # a panel added afterwards
    assert len(session.view().objects) == 1
    eye = np.array([0.1, -0.5, 0.8])
    a, b = np.array([-0.3, 0.35, 0.0]), np.array([0.2, 0.1, 0.0])

    view.start_measuring(operator.client_id)
    click(app.server, operator, eye, (a - eye) * 2.0)
    assert view.measurement is None and not late
    click(app.server, operator, eye, (0.3, 0.0, 0.0))               # parallel: refused, no point
    assert operator.notes[-1][0] == "Not on the table" and view.measurement is None
    click(app.server, operator, eye, b - eye)
    m = view.measurement
    assert m is not None and m.distance == pytest.approx(np.linalg.norm(b - a), abs=1e-9)
    assert view.label.text == m.label and view.label.visible and view.line.visible
    np.testing.assert_allclose(view.line.points[0, :, :2], [a[:2], b[:2]], atol=1e-9)
    time.sleep(0.3)
    assert len(session.view().objects) == 1 and not late            # nothing placed

    click(app.server, operator, eye, (a - eye))                     # measuring is over
    wait_for(lambda: len(session.view().objects) == 2)
    assert len(late) == 1

    view.start_measuring(other.client_id)                           # a viewer measures
    click(app.server, operator, eye, (b + [0.05, 0.05, 0] - eye))   # the operator still places
    wait_for(lambda: len(session.view().objects) == 3)
    click(app.server, other, eye, (a - eye))
    click(app.server, other, eye, (a + [0.1, 0, 0] - eye))
    assert view.measurement.label == "100.0 mm"
    assert len(session.view().objects) == 3


def test_clear_trails_is_the_operators_and_clears_the_plan_trail(planar_console):
    import viser

    from console.panels.common.view import ViewPanel

    app = planar_console
    view, session = app.panel(ViewPanel), app.grasp_session
    wait_for(lambda: session.view().outcome is not None and session.view().outcome.plan)
    session.inspect(index=3)
    viewer, operator = FakeClient(41), FakeClient(42)
    app.access.take(operator.client_id, None, name="Alice")

    def press(client):
        for cb in list(view.clear_trails._impl.update_cb):
            cb(viser.GuiEvent(client=client, client_id=client.client_id,
                              target=view.clear_trails))

    press(viewer)
    assert session.view().trail_from == 0 and viewer.notes              # refused
    press(operator)
    assert session.view().trail_from == 3
    wait_for(lambda: not app.grasp_scene.plan_scene.ghosts.visible)
    session.inspect(step=1)
    wait_for(lambda: app.grasp_scene.plan_scene.ghosts.visible)                   # it grows again


def test_view_panel_for_the_extensible_arm_has_its_presets_and_legend(server):
    from console.panels.common.view import ViewPanel, legend_html
    from tests.fakes import console_app

    app = console_app(EXT, server, panels=(ViewPanel,))
    view = app.panel(ViewPanel)
    assert set(view.cameras) == {"Perspective", "Front", "Side", "Top-down"}
    ext, soft = legend_html("delta"), legend_html("planar")
    assert "Racks" in ext and "Approach circles" not in ext
    assert "Approach circles" in soft and "Racks" not in soft
    for words in ("Ghost arm", "Trail", "Waypoints", "Capture region", "Object",
                  "grasp can be planned", "planning fails", "Measurement"):
        assert words in soft, words
    assert all(app.guard.viewer_allowed(b) for b in view.cameras.values())
    assert app.guard.viewer_allowed(view.reset) and app.guard.viewer_allowed(view.measure)
    assert not app.guard.viewer_allowed(view.clear_trails)


def test_viser_still_keeps_scene_click_callbacks_where_the_claims_expect(server):
    entries = server.scene._scene_pointer_cb
    server.scene.on_click()(lambda e: None)
    entry = server.scene._scene_pointer_cb[-1]
    assert isinstance(entries, list)
    for field in ("callback", "event_type", "event_class"):
        assert hasattr(entry, field)
