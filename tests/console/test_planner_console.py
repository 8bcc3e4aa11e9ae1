"""Grasp console pieces without a browser: drawing geometry against the kinematics, scene JSON,
click rays, and the grasp session on a live viser server (plans, refusals, inspection,
playback, throttled live re-planning)."""

from __future__ import annotations

import json
import math
import socket
import time

import numpy as np
import pytest

from console.scene.plan_view import (circle_segments, ghost_segments, object_mesh, plan_geometry,
                               ray_to_table, reach_mesh)
from console.core.table_scene import TableObject, scene_from_json, scene_to_json
from core.kinematics import planar as pk
from core.planning.sides import plan_grasp_sided
from core.planning.reachability import PLANNABLE, from_json, reachability_map, to_json
from core.robots import load
from fakes import FakeClient, click_at, user
from ws_client import wait_for

ROBOT = load("soft-arm")


def test_click_ray_meets_the_table_plane():
    assert ray_to_table((0.1, 0.2, 1.0), (0.0, 0.0, -1.0)) == pytest.approx((0.1, 0.2))
    x, y = ray_to_table((0.0, -1.0, 1.0), (0.0, 0.6, -0.8))
    assert (x, y) == pytest.approx((0.0, -1.0 + 0.75))
    assert ray_to_table((0.0, 0.0, 1.0), (0.0, 1.0, 0.2)) is None     # looking up
    assert ray_to_table((0.0, 0.0, -1.0), (0.0, 0.0, -1.0)) is None   # table behind the ray


def test_scene_json_round_trip_and_refusals():
    objs = [TableObject("cup", -0.2, 0.2, 0.02), TableObject("egg", -0.1, 0.3, 0.0165)]
    assert scene_from_json(scene_to_json(objs), ROBOT) == objs
    for bad, words in (("not json", "not a scene"), ('{"objects": [{"x": 1}]}', "not a scene"),
                       ('{"objects": [{"name": "a", "x": 0, "y": 0, "r": -1}]}', "radius"),
                       (json.dumps({"objects": [dataclass_dict(o) for o in objs * 2]}),
                        "unique")):
        with pytest.raises(ValueError, match=words):
            scene_from_json(bad, ROBOT)


def dataclass_dict(o: TableObject) -> dict:
    return {"name": o.name, "x": o.x, "y": o.y, "r": o.r}


def test_drawing_geometry_matches_the_plan_and_the_kinematics():
    plan = plan_grasp_sided(ROBOT, np.zeros(6), (-0.2, 0.2), 0.0165)
    segs = circle_segments(plan.center, plan.radii, 0.03)
    d = np.hypot(segs[..., 0] - plan.center[0], segs[..., 1] - plan.center[1])
    np.testing.assert_allclose(d.reshape(plan.n, -1), np.repeat(plan.radii, d.size // plan.n)
                               .reshape(plan.n, -1), atol=1e-12)
    ghosts = ghost_segments(ROBOT, plan.kappas, 0.03)
    tips = pk.forward_kinematics(plan.kappas, ROBOT.lengths, ROBOT.base_pose)[:, -1]
    ends = tips[:, :2] + ROBOT.gripper.length * np.c_[np.cos(tips[:, 2]), np.sin(tips[:, 2])]
    np.testing.assert_allclose(ghosts[:, -1, 1, :2], ends, atol=1e-12)       # gripper end
    np.testing.assert_allclose(ghosts[:, -1, 0, :2], tips[:, :2], atol=1e-12)  # gripper root
    np.testing.assert_allclose(ghosts[:, 0, 0, :2], 0.0, atol=1e-12)          # base
    g = plan_geometry(ROBOT, plan, plan.n - 1, trail=True)
    assert len(g["ghosts"]) == (plan.n - 1) * ghosts.shape[1]                # trail: passed ones
    assert g["capture_visible"]
    final = plan.palm_poses[-1]
    aim = final[:2] + (ROBOT.gripper.g_off + ROBOT.capture.nominal_object_radius) * np.array(
        [-math.sin(final[2]), math.cos(final[2])])
    np.testing.assert_allclose(g["capture"][0][0, :2], aim, atol=1e-12)
    assert np.max(np.hypot(*(g["capture"][0][1:, :2] - aim).T)) == pytest.approx(
        ROBOT.capture.diameter / 2)
    assert not plan_geometry(ROBOT, plan, 0, trail=False)["capture_visible"]


def test_object_mesh_is_a_closed_cylinder():
    v, f = object_mesh(0.02, 0.04)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)                                              # watertight
    assert np.hypot(v[:-2, 0], v[:-2, 1]) == pytest.approx(0.02)


