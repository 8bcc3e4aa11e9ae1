"""Obstacles in the console (#17.1, planar arm): scene files, the Objects panel's click mode and
obstacle editor, the planner's clearance field, drawing, sharing rules, recordings and replay."""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from mcap.reader import make_reader

from console.core.datadir import DataDir
from console.recording.lab_feed import feed_grasp
from console.core.model import model_for
from console.scene.obstacle_view import hatch_segments, obstacle_geometry
from console.scene.plan_view import outcome_html
from console.recording.recorder import Recorder, load_recording
from console.core.state import StateStore
from console.core.table_scene import TableObject, parse_scene, scene_from_json, scene_to_json
from core.planning.obstacles import Obstacle
from core.robots import load
from arm_gaps import dense_gap, swept
from fakes import FakeClient
from test_planner_console import click_at, gated, user, wait_for  # noqa: F401 (fixture)

ROBOT = load("soft-arm")
CUP = TableObject("Cup", -0.2, 0.2, 0.0165)
POST = Obstacle("Post", -0.07, 0.21, 0.015)
OUT_OF_THE_WAY = (0.15, 0.15)  # a 20 mm obstacle here: the demo object's plan is ~0 s CPU


def test_scene_json_round_trips_obstacles_and_old_files_load_without_them():
    text = scene_to_json([CUP], [POST, Obstacle("Wall", 0.2, 0.3, 0.05)])
    scene = parse_scene(text, ROBOT)
    assert scene.objects == [CUP]
    assert scene.obstacles == [POST, Obstacle("Wall", 0.2, 0.3, 0.05)]
    assert json.loads(text)["obstacles"][0] == {"name": "Post", "x": -0.07, "y": 0.21,
                                                "r": 0.015}
    old = json.dumps({"objects": [{"name": "Cup", "x": -0.2, "y": 0.2, "r": 0.0165}]})
    assert parse_scene(old, ROBOT).obstacles == [] and scene_from_json(old, ROBOT) == [CUP]
    for bad, words in (
            ('{"objects": [], "obstacles": [{"name": "a", "x": -0.1, "y": 0.2, "r": -0.02}]}',
             "radius must be positive"),
            ('{"objects": [], "obstacles": [{"name": "a", "x": NaN, "y": 0.2, "r": 0.02}]}',
             "finite"),
            ('{"objects": [], "obstacles": [{"name": "a", "x": 0.0, "y": 0.0, "r": 0.02}]}',
             "on the arm's base"),
            ('{"objects": [], "obstacles": [{"x": 0.1}]}', "not a scene")):
        with pytest.raises(ValueError, match=words):
            parse_scene(bad, ROBOT)


def test_obstacle_drawing_hatches_inside_the_disk_and_rings_at_the_clearance():
    seg = hatch_segments(0.1, 0.2, 0.02, 0.06)
    assert len(seg) >= 4
    d = np.hypot(seg[..., 0] - 0.1, seg[..., 1] - 0.2)
    assert np.all(d <= 0.02 + 1e-12) and np.allclose(d, 0.02)        # chords of the top
    assert np.allclose(seg[:, 1, 0] - seg[:, 0, 0], seg[:, 1, 1] - seg[:, 0, 1])  # 45 deg
    g = obstacle_geometry([POST], 0.01)
    ring = np.hypot(g["rings"][..., 0] - POST.x, g["rings"][..., 1] - POST.y)
    np.testing.assert_allclose(ring, POST.r + 0.01, atol=1e-12)


