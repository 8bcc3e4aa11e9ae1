"""The extensible arm's Obstacles panel: the operator adds / selects / updates / removes boxes
(typed or by a table click), sets the clearance, saves and loads them; bad input and viewers
change nothing; the boxes are drawn, reach the tip target and the path planner (which refuse
with the box's name when blocked), and are recorded (read back with the ``mcap`` reader)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from core.kinematics import box_clearance as bc
from core.kinematics import delta as dk
from core.planning.box_scene import BoxScene, scene_from_json, scene_to_json
from core.robots import load
from fakes import FakeRunner, SyncPool, user

EXT = load("extensible")


def type_box(panel, client, name, centre_mm, size_mm):
    user(panel.name, client, name)
    for h, v in zip(panel.centre, centre_mm):
        user(h, client, v)
    for h, v in zip(panel.size, size_mm):
        user(h, client, v)


@pytest.fixture
def gated(server):
    from fakes import console_app

    from console.core.access import AccessControl
    from console.panels.extensible.panel_set import EXTENSIBLE_PANELS

    app = console_app(EXT, server, panels=EXTENSIBLE_PANELS, extensible_runner=FakeRunner(),
                      access=AccessControl("tok"))
    try:
        yield app
    finally:
        app.stop()


def state_of(html: str, key: str = "state") -> str:
    return re.search(rf'data-{key}="([^"]*)"', html).group(1)


def test_operator_places_edits_and_removes_boxes_and_bad_input_changes_nothing(gated):
    from fakes import FakeClient

    from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel, box_scene_of

    app = gated
    panel = app.panel(BoxObstaclesPanel)
    op = FakeClient(1)
    app.access.take(op.client_id, "tok", name="Alice")
    type_box(panel, op, "Shelf", (200, 0, 250), (200, 300, 20))
    user(panel.add_button, op)
    scene, v1 = box_scene_of(app)
    assert scene.boxes == (bc.Box("Shelf", (0.2, 0.0, 0.25), (0.2, 0.3, 0.02)),)
    assert len(panel._handles) == 1
    np.testing.assert_allclose(panel._handles[0].position, (0.2, 0.0, 0.25))
    assert state_of(panel.info.content, "names") == "Shelf"
    assert state_of(panel.info.content, "selected") == "Shelf"
    # Bad input: a clear message, nothing changes.
    for size, why in (((200, 0, 20), "size must be > 0"), ((200, -5, 20), "size must be > 0")):
        type_box(panel, op, "Bad", (200, 0, 100), size)
        user(panel.add_button, op)
        assert box_scene_of(app) == (scene, v1) and why in op.notes[-1][1]
    type_box(panel, op, "Base", (0, 0, 0), (100, 100, 100))
    user(panel.add_button, op)
    assert box_scene_of(app) == (scene, v1) and "contains the arm's base" in op.notes[-1][1]
    assert state_of(panel.info.content) == "error"
    panel.centre[1]._impl.value = float("nan")  # what a raw message could carry
    user(panel.add_button, op)
    assert box_scene_of(app) == (scene, v1) and "finite" in op.notes[-1][1]
    user(panel.clearance, op, -3.0)
    assert box_scene_of(app)[0].clearance == scene.clearance and "Clearance" in op.notes[-1][1]
    # Update the selected box, then a second one by a table click, then remove.
    type_box(panel, op, "Shelf", (220, 10, 240), (200, 300, 20))
    user(panel.update_button, op)
    assert box_scene_of(app)[0].get("Shelf").centre == (0.22, 0.01, 0.24)
    import viser
    user(panel.click_place, op, True)
    type_box(panel, op, "Crate", (0, 0, 0), (100, 80, 60))
    panel._on_scene_click(viser.SceneClickEvent(op, op.client_id, (0.3, -0.2, 1.0),
                                                (0.0, 0.0, -1.0), (0.5, 0.5), None))
    crate = box_scene_of(app)[0].get("Crate 1")
    np.testing.assert_allclose(crate.centre, (0.3, -0.2, 0.03))  # standing on the table
    assert len(panel._handles) == 2
    user(panel.clearance, op, 35.0)
    assert box_scene_of(app)[0].clearance == pytest.approx(0.035)
    user(panel.selected, op, "Shelf")
    user(panel.remove_button, op)
    assert box_scene_of(app)[0].names() == ["Crate 1"] and len(panel._handles) == 1


def test_the_panel_checks_boxes_at_the_base_with_the_robot_body(gated, tmp_path):
    from fakes import FakeClient

    from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel, box_scene_of

    app = gated
    panel = app.panel(BoxObstaclesPanel)
    op = FakeClient(1)
    app.access.take(op.client_id, "tok", name="Alice")
    assert box_scene_of(app)[0].body_radius == EXT.body_radius == 0.045
    # 40 mm above the base: clear of the backbone's first point, inside the 45 mm body
    type_box(panel, op, "Low", (0, 0, 90), (100, 100, 100))
    user(panel.add_button, op)
    assert box_scene_of(app)[0].boxes == () and "touches the arm's body at its base" in \
        op.notes[-1][1]
    # a loaded file is checked the same way
    text = scene_to_json(BoxScene((bc.make_box("Low", (0, 0, 0.09), (0.1, 0.1, 0.1)),), 0.0))
    user(panel.load_button, op, viser_upload("low.json", text.encode()))
    assert box_scene_of(app)[0].boxes == () and "arm's body at its base" in op.notes[-1][1]
    type_box(panel, op, "High", (0, 0, 120), (100, 100, 100))           # 70 mm: body keeps 25
    user(panel.add_button, op)
    assert box_scene_of(app)[0].names() == ["High"]


def viser_upload(name: str, content: bytes):
    import viser
    return viser.UploadedFile(name, content)


def test_viewers_change_nothing_and_scene_files_round_trip(gated):
    import viser
    from fakes import FakeClient, ScopedClient

    from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel, box_scene_of

    app = gated
    panel = app.panel(BoxObstaclesPanel)
    op, viewer = FakeClient(1), FakeClient(2)
    app.access.take(op.client_id, "tok", name="Alice")
    shelf = bc.make_box("Shelf", (0.2, 0.0, 0.25), (0.2, 0.3, 0.02))
    post = bc.make_box("Post", (0.0, 0.0, 0.17), (0.04, 0.04, 0.04))
    text = scene_to_json(BoxScene((shelf, post), 0.025)).encode()
    user(panel.load_button, op, viser.UploadedFile("shelf.json", text))
    before = box_scene_of(app)
    assert before[0] == BoxScene((shelf, post), 0.025)
    user(panel.add_button, viewer)
    user(panel.remove_button, viewer)
    user(panel.update_button, viewer)
    user(panel.clearance, viewer, 5.0)
    user(panel.selected, viewer, "Post")
    user(panel.click_place, viewer, True)
    user(panel.centre[0], viewer, 999.0)
    user(panel.load_button, viewer, viser.UploadedFile("x.json", scene_to_json(BoxScene()).encode()))
    assert box_scene_of(app) == before
    assert panel.clearance.value == 25.0 and panel.selected.value == "Shelf"
    assert panel.click_place.value is False and panel.centre[0].value == 200.0
    refused = {b.split(" — ")[0].removeprefix("Only the operator can ")
               for t, b in viewer.notes if t == "Not allowed"}
    assert {"add a box", "remove a box", "change a box", "change the clearance",
            "select a box", "change how clicks on the table act", "edit a box",
            "load a box scene"} <= refused
    # A bad file is refused with its reason and changes nothing.
    bad = json.dumps({"boxes": [{"name": "A", "centre": [0, 0, 0.3], "size": [0.1, 0.1, -1]}]})
    user(panel.load_button, op, viser.UploadedFile("bad.json", bad.encode()))
    assert box_scene_of(app) == before and "Could not load bad.json" in op.notes[-1][1]
    # Save: a download for anyone, the same scene back.
    client = ScopedClient(app.server, 3)
    panel._on_save(viser.GuiEvent(client=client, client_id=3, target=panel.save_button))
    assert scene_from_json(client.downloads[0][1]) == before[0]


def test_target_and_paths_keep_clear_of_the_boxes_or_say_which_box_blocks(gated, monkeypatch):
    from fakes import FakeClient

    from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel
    from console.panels.extensible.paths import PathsPanel
    from console.panels.extensible.target import TargetPanel

    app = gated
    obstacles, target, paths = (app.panel(BoxObstaclesPanel), app.panel(TargetPanel),
                                app.panel(PathsPanel))
    monkeypatch.setattr(target, "_ik_pool", lambda: SyncPool())
    monkeypatch.setattr(paths, "_plan_pool", lambda: SyncPool())
    op = FakeClient(1)
    app.access.take(op.client_id, "tok", name="Alice")
    ceiling = bc.make_box("Ceiling", (0.0, 0.0, 0.26), (2.0, 2.0, 0.02))
    obstacles.set_scene(BoxScene((ceiling,), 0.02), "Ceiling")
    app.store.request(np.zeros((EXT.n_segments, 3)) + [0, 0, 0.04], "jog")  # 180 mm, straight
    q_before = np.array(app.store.command.q)
    assert bc.clearance_of(EXT, q_before, [ceiling]).clear_of(0.02)  # the start pose is clear
    target.solve(np.array([0.2, 0.0, 0.32]), True, op.client_id, target.worker.generation)
    status = target.status.content
    assert state_of(status) == "blocked" and "Ceiling" in status and "Not moved" in status
    assert app.hold.target() is None and np.array_equal(app.store.command.q, q_before)
    # A shelf beside the arm: the target over it is reached with the arm's body clear (120 mm
    # above the board: at 60 mm the 45 mm body radius would leave 15 mm < the clearance).
    shelf = bc.make_box("Shelf", (0.2, 0.0, 0.25), (0.2, 0.3, 0.02))
    obstacles.set_scene(BoxScene((shelf,), 0.02), "Shelf")
    target.solve(np.array([0.2, 0.0, 0.38]), True, op.client_id, target.worker.generation)
    status = target.status.content
    assert state_of(status) == "reachable", status
    assert state_of(status, "target-mm") == "200.0,0.0,380.0"   # which target this answers
    assert float(state_of(status, "clearance-mm")) >= 20.0
    goal = app.hold.target()
    assert goal is not None
    legs = [goal] + target._legs[1]
    assert bc.clearance_of(EXT, legs[-1], [shelf]).clear_of(0.02)
    np.testing.assert_allclose(dk.tip_position(EXT, legs[-1]), [0.2, 0.0, 0.38], atol=1e-3)
    chain = dk.robot_rack_lengths(EXT, np.stack([q_before, *legs]))
    assert bc.motion_clearance(EXT, chain, [shelf]).clear_of(0.02)
    app.stop_motion("test")  # the one STOP: the hold ends, the target panel lets go
    # A path through a box is refused by the planner, naming it.
    post = bc.make_box("Post", (0.1, 0.0, 0.1), (0.04, 0.04, 0.04))  # on the tip's way in x
    obstacles.set_scene(BoxScene((post,), 0.02), "Post")
    app.store.request(np.zeros((EXT.n_segments, 3)), "jog")  # retracted: tip at z = 100 mm
    assert bc.clearance_of(EXT, app.store.command.q, [post]).clear_of(0.02)
    paths.size.value = 300.0
    paths.plane.value = "xz"
    paths.kind.value = "linear"
    paths._request_plan(execute=False)
    assert state_of(paths.status.content) == "blocked", paths.status.content
    assert "box &#x27;Post&#x27;" in paths.status.content
    assert paths._current_request().obstacles == obstacles.current()[1]


def test_a_route_leg_starts_only_for_the_operator_and_a_refusal_moves_nothing(gated):
    from fakes import FakeClient

    from console.panels.extensible.target import TargetPanel

    app = gated
    target = app.panel(TargetPanel)
    op = FakeClient(1)
    q = np.zeros((EXT.n_segments, 3))
    first, second = q + [0, 0, 0.01], q + [0, 0, 0.02]
    said = "Stopped on the way: you no longer hold control."
    assert not target._start_leg(op.client_id, [first, second], said)  # nobody holds control
    assert target._legs == (0, []) and target._moving_to is None
    assert app.hold.target() is None and said in target.status.content
    app.access.take(op.client_id, "tok", name="Alice")
    assert target._start_leg(op.client_id, [first, second], said)
    client_id, rest = target._legs
    assert client_id == op.client_id and len(rest) == 1 and np.array_equal(rest[0], second)
    np.testing.assert_allclose(app.hold.target(), first)
    np.testing.assert_allclose(target._moving_to, first)
    app.stop_motion("test")  # the one STOP: the hold ends, the target panel lets go


def test_a_target_asked_for_before_a_stop_never_moves_the_arm(gated):
    """A solve under way when STOP comes (the worker took the target under the older stop
    generation) starts no move after it: the core refuses it under the same lock as STOP."""
    from fakes import FakeClient

    from console.panels.extensible.target import TargetPanel

    app = gated
    target = app.panel(TargetPanel)
    op = FakeClient(1)
    app.access.take(op.client_id, "tok", name="Alice")
    taken = app.core.stop_generation  # the worker takes the target ...
    app.stop_motion("STOP pressed by Bob")  # ... STOP while it solves ...
    goal = np.zeros((EXT.n_segments, 3)) + [0, 0, 0.01]
    assert not target._start_leg(op.client_id, [goal], "refused", taken)  # ... then no move
    assert app.hold.target() is None and target._moving_to is None
    assert "motion stopped (STOP pressed by Bob)" in target.status.content


def test_boxes_are_recorded_and_read_back_with_the_mcap_reader(gated, tmp_path):
    from fakes import FakeClient
    from mcap.reader import make_reader

    from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel

    app = gated
    panel = app.panel(BoxObstaclesPanel)
    op = FakeClient(1)
    app.access.take(op.client_id, "tok", name="Alice")
    type_box(panel, op, "Shelf", (200, 0, 250), (200, 300, 20))
    user(panel.add_button, op)  # before the recording: logged when it starts
    path = app.recorder.start("boxes", op)
    type_box(panel, op, "Wall", (-250, 0, 200), (20, 300, 400))
    user(panel.add_button, op)
    app.recorder.stop()
    records, cubes = [], []
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            data = json.loads(message.data)
            if channel.topic == "/console/boxes":
                records.append(json.loads(data["data"]))  # JSON text
            elif channel.topic == "/scene/boxes":
                cubes.append(data["entities"][0]["cubes"])
    assert [[b["name"] for b in r["boxes"]] for r in records] == [["Shelf"], ["Shelf", "Wall"]]
    assert records[-1]["boxes"][1] == {"name": "Wall", "centre": [-0.25, 0.0, 0.2],
                                       "size": [0.02, 0.3, 0.4]}
    assert records[-1]["clearance"] == pytest.approx(0.02)
    assert scene_from_json(json.dumps(records[-1])).names() == ["Shelf", "Wall"]
    assert [c["size"] for c in cubes[-1]] == [{"x": 0.2, "y": 0.3, "z": 0.02},
                                              {"x": 0.02, "y": 0.3, "z": 0.4}]


def _surface_distance_mm(delta: np.ndarray, centre_mm, size_mm) -> float:
    """Smallest distance (mm) from the arm's body at ``delta`` to the box: the backbone's,
    sampled every 0.5 mm with the forward kinematics (an arc fraction s of segment i is segment i
    with (s dx, s dy, s L)), measured by clipping, minus the robot file's body radius --
    independent of core.kinematics.box_clearance."""
    import math

    lo = (np.array(centre_mm) - np.array(size_mm) / 2) / 1e3
    hi = (np.array(centre_mm) + np.array(size_mm) / 2) / 1e3
    frames = dk.forward_kinematics(delta, EXT.L0, EXT.d)
    pts = [np.zeros((1, 3))]
    for i, (dx, dy, dl) in enumerate(delta):
        length = EXT.L0 + dl
        s = np.linspace(0.0, 1.0, int(math.ceil(length / 5e-4)) + 1)[1:]
        part = np.stack([s * dx, s * dy, s * length - EXT.L0], axis=-1)
        pts.append((frames[i] @ dk.segment_transform(part, EXT.L0, EXT.d))[:, :3, 3])
    p = np.vstack(pts)
    outside = np.linalg.norm(p - np.clip(p, lo, hi), axis=-1)
    inside = np.minimum(p - lo, hi - p).min(axis=-1)
    return float((np.where(outside > 0, outside, -inside).min() - EXT.body_radius) * 1e3)


def test_a_typed_shelf_and_a_typed_target_over_it_are_reached_clear_of_it(gated, monkeypatch):
    """The operator types a shelf board in the Obstacles panel and a tip target 120 mm above it
    (was tests/browser/test_browser_boxes.py): the panel lists the shelf with the default 20 mm
    clearance, the target is answered reachable with >= 20 mm and names the shelf, and the
    posture the arm is sent to has its tip at the target and its body (sampled here every
    0.5 mm) >= 20 mm from the board, which the plain IK's posture would cut through."""
    from fakes import FakeClient

    from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel
    from console.panels.extensible.target import TargetPanel
    from core.kinematics.delta_ik import solve_tip_ik
    from tests.ws_client import wait_for

    centre, size, target_mm = (200.0, 0.0, 250.0), (200.0, 300.0, 20.0), (200.0, 0.0, 380.0)
    plain = solve_tip_ik(EXT, np.array(target_mm) / 1e3)
    assert plain.reachable and _surface_distance_mm(plain.delta, centre, size) < 0  # a detour
    app = gated
    obstacles, target = app.panel(BoxObstaclesPanel), app.panel(TargetPanel)
    monkeypatch.setattr(target, "_ik_pool", lambda: SyncPool())
    op = FakeClient(1)
    app.access.take(op.client_id, "tok", name="Alice")
    type_box(obstacles, op, "Shelf", centre, size)
    user(obstacles.add_button, op)
    info = obstacles.info.content
    assert state_of(info, "count") == "1" and state_of(info, "names") == "Shelf"
    assert float(state_of(info, "clearance-mm")) == 20.0
    for handle, value in zip(target.inputs, target_mm):
        user(handle, op, value)
    user(target.go, op)  # x, y, z together
    aimed = ",".join(f"{v:.1f}" for v in target_mm)
    wait_for(lambda: state_of(target.status.content, "target-mm") == aimed
             and state_of(target.status.content) in ("reachable", "blocked", "error"),
             timeout=60.0, what="the typed target solved with the shelf")
    status = target.status.content
    assert state_of(status) == "reachable", status
    assert float(state_of(status, "clearance-mm")) >= 20.0 and "Shelf" in status
    wait_for(lambda: app.hold.target() is not None, timeout=10.0, what="a move started")
    goal = app.hold.target()
    final = ([goal] + target._legs[1])[-1]
    np.testing.assert_allclose(dk.tip_position(EXT, final) * 1e3, target_mm, atol=1.0)
    assert _surface_distance_mm(final, centre, size) >= 20.0 - 0.3
    assert not any(title == "Not allowed" for title, _ in op.notes)