def test_reachability_map_agrees_with_the_planner_and_round_trips():
    reach = reachability_map(ROBOT, 0.0165, (-0.3, 0.1), (0.0, 0.4), 0.1)
    for i, y in enumerate(reach.ys):
        for j, x in enumerate(reach.xs):
            try:
                ok = plan_grasp_sided(ROBOT, np.zeros(6), (x, y), 0.0165).success
            except ValueError:
                ok = False
            assert (reach.status[i, j] == PLANNABLE) == ok, (x, y)
    again = from_json(to_json(reach))
    np.testing.assert_array_equal(again.status, reach.status)
    assert reach.lookup(-0.2, 0.2) == reach.status[2, 1]
    v, f = reach_mesh(reach, PLANNABLE)
    assert len(f) == 2 * (reach.status == PLANNABLE).sum()


@pytest.fixture(scope="module")
def console():
    import viser

    from console.app import ConsoleApp
    from console.panels.soft_arm import panel_set, planner

    with pytest.MonkeyPatch.context() as patch:  # (module scope: no monkeypatch fixture)
        patch.setattr(planner.GraspSession, "compute_reach", False)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
        app = ConsoleApp(ROBOT, server, panels=panel_set.grasp_panels()).start()
        yield app
        app.grasp_session.close()
        app.stop()
        server.stop()


def test_session_plans_refuses_inspects_and_plays(console):
    from console.panels.soft_arm.planner import PlannerPanel, outcome_html
    from console.panels.soft_arm.waypoints import WaypointsPanel

    s = console.grasp_session
    first = wait_for(lambda: s.view().outcome)            # the demo object, planned at start
    assert first.plan is not None and first.plan.success
    name = s.place(-0.12, 0.28)
    out = wait_for(lambda: (o := s.view().outcome) and o.obj and o.obj.name == name and o)
    ref = plan_grasp_sided(ROBOT, np.zeros(6), (-0.12, 0.28),
                           ROBOT.capture.nominal_object_radius)
    np.testing.assert_allclose(out.plan.kappas, ref.kappas, atol=1e-9)
    seq = s.view().outcome.seq
    assert s.place(-0.121, 0.281) == name                 # a click on an object selects it
    out = wait_for(lambda: (o := s.view().outcome) and o.seq > seq and o)    # and re-plans it
    wait_for(lambda: 'data-state="ok"' in console.panel(PlannerPanel).summary.content)
    # Scene: one circle outline per waypoint, ghost of the inspected waypoint.
    scene = console.grasp_scene.plan_scene
    assert len(scene.circles.points) % out.plan.n == 0 and scene.circles.visible

    s.inspect(step=+10)
    wait_for(lambda: s.view().index == out.plan.n - 1)
    wait_for(lambda: console.panel(WaypointsPanel).slider.value == out.plan.n)   # mirrored
    s.inspect(step=-100)
    wait_for(lambda: s.view().index == 0)
    s.play(True, speed=40.0)
    wait_for(lambda: not s.view().playing and s.view().index == out.plan.n - 1)

    s.update(name, x=0.6, y=0.6)
    refused = wait_for(lambda: (o := s.view().outcome) and o.refusal and o)
    assert "out of reach" in refused.refusal
    assert 'data-state="refused"' in outcome_html(refused)
    with pytest.raises(ValueError):
        s.update(name, r=-0.01)                           # bad input changes nothing
    assert next(o for o in s.view().objects if o.name == name).r > 0


def test_live_replanning_is_throttled_to_the_newest_position(console):
    s = console.grasp_session
    # beyond Object 1 from the arm: its approach is clear of Object 1 (an obstacle for it)
    name = s.place(-0.14, 0.33)
    wait_for(lambda: (o := s.view().outcome) and o.obj and o.obj.name == name)
    seq0 = s.view().outcome.seq
    t0 = time.monotonic()
    for k in range(60):                                   # a fast drag: 60 positions in ~0.3 s
        s.update(name, x=-0.14 + 0.001 * k, live=True)
        time.sleep(0.005)
    s.update(name, x=-0.08, y=0.33)                       # release: one final plan
    out = wait_for(lambda: (o := s.view().outcome) and o.obj.x == pytest.approx(-0.08) and o)
    elapsed = time.monotonic() - t0
    plans = out.seq - seq0
    assert plans <= 2 + elapsed * 20.0 * 1.5              # LIVE_HZ = 20, plus the final plan
    assert out.plan is not None and out.plan.success


