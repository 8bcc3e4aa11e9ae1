"""Issue #17.3 in the console, without a browser: the bin placed by a table click (Objects panel,
"Table click places: Bin"), "Clear table into bin" (Control panel) refused with what to do --
viewer, disarmed, no bin, no objects -- and otherwise sent as one RunRow with every object and
the bin's pose; the row's progress in the header and the panel, per-object outcomes after it,
released objects taken off the table; the bin in scene JSON and recordings."""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import time

import numpy as np
import pytest
import viser

from console.core.access import AccessControl
from console.recording.lab_feed import feed_grasp
from console.panels.soft_arm import planner
from console.panels.soft_arm.control import ControlPanel
from console.panels.soft_arm.control_row import NO_BIN, NO_OBJECTS
from console.panels.soft_arm.objects import ObjectsPanel
from console.core.grasp_state import SessionView
from console.core.table_bin import (BIN_HEIGHT, TableBin, bin_point_from_scene_json, locate_bin,
                               open_box_mesh, scene_json_with_bin)
from console.core.table_scene import TableObject, scene_from_json, scene_to_json
from core.control.row import ObjectOutcome, RowObject, bin_at
from core.control.row_stack import RowReport
from core.robots import load
from tests import ws_client
from fakes import FakeClient, click_at, console_app, user
from hw_bridge.soft_arm_process import ROW_ARM_FIRST

SOFT = load("soft-arm")
BIN_XY = (0.15, 0.25)
OBJECTS = ((-0.22, 0.20), (-0.16, 0.28), (-0.08, 0.33))
R = 0.0165


def wait_for(fn, timeout=20.0):
    return ws_client.wait_for(fn, timeout)


class FakeRowControl:
    """Stands in for ControlProcess: records what the Control panel sends; ``view`` is set by
    the test."""

    alive = True
    failure = None

    def __init__(self):
        self.view = None
        self.sent: list[tuple] = []
        self.scene: list[tuple] = []  # per row: the right finger's bin pose, obstacles, clearance

    def run_row(self, row_id, objects, bin_xy, bin_kappa, bin_kappa_right=(), obstacles=(),
                clearance=0.0):
        self.sent.append((row_id, [tuple(o) for o in objects], tuple(bin_xy), tuple(bin_kappa)))
        self.scene.append((tuple(bin_kappa_right), tuple(obstacles), clearance))
        fut = cf.Future()
        fut.set_result(None)
        return fut

    def grasp_at(self, x, y, r, obstacles=(), clearance=0.0, bin_params=None):
        self.sent.append(("grasp_at", (x, y, r), bin_params))
        fut = cf.Future()
        fut.set_result(None)
        return fut

    def execute(self, plan, x, y, r, bin_params=None):
        self.sent.append(("execute", (x, y, r), bin_params))
        fut = cf.Future()
        fut.set_result(None)
        return fut

    def stop_arm(self, reason="operator STOP"):
        self.sent.append(("stop", reason))
        fut = cf.Future()
        fut.set_result(None)
        return fut

    def goto(self, q):
        self.sent.append(("goto", tuple(q)))
        fut = cf.Future()
        fut.set_result(None)
        return fut

    def view_age(self):
        return 0.0

    def restart(self, timeout=5.0):
        pass

    def close(self):
        pass


def view_with(armed=True, phase="idle", row=None, waypoint=0, n_waypoints=0):
    from test_control_console import fake_view
    v = fake_view(armed=armed, phase=phase, device="sim", link=False)
    c = dataclasses.replace(v.snapshot.control, waypoint=waypoint, n_waypoints=n_waypoints)
    return dataclasses.replace(v, snapshot=dataclasses.replace(v.snapshot, control=c), row=row)