def test_operator_places_an_obstacle_by_click_and_the_plan_keeps_the_clearance(gated):
    from console.panels.soft_arm.objects import ObjectsPanel
    from console.panels.soft_arm.planner import PlannerPanel

    app, s = gated, gated.grasp_session
    op, pp = app.panel(ObjectsPanel), app.panel(PlannerPanel)
    operator = FakeClient(31)
    app.access.take(operator.client_id, "tok", name="Alice")
    wait_for(lambda: s.view().objects)
    user(op.click_place, operator, "Obstacle")
    click_at(op, operator, POST.x, POST.y)
    view = wait_for(lambda: (v := s.view()).obstacles and v)
    assert [(o.name, o.x, o.y) for o in view.obstacles] == [("Obstacle 1", POST.x, POST.y)]
    assert view.objects[0].name == "Object 1" and len(view.objects) == 1   # no object placed
    user(op.obstacles.r, operator, 15.0)                                  # mm
    wait_for(lambda: s.view().obstacles[0].r == pytest.approx(0.015))
    user(pp.clearance, operator, 10.0)
    assert s.clearance == pytest.approx(0.010)
    user(pp.plan_button, operator)
    # the click's own re-plan (20 mm radius, in the way) may spend its whole ~3.6 s CPU search
    # budget first: on busy cores, many seconds
    out = wait_for(lambda: (o := s.view().outcome) and o.plan and o.plan.obstacles and o,
                   timeout=60.0)
    assert out.plan.success
    assert np.all(out.plan.obstacle_path_clearance >= 0.010)
    assert 'data-obstacle-mm="' in outcome_html(out)
    # Drawn: one obstacle body, hatching and a ring at r + clearance.
    layer = app.grasp_scene.obstacle_layer
    wait_for(lambda: len(layer.bodies) == 1 and layer.rings is not None)
    ring = np.hypot(layer.rings.points[..., 0] - POST.x, layer.rings.points[..., 1] - POST.y)
    np.testing.assert_allclose(ring, 0.015 + 0.010, atol=1e-6)   # float32 in viser
    # A click on it selects it; the editor removes it.
    click_at(op, operator, POST.x + 0.005, POST.y)
    assert len(s.view().obstacles) == 1
    user(op.obstacles.remove_button, operator)
    wait_for(lambda: not s.view().obstacles and not layer.bodies and layer.rings is None)


def test_bad_obstacle_input_is_refused_with_a_message_and_changes_nothing(gated):
    from console.panels.soft_arm.objects import ObjectsPanel
    from console.panels.soft_arm.planner import PlannerPanel

    app, s = gated, gated.grasp_session
    op, pp = app.panel(ObjectsPanel), app.panel(PlannerPanel)
    operator = FakeClient(41)
    app.access.take(operator.client_id, "tok", name="Alice")
    user(op.click_place, operator, "Obstacle")
    click_at(op, operator, 0.0, 0.01)                    # on the arm's base
    assert not s.view().obstacles
    assert any("on the arm's base" in body for _, body in operator.notes)
    click_at(op, operator, -0.1, 0.3)
    wait_for(lambda: s.view().obstacles)
    before = s.view().obstacles
    for value, words in ((-5.0, "radius must be positive"), (math.nan, "finite")):
        user(op.obstacles.r, operator, value)
        assert s.view().obstacles == before
        assert any(words in body for _, body in operator.notes)
        assert op.obstacles.r.value == pytest.approx(before[0].r * 1e3)   # put back
    user(pp.clearance, operator, -3.0)
    assert s.clearance == pytest.approx(0.010) and pp.clearance.value == pytest.approx(10.0)
    assert any("clearance must be between" in body for _, body in operator.notes)