# -- sharing: only the operator changes the objects, the plan and the inspected waypoint ------

def drag(app, name: str, client, x: float, y: float, phase: str = "end") -> None:
    """What viser does with a browser's gizmo drag: store the pose, then call back."""
    import viser

    layers = app.grasp_scene
    gizmo = wait_for(lambda: layers.plan_scene.objects.get(name))[0]  # drawn by the worker
    gizmo._impl.position = np.array([x, y, 0.0])
    layers.on_gizmo(name, viser.TransformControlsEvent(client, client.client_id, gizmo, phase))


@pytest.fixture
def gated(monkeypatch):
    """A console with the grasp panels, an operator token and its own session."""
    import viser

    from console.core.access import AccessControl
    from console.app import ConsoleApp
    from console.panels.soft_arm import panel_set, planner

    monkeypatch.setattr(planner.GraspSession, "compute_reach", False)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = ConsoleApp(ROBOT, server, panels=panel_set.grasp_panels(), access=AccessControl("tok"))
    try:
        yield app
    finally:
        app.grasp_session.close()
        app.grasp_session._thread.join(5)  # no drawing into a stopped server
        server.stop()


def test_a_viewer_changes_nothing_and_edits_snap_back(gated):
    import viser

    from console.panels.soft_arm.objects import ObjectsPanel
    from console.panels.soft_arm.planner import PlannerPanel
    from console.panels.soft_arm.waypoints import WaypointsPanel

    app, s = gated, gated.grasp_session
    op, pp, wp = app.panel(ObjectsPanel), app.panel(PlannerPanel), app.panel(WaypointsPanel)
    viewer, operator = FakeClient(21), FakeClient(22)
    app.access.take(operator.client_id, "tok", name="Alice")
    user(op.add_button, operator)  # two objects, so selecting is possible
    wait_for(lambda: len(s.view().objects) == 2 and s.view().outcome
             and s.view().outcome.obj.name == "Object 2")
    user(op.selected, operator, "Object 1")
    out = wait_for(lambda: (o := s.view().outcome) and o.obj.name == "Object 1" and o.plan
                   and o)
    time.sleep(0.2)
    before, settings = s.view(), (s.delta_d, s.weights, s.live, s.show_reach)
    command = app.store.command
    obj = before.objects[0]
    scene = scene_to_json([TableObject("Cup", -0.1, 0.3, 0.02)]).encode()

    user(op.add_button, viewer)
    user(op.remove_button, viewer)
    user(op.x, viewer, 50.0)  # mm (issue 18: units people read)
    user(op.r, viewer, 30.0)
    user(op.selected, viewer, "Object 2")
    user(op.click_place, viewer, "Nothing")   # #17.1: a dropdown (Object | Obstacle | Nothing)
    user(op.load_button, viewer, viser.UploadedFile("cup.json", scene))
    click_at(op, viewer, -0.1, 0.3)
    drag(app, "Object 1", viewer, 0.0, 0.35, phase="update")
    user(pp.plan_button, viewer)
    user(pp.delta_d, viewer, 50.0)
    user(pp.weights, viewer, "1, 1, 1, 1, 1, 1")
    user(pp.live, viewer, False)
    user(pp.reach, viewer, False)
    for button in (wp.next_button, wp.prev_button, wp.play_button, wp.move_button):
        user(button, viewer)
    user(wp.slider, viewer, out.plan.n)
    user(wp.speed, viewer, 8.0)
    user(wp.trail, viewer, False)
    time.sleep(0.3)  # a wrongly accepted request would be planned / drawn by now

    after = s.view()
    assert after.objects == before.objects and after.selected == "Object 1"
    assert after.outcome.seq == before.outcome.seq and after.index == before.index
    assert not after.playing and after.speed == before.speed and after.trail == before.trail
    assert (s.delta_d, s.weights, s.live, s.show_reach) == settings
    assert app.store.command is command
    # What the viewer's browser showed everyone is put back.
    assert (op.x.value, op.r.value) == (round(obj.x * 1e3, 1), round(obj.r * 1e3, 1))  # mm
    assert op.selected.value == "Object 1" and op.click_place.value == "Object"
    assert pp.delta_d.value == round(s.delta_d * 1e3, 1) and pp.live.value and pp.reach.value
    assert pp.weights.value == ", ".join(f"{w:g}" for w in s.weights)
    assert wp.slider.value == before.index + 1 and wp.speed.value == 2.0 and wp.trail.value
    gizmo = app.grasp_scene.plan_scene.objects["Object 1"][0]
    wait_for(lambda: np.allclose(gizmo.position[:2], (obj.x, obj.y)))
    refused = {body.split(" — ")[0].removeprefix("Only the operator can ")
               for title, body in viewer.notes if title == "Not allowed"}
    assert refused == {
        "add an object", "remove an object", "edit an object", "select an object",
        "change how clicks on the table act", "load a scene", "place or select an object",
        "move an object", "plan a grasp", "change the planner", "change the shading",
        "step through the waypoints", "play the waypoints", "change the playback speed",
        "change the trail", "move the arm"}
    assert all("Alice holds control" in body for _, body in viewer.notes)