@pytest.fixture
def rig(monkeypatch):
    monkeypatch.setattr(planner.GraspSession, "compute_reach", False)
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    ctl = FakeRowControl()
    app = console_app(SOFT, srv, panels=(ObjectsPanel,), soft_control=ctl,
                      access=AccessControl("tok"))
    control = app.add_panel(ControlPanel)
    control._pump_stop.set()  # the test shows views itself
    control._pump.join(2.0)
    operator, viewer = FakeClient(1), FakeClient(2)
    app.access.take(operator.client_id, "tok", name="Alice")
    try:
        yield app, app.panel(ObjectsPanel), control, ctl, operator, viewer
    finally:
        control.close()
        app.grasp_session.close()
        app.grasp_session._thread.join(5)
        srv.stop()


def place_scene(app, objects_panel, operator):
    """Three objects by clicks (Object 1 is there already: moved onto the first spot), then the
    bin by a click with "Table click places: Bin"."""
    s = app.grasp_session
    s.update("Object 1", x=OBJECTS[0][0], y=OBJECTS[0][1])
    for xy in OBJECTS[1:]:
        click_at(objects_panel, operator, *xy)
    wait_for(lambda: len(s.view().objects) == 3)
    user(objects_panel.click_place, operator, "Bin")
    click_at(objects_panel, operator, *BIN_XY)
    return wait_for(lambda: s.view().bin)


def show(control, view):
    control.ctl.view = view
    control._show(view)


def test_a_click_places_the_bin_the_arm_can_hold_an_object_over(rig):
    app, objects_panel, _, _, operator, viewer = rig
    table_bin = place_scene(app, objects_panel, operator)
    assert len(app.grasp_session.view().objects) == 3  # the bin click placed no object
    expected = bin_at(SOFT, *BIN_XY)
    assert (table_bin.x, table_bin.y) == BIN_XY
    np.testing.assert_allclose(table_bin.kappa, expected.kappa, atol=1e-9)
    assert table_bin.drop_radius == SOFT.bin.drop_radius_m
    back = table_bin.params()  # and back to what the state machine reads
    np.testing.assert_allclose(back.kappa, expected.kappa, atol=1e-9)
    assert back.drop_radius_m == expected.drop_radius_m
    assert (back.kappa_right is None) == (expected.kappa_right is None)
    if expected.kappa_right is not None:
        np.testing.assert_allclose(back.kappa_right, expected.kappa_right, atol=1e-9)
    box = app.grasp_scene.bin_view
    wait_for(lambda: box.shown == table_bin)
    assert box.label.visible and tuple(box.box.position[:2]) == pytest.approx(BIN_XY)
    from console.panels.common.view import legend_html
    assert "Bin: where" in legend_html("planar") and "Clear table into bin" in legend_html("planar")
    wait_for(lambda: 'data-bin="150,250"' in objects_panel.info.content)
    # Out of reach: refused with the reason, the bin stays where it was.
    click_at(objects_panel, operator, 0.6, 0.1)
    wait_for(lambda: any(t == "Bin" for t, _ in operator.notes))
    assert any("Not placed: The bin at (600, 100) mm is out of reach" in b
               for _, b in operator.notes)
    time.sleep(0.2)
    assert app.grasp_session.view().bin == table_bin
    # A viewer may neither switch what clicks place nor place the bin.
    user(objects_panel.click_place, viewer, "Object")
    assert objects_panel.click_place.value == "Bin"
    click_at(objects_panel, viewer, -0.1, 0.3)
    time.sleep(0.3)
    assert app.grasp_session.view().bin == table_bin
    refused = {b.split(" — ")[0] for t, b in viewer.notes if t == "Not allowed"}
    assert refused == {"Only the operator can change how clicks on the table act",
                       "Only the operator can place the bin"}


def test_clear_table_into_bin_is_refused_with_what_to_do(rig):
    app, objects_panel, control, ctl, operator, viewer = rig
    button = control.row.button
    show(control, view_with(armed=False))
    user(button, viewer)
    assert any("Only the operator can clear the table into the bin" in b for _, b in viewer.notes)
    user(button, operator)
    assert operator.notes[-1] == ("Arm first", ROW_ARM_FIRST)
    assert ROW_ARM_FIRST.startswith("Arm first (press Arm)")
    show(control, view_with(armed=True))
    user(button, operator)
    assert operator.notes[-1] == ("Place a bin first", NO_BIN)
    place_scene(app, objects_panel, operator)
    for o in app.grasp_session.view().objects:
        app.grasp_session.remove(o.name)
    user(button, operator)
    assert operator.notes[-1] == ("Nothing to clear", NO_OBJECTS)
    assert ctl.sent == []  # nothing reached the arm


