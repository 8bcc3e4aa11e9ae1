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

from console.plan_view import (TableObject, circle_segments, ghost_segments, object_mesh,
                               plan_geometry, ray_to_table, reach_mesh, scene_from_json,
                               scene_to_json)
from core.kinematics import planar as pk
from core.planning.grasp import plan_grasp
from core.planning.reachability import PLANNABLE, ReachMap, from_json, reachability_map, to_json
from core.robots import load

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
    plan = plan_grasp(ROBOT, np.zeros(6), (-0.2, 0.2), 0.0165)
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
                ok = plan_grasp(ROBOT, np.zeros(6), (x, y), 0.0165).success
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
    from console.panels import planner

    planner.GraspSession.compute_reach = False
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    app = ConsoleApp(ROBOT, server, panels=planner.grasp_panels()).start()
    yield app
    app.grasp_session.close()
    app.stop()
    server.stop()
    planner.GraspSession.compute_reach = True


def wait_for(fn, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = fn()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError("condition not met in time")


def test_session_plans_refuses_inspects_and_plays(console):
    from console.panels.planner import PlannerPanel, outcome_html
    from console.panels.waypoints import WaypointsPanel

    s = console.grasp_session
    first = wait_for(lambda: s.view().outcome)            # the demo object, planned at start
    assert first.plan is not None and first.plan.success
    name = s.place(-0.12, 0.28)
    out = wait_for(lambda: (o := s.view().outcome) and o.obj and o.obj.name == name and o)
    ref = plan_grasp(ROBOT, np.zeros(6), (-0.12, 0.28), ROBOT.capture.nominal_object_radius)
    np.testing.assert_allclose(out.plan.kappas, ref.kappas, atol=1e-9)
    seq = s.view().outcome.seq
    assert s.place(-0.121, 0.281) == name                 # a click on an object selects it
    out = wait_for(lambda: (o := s.view().outcome) and o.seq > seq and o)    # and re-plans it
    wait_for(lambda: 'data-state="ok"' in console.panel(PlannerPanel).summary.content)
    # Scene: one circle outline per waypoint, ghost of the inspected waypoint.
    scene = s.scene
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
    name = s.place(-0.25, 0.15)
    wait_for(lambda: (o := s.view().outcome) and o.obj and o.obj.name == name)
    seq0 = s.view().outcome.seq
    t0 = time.monotonic()
    for k in range(60):                                   # a fast drag: 60 positions in ~0.3 s
        s.update(name, x=-0.25 + 0.001 * k, live=True)
        time.sleep(0.005)
    s.update(name, x=-0.19, y=0.15)                       # release: one final plan
    out = wait_for(lambda: (o := s.view().outcome) and o.obj.x == pytest.approx(-0.19) and o)
    elapsed = time.monotonic() - t0
    plans = out.seq - seq0
    assert plans <= 2 + elapsed * 20.0 * 1.5              # LIVE_HZ = 20, plus the final plan
    assert out.plan is not None and out.plan.success