def test_the_operator_changes_objects_plan_and_waypoints(gated):
    import viser

    from console.panels.soft_arm.objects import ObjectsPanel
    from console.panels.soft_arm.planner import PlannerPanel
    from console.panels.soft_arm.waypoints import WaypointsPanel

    app, s = gated, gated.grasp_session
    op, pp, wp = app.panel(ObjectsPanel), app.panel(PlannerPanel), app.panel(WaypointsPanel)
    operator = FakeClient(7)
    app.access.take(operator.client_id, "tok")
    first = wait_for(lambda: s.view().outcome)
    click_at(op, operator, -0.12, 0.28)
    wait_for(lambda: [o.name for o in s.view().objects] == ["Object 1", "Object 2"])
    placed = s.view().objects[1]
    assert (placed.x, placed.y) == pytest.approx((-0.12, 0.28))
    drag(app, "Object 2", operator, -0.15, 0.25)
    wait_for(lambda: s.view().objects[1].x == pytest.approx(-0.15))
    wait_for(lambda: (op.x.value, op.y.value) == (-150.0, 250.0))  # mirrored into the fields (mm)
    user(op.r, operator, 20.0)
    wait_for(lambda: s.view().objects[1].r == pytest.approx(0.02))
    assert (s.view().objects[1].x, s.view().objects[1].y) == pytest.approx((-0.15, 0.25))
    user(pp.delta_d, operator, 30.0)  # mm
    assert s.delta_d == pytest.approx(0.03)
    user(pp.delta_d, operator, 0.0)  # bad input: a clear message, the setting stays
    assert s.delta_d == pytest.approx(0.03) and pp.delta_d.value == pytest.approx(30.0)
    assert any("Δd must be a positive distance" in body for _, body in operator.notes)
    seq = s.view().outcome.seq
    user(pp.plan_button, operator)
    out = wait_for(lambda: (o := s.view().outcome) and o.seq > seq and o.plan and o)
    assert out.obj.name == "Object 2" and out.seq > first.seq
    user(wp.next_button, operator)
    wait_for(lambda: s.view().index == min(1, out.plan.n - 1))
    user(wp.slider, operator, out.plan.n)
    wait_for(lambda: s.view().index == out.plan.n - 1)
    user(wp.move_button, operator)
    np.testing.assert_allclose(app.store.command.q, out.plan.kappas[-1])
    user(op.load_button, operator, viser.UploadedFile(
        "cup.json", scene_to_json([TableObject("Cup", -0.1, 0.3, 0.02)]).encode()))
    wait_for(lambda: [o.name for o in s.view().objects] == ["Cup"])
    assert not any(title == "Not allowed" for title, _ in operator.notes)


def test_closed_panels_stop_listening_to_the_session_that_outlives_them(gated, caplog):
    """A panel closed while the grasp session goes on (the session belongs to the console)
    is no longer told of changes: its removed widgets were written to ("Cannot assign to
    'content' on a removed GuiHtmlHandle", logged on every change in fresh40)."""
    import logging

    s = gated.grasp_session
    wait_for(lambda: s.view().outcome)
    for panel in gated.panels:
        panel.close()
    told = []
    s.add_listener(lambda view, changed: told.append([o.name for o in view.objects]))
    caplog.clear()
    with caplog.at_level(logging.ERROR, logger="console.core.grasp_session"):
        name = s.place(-0.12, 0.28)
        wait_for(lambda: any(name in names for names in told))
        wait_for(lambda: (o := s.view().outcome) and o.obj is not None and o.obj.name == name,
                 timeout=30.0)
        s.remove(name)
        wait_for(lambda: told and name not in told[-1])
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