def test_a_grasp_echo_between_a_typed_value_and_its_callback_cannot_smuggle_it_in(gated):
    """viser stores a browser's value before its callback runs (in a thread pool) while the
    grasp worker echoes the session into the same fields: a bad radius typed then must still be
    refused and put back to the obstacle's radius, whether the echo lands between the store and
    the callback or the callback runs while the echo is writing (a CI run put back NaN)."""
    import viser

    from console.panels.soft_arm.objects import ObjectsPanel

    app, s = gated, gated.grasp_session
    op = app.panel(ObjectsPanel)
    ed = op.obstacles
    operator = FakeClient(43)
    app.access.take(operator.client_id, "tok", name="Alice")
    user(op.click_place, operator, "Obstacle")
    click_at(op, operator, -0.1, 0.3)
    wait_for(lambda: s.view().obstacles)
    before = s.view().obstacles
    radius_mm = before[0].r * 1e3

    def callback(value: float) -> None:
        for cb in list(ed.r._impl.update_cb):
            cb(viser.GuiEvent(client=operator, client_id=operator.client_id,  # type: ignore[arg-type]
                              target=ed.r))

    # 1. The echo between viser's store and the callback.
    ed.r._impl.value = math.nan
    ed.refresh(s.view())
    callback(math.nan)
    assert s.view().obstacles == before
    assert sum("finite" in body for _, body in operator.notes) == 1
    assert ed.r.value == pytest.approx(radius_mm)
    # 2. The callback runs while the echo writes the fields (here: from inside its write of
    #    the dropdown, as another thread's callback may).
    ed.r._impl.value = -5.0
    ed.selected._impl.value = "(none)"  # so the echo writes the dropdown back
    ed.selected.on_update(lambda _: callback(-5.0) if ed.r.value == -5.0 else None)
    ed.refresh(s.view())
    assert s.view().obstacles == before
    assert any("radius must be positive" in body for _, body in operator.notes)
    assert ed.r.value == pytest.approx(radius_mm)


def test_viewers_cannot_place_change_or_remove_obstacles(gated):
    from console.panels.soft_arm.objects import ObjectsPanel
    from console.panels.soft_arm.planner import PlannerPanel

    app, s = gated, gated.grasp_session
    op, pp = app.panel(ObjectsPanel), app.panel(PlannerPanel)
    viewer, operator = FakeClient(51), FakeClient(52)
    app.access.take(operator.client_id, "tok", name="Alice")
    user(op.click_place, operator, "Obstacle")
    click_at(op, operator, -0.1, 0.3)
    before = wait_for(lambda: s.view().obstacles)
    click_at(op, viewer, 0.1, 0.3)
    user(op.obstacles.r, viewer, 40.0)
    user(op.obstacles.remove_button, viewer)
    user(pp.clearance, viewer, 50.0)
    user(op.click_place, viewer, "Nothing")
    assert s.view().obstacles == before and s.clearance == pytest.approx(0.010)
    assert op.obstacles.r.value == pytest.approx(before[0].r * 1e3)
    assert pp.clearance.value == pytest.approx(10.0) and op.click_place.value == "Obstacle"
    refused = {body.split(" — ")[0].removeprefix("Only the operator can ")
               for title, body in viewer.notes if title == "Not allowed"}
    assert refused == {"place or select an obstacle", "edit an obstacle", "remove an obstacle",
                       "change the planner", "change how clicks on the table act"}