def test_the_row_is_sent_shown_and_released_objects_leave_the_table(rig):
    app, objects_panel, control, ctl, operator, _ = rig
    table_bin = place_scene(app, objects_panel, operator)
    names = tuple(o.name for o in app.grasp_session.view().objects)
    assert names == ("Object 1", "Object 2", "Object 3")
    actions = []
    app.recorder.action = lambda what, client=None, **kw: actions.append(what)
    show(control, view_with(armed=True))
    user(control.row.button, operator)
    assert actions == ["clear table into bin: 3 objects into the bin at (150, 250) mm"]
    (row_id, objects, bin_xy, kappa), = ctl.sent
    assert objects == [(x, y, R) for x, y in OBJECTS]  # every object, in the panel's order
    assert bin_xy == BIN_XY and kappa == table_bin.kappa
    assert operator.notes[-1][0] == "Clear table into bin"
    assert "3 objects into the bin at (150, 250) mm" in operator.notes[-1][1]

    rows = [RowObject(x, y, R) for x, y in OBJECTS]
    first = ObjectOutcome(0, rows[0], "released", None, 0.6, 30.0)
    running = RowReport(row_id, "running", 1, 3, (first,), None)
    show(control, view_with(phase="approach", row=running, waypoint=3, n_waypoints=9))
    header = app.header.text("phase")
    # (the time left at the row's pace: object 1 took 29.4 s; this view has no plan to time)
    assert header.startswith("object 2 of 3: approach · waypoint 4 of 9 · ARMED · ≈ ")
    assert header.endswith(" s left"), header
    status = control.row.status.content
    assert 'data-state="running"' in status and "object 2 of 3 (Object 2): approach" in status
    assert control.row.button.disabled
    wait_for(lambda: names[0] not in {o.name for o in app.grasp_session.view().objects})

    done = RowReport(row_id, "done", None, 3, (
        first, ObjectOutcome(1, rows[1], "failed", "planner refused: out of reach"),
        ObjectOutcome(2, rows[2], "released", None)), None)
    show(control, view_with(phase="released", row=done))
    left = wait_for(lambda: (v := app.grasp_session.view().objects) and len(v) == 1 and v)
    assert [o.name for o in left] == [names[1]]  # only the failed one stays on the table
    status = control.row.status.content
    assert 'data-released="2"' in status and "Row done:</b> 2 of 3 released" in status
    assert f'<li data-status="failed">{names[1]}: failed (planner refused: out of reach)</li>' \
        in status
    assert not control.row.button.disabled
    assert "object" not in app.header.text("phase")  # the panel's own phase line again
    show(control, view_with(phase="released", row=done))  # the end is recorded once
    assert actions[1:] == ["row done: 2 of 3 released -- Object 1: released; Object 2: failed "
                           "(planner refused: out of reach); Object 3: released"]

    stopped = RowReport(row_id + 1, "stopped", None, 2, (
        ObjectOutcome(0, rows[1], "failed", "operator STOP"),
        ObjectOutcome(1, rows[2], "skipped", "row stopped: operator STOP")), "operator STOP")
    show(control, view_with(phase="stopped", row=stopped))
    status = control.row.status.content
    assert "Row stopped (operator STOP)" in status
    assert "skipped (row stopped: operator STOP)" in status