def test_the_session_records_obstacles_and_a_replay_shows_them(gated, tmp_path):
    from console.panels.soft_arm.objects import ObjectsPanel
    from console.playback.replay import ReplaySession  # noqa: F401 (the replay draws what this reads)

    app, s = gated, gated.grasp_session
    model = model_for(ROBOT)
    rec = Recorder(DataDir(tmp_path), model)
    path = rec.start("obstacles")
    rec.on_state(StateStore(model).request(np.zeros(6), "init"))
    logged = []
    app.recorder = SimpleNamespace(log=lambda kind, data, *a: logged.append((kind, data)),
                                   action=lambda *a, **k: None)
    op = app.panel(ObjectsPanel)
    operator = FakeClient(61)
    app.access.take(operator.client_id, "tok", name="Alice")
    user(op.click_place, operator, "Obstacle")
    click_at(op, operator, POST.x, POST.y)
    wait_for(lambda: any(k == "objects" and d["obstacles"] for k, d in logged))
    kind, data = next((k, d) for k, d in logged if k == "objects" and d["obstacles"])
    assert data["obstacles"] == [{"name": "Obstacle 1", "x": POST.x, "y": POST.y, "r": 0.02}]
    assert data["clearance"] == pytest.approx(0.010)
    # The same feed into a real MCAP recording, read back with the mcap reader ...
    feed_grasp(rec, s.view(), {"obstacles"})
    rec.stop()
    got: dict[str, list] = {}
    with open(path, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages():
            got.setdefault(ch.topic, []).append(json.loads(m.data))
    assert got["/objects"][-1]["obstacles"][0]["name"] == "Obstacle 1"
    ents = {e["id"]: e for e in got["/scene/objects"][-1]["entities"]}
    cyl = ents["obstacles"]["cylinders"][0]
    assert cyl["size"]["x"] == pytest.approx(0.04) and cyl["pose"]["position"]["x"] == POST.x
    assert len(ents["obstacles"]["lines"]) == 1                      # the clearance ring
    # ... and what a replay draws: the newest obstacles at a time.
    loaded = load_recording(path, model)
    last = max(e.t for e in loaded.events if e.kind == "objects")
    assert loaded.obstacles_until(last - 1e-6) is None          # not yet at that time
    shown = loaded.obstacles_until(last)
    assert shown["obstacles"][0]["x"] == POST.x and shown["clearance"] == pytest.approx(0.01)


def test_execute_needs_the_plan_around_the_obstacles():
    from console.panels.soft_arm.control_text import execute_target
    from console.core.grasp_state import Outcome, SessionView
    from core.planning.grasp import plan_grasp

    obj = TableObject("Object 1", CUP.x, CUP.y, CUP.r)
    plain = plan_grasp(ROBOT, np.zeros(6), (obj.x, obj.y), obj.r)
    view = SessionView((obj,), obj.name, Outcome(obj, plain, None, 1), 0, False, 1.0, False,
                       None)
    assert execute_target(view).plan is plain                      # no obstacles: as before
    with_post = dataclasses.replace(view, obstacles=(POST,), clearance=0.01)
    with pytest.raises(ValueError, match="Obstacles are on the table"):
        execute_target(with_post)                                  # a plan that ignores POST
    around = plan_grasp(ROBOT, np.zeros(6), (obj.x, obj.y), obj.r, obstacles=[POST],
                        clearance=0.01)
    ok = dataclasses.replace(with_post, outcome=Outcome(obj, around, None, 2))
    assert execute_target(ok).plan is around
    refused = dataclasses.replace(with_post, outcome=Outcome(obj, None, "Post is in the way", 3))
    with pytest.raises(ValueError, match="Post is in the way"):
        execute_target(refused)


def test_a_replay_draws_the_recorded_obstacles_and_skips_bad_entries():
    import viser

    from console.scene.obstacle_view import draw_recorded_obstacles

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        record = {"obstacles": [{"name": "Post", "x": -0.07, "y": 0.21, "r": 0.015},
                                {"name": "bad", "x": "?", "y": 0.0, "r": 0.02},
                                {"name": "nan", "x": math.nan, "y": 0.0, "r": 0.02}],
                  "clearance": 0.01}
        nodes = draw_recorded_obstacles(server.scene, record, "/replay/obstacles")
        assert len(nodes) == 2                               # body + hatch/ring of Post only
        body, lines = nodes
        np.testing.assert_allclose(body.position[:2], (-0.07, 0.21))
        ring = lines.points[-72:]                            # the clearance ring comes last
        np.testing.assert_allclose(np.hypot(ring[..., 0] + 0.07, ring[..., 1] - 0.21), 0.025,
                                   atol=1e-6)
        assert draw_recorded_obstacles(server.scene, None, "/replay/obstacles") == []
    finally:
        server.stop()


def test_a_placed_obstacle_is_drawn_and_recorded_before_its_re_plan_ends(gated):
    """Placing an obstacle re-plans the selected object (seconds with obstacles): the obstacle
    shows and is recorded at once, not after that plan (it used to wait for it)."""
    import threading

    from console.panels.soft_arm.objects import ObjectsPanel

    app, s = gated, gated.grasp_session
    logged = []
    app.recorder = SimpleNamespace(log=lambda kind, data, *a: logged.append((kind, data)),
                                   action=lambda *a, **k: None)
    release, planning = threading.Event(), threading.Event()
    # the demo object's plan at start first: held by slow_plan, it would hold the edit behind it
    # (a loaded run patched the planner before that plan began: "condition not reached")
    wait_for(lambda: s.view().outcome)
    plan = s.planner.plan

    def slow_plan(*args, **kwargs):
        planning.set()
        release.wait(20.0)
        return plan(*args, **kwargs)

    s.planner.plan = slow_plan
    op = app.panel(ObjectsPanel)
    operator = FakeClient(62)
    app.access.take(operator.client_id, "tok", name="Alice")
    try:
        user(op.click_place, operator, "Obstacle")
        # Out of the way: the re-plan around it needs no search once released (at POST, with
        # the 20 mm radius a click gives, the search spends its whole ~3.6 s CPU budget, which
        # on four busy workers took longer than this test waited).
        click_at(op, operator, *OUT_OF_THE_WAY)
        wait_for(lambda: any(k == "objects" and d["obstacles"] for k, d in logged))
        # the re-plan may begin a moment after the obstacle is recorded (its pool's thread; a
        # loaded run read `planning` before the planner was called): it cannot end before
        # `release`, so the obstacle was recorded before the re-plan's end either way
        wait_for(planning.is_set)
        assert not release.is_set()   # the re-plan is still running
        # the demo object's own records (objects, then its plan) may land in `logged` too when
        # the session's first publish came after the recorder was swapped (fresh33): only what
        # follows the obstacle's record counts
        first = next(i for i, (k, d) in enumerate(logged) if k == "objects" and d["obstacles"])
        assert not any(k == "plan" for k, _ in logged[first:])
    finally:
        release.set()
    wait_for(lambda: any(k == "plan" for k, _ in logged), timeout=60.0)


def test_an_obstacle_clicked_between_arm_and_object_is_planned_around(gated):
    """A click with "Table click places: Obstacle" between the straight arm (x = 0) and Object 1,
    then Plan grasp: every arm and gripper point between waypoints keeps the clearance from it,
    where the plain Algorithm 1 plan for the same object would not (the plan goes around it);
    the summary the page shows says so (was tests/browser/test_obstacle_browser.py)."""
    from console.panels.soft_arm.objects import ObjectsPanel
    from console.panels.soft_arm.planner import PlannerPanel
    from core.planning.grasp import plan_grasp

    spot = (-0.062, 0.188)
    app, s = gated, gated.grasp_session
    op, pp = app.panel(ObjectsPanel), app.panel(PlannerPanel)
    operator = FakeClient(41)
    app.access.take(operator.client_id, "tok", name="Alice")
    wait_for(lambda: s.view().outcome)
    assert [(o.x, o.y) for o in s.view().objects] == [(-0.2, 0.2)]
    user(op.click_place, operator, "Obstacle")
    click_at(op, operator, *spot)
    (obs,) = wait_for(lambda: s.view().obstacles)
    assert math.hypot(obs.x - spot[0], obs.y - spot[1]) < 1e-9
    assert len(s.view().objects) == 1  # an obstacle, not an object
    wait_for(lambda: 'data-count="1"' in op.obstacles.info.content)
    user(pp.plan_button, operator)
    out = wait_for(lambda: (o := s.view().outcome) and o.plan is not None and o.plan.obstacles
                   and o, timeout=60.0)
    plan, clearance = out.plan, s.view().clearance
    assert clearance == pytest.approx(0.010)
    assert plan.success, plan.summary()
    gaps = dense_gap(ROBOT, swept(plan.kappa_meas, plan.kappas), obs.x, obs.y, obs.r)
    assert gaps.min() >= clearance - 1e-9, gaps.min()
    plain = plan_grasp(ROBOT, plan.kappa_meas, plan.center, plan.radius)
    assert dense_gap(ROBOT, swept(plain.kappa_meas, plain.kappas), obs.x, obs.y, obs.r).min() \
        < clearance
    summary = outcome_html(out)
    assert 'data-state="ok"' in summary and "from the obstacles" in summary
    mm = float(summary.split('data-obstacle-mm="')[1].split('"')[0])
    assert mm >= 10.0 - 1e-6
    assert not any(title == "Not allowed" for title, _ in operator.notes)