def test_the_row_takes_the_right_finger_bin_pose_and_the_obstacles_along(rig):
    """The control process plans every object of the row itself (and re-plans): it gets the
    Objects panel's obstacles with the clearance, and the bin's pose for the right finger."""
    app, objects_panel, control, ctl, operator, _ = rig
    table_bin = place_scene(app, objects_panel, operator)
    expected = bin_at(SOFT, *BIN_XY)
    np.testing.assert_allclose(table_bin.kappa_right, expected.kappa_right, atol=1e-9)
    s = app.grasp_session
    s.place_obstacle(-0.05, 0.40, 0.015)
    s.set_clearance(0.012)
    show(control, view_with(armed=True))
    user(control.row.button, operator)
    (right, obstacles, clearance), = ctl.scene
    assert right == table_bin.kappa_right and len(right) == SOFT.n_segments
    assert [(o.name, o.x, o.y, o.r) for o in obstacles] == [("Obstacle 1", -0.05, 0.40, 0.015)]
    assert clearance == 0.012


def test_the_bin_in_scene_json_and_recordings_and_old_files_load():
    table_bin = locate_bin(SOFT, *BIN_XY)
    objects = [TableObject("cup", -0.2, 0.2, 0.02)]
    text = scene_json_with_bin(scene_to_json(objects), table_bin)
    assert json.loads(text)["bin"] == {"x": 0.15, "y": 0.25, "r": SOFT.bin.drop_radius_m}
    assert scene_from_json(text, SOFT) == objects and bin_point_from_scene_json(text) == BIN_XY
    old = scene_to_json(objects)  # a file from before the bin
    assert scene_from_json(old, SOFT) == objects and bin_point_from_scene_json(old) is None
    assert scene_json_with_bin(old, None) == json.dumps(json.loads(old), indent=1)
    with pytest.raises(ValueError, match="not a finite point"):
        bin_point_from_scene_json('{"objects": [], "bin": {"x": NaN, "y": 0}}')
    with pytest.raises(ValueError, match="not a point"):
        bin_point_from_scene_json('{"objects": [], "bin": {"x": 1}}')

    logged = []

    class Recorder:
        def log(self, kind, payload, client=None):
            logged.append((kind, payload))

    view = SessionView(tuple(objects), "cup", None, 0, False, 1.0, True, None,
                               bin=table_bin)
    feed_grasp(Recorder(), view, {"objects"})
    assert logged == [("objects", {"objects": [dataclasses.asdict(objects[0])],
                                   "selected": "cup", "obstacles": [], "clearance": 0.0,
                                   "bin": table_bin.record()})]
    feed_grasp(Recorder(), dataclasses.replace(view, bin=None), {"objects"})
    assert "bin" not in logged[-1][1]
    assert isinstance(table_bin, TableBin)


def test_the_bin_is_an_open_box_as_wide_as_its_drop_circle():
    v, f = open_box_mesh(0.05)
    assert v[:, :2].min() == pytest.approx(-0.05) and v[:, :2].max() == pytest.approx(0.05)
    assert v[:, 2].min() == 0.0 and v[:, 2].max() == pytest.approx(BIN_HEIGHT)
    assert f.min() == 0 and f.max() == len(v) - 1 and len(f) == 4 * 12  # four closed walls
    centroids = v[f].mean(axis=1)  # every triangle lies in a wall band: no floor, no lid
    assert np.abs(centroids[:, :2]).max(axis=1).min() >= 0.046 - 1e-9


def test_execute_takes_the_object_to_the_placed_bin(rig):
    """Execute (and Click to grasp) send the bin placed on the table with the task, so the arm
    carries the object where the plan view draws the carry; without one, the robot file's."""
    app, objects_panel, control, ctl, operator, _ = rig
    show(control, view_with(armed=True))
    event = type("E", (), {"client": operator, "client_id": operator.client_id})()
    control.execute._execute(event)
    assert ctl.sent[-1][0] in ("grasp_at", "execute") and ctl.sent[-1][2] is None  # no bin
    table_bin = place_scene(app, objects_panel, operator)
    control.execute._execute(event)
    kind, _, sent_bin = ctl.sent[-1]
    assert kind in ("grasp_at", "execute") and sent_bin == table_bin
    from hw_bridge.commands import GraspAt, bin_rows
    cmd = GraspAt(0.0, 0.0, 0.01, (), 0.0, *bin_rows(sent_bin))
    np.testing.assert_allclose(cmd.bin_kappa, bin_at(SOFT, *BIN_XY).kappa, atol=1e-9)
