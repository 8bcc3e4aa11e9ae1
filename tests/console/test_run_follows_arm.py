"""Issue 31.1 / 31.3 without a browser: while the arm runs a row of two objects, the 3D view's
plan, the Waypoints panel and the header show the plan the ARM executes (the one in the loop's
published view) with its waypoint and "object k of n"; a plan the operator makes meanwhile for
another object is drawn apart (dimmed, "Next plan"); a single Execute of the operator's own plan
shows the arm's waypoint, not the inspected one; the progress bar advances on the loop's
(simulated) time and is gone when the row is done. The loop's views are built here, as the
control process publishes them (tests/console/test_row_console.py's fake control)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from console.panels.soft_arm.waypoints import WaypointsPanel
from core.control.row import ObjectOutcome, RowObject
from core.control.row_stack import RowReport
from core.control.run_estimate import ExecutingPlan
from core.planning.grasp import plan_grasp
from test_row_console import BIN_XY, OBJECTS, R, SOFT, place_scene, rig, show, view_with, wait_for  # noqa: F401

assert rig  # the fixture, used by name
PLAN_S = 120.0  # a plan takes ~2.5 s; on two cores shared with other suites, far longer


def executing(xy, started=0.0, start=None):
    """The plan the control process would publish for an object at ``xy`` (planned here from
    ``start``, the straight arm by default, as the controller would), carried to the bin."""
    from core.control.row import bin_at
    plan = plan_grasp(SOFT, np.zeros(SOFT.n_segments) if start is None else start, xy, R)
    carry = bin_at(SOFT, *BIN_XY).kappa[None]
    return ExecutingPlan(np.asarray(plan.kappas, float), np.asarray(plan.palm_poses, float),
                         tuple(xy), carry, 0, started)


def arm_view(plan, phase, waypoint, t, row=None):
    """A published view: the machine in ``phase`` at ``waypoint`` (0-based) of ``plan`` at loop
    time ``t``, the arm at that waypoint's curvatures."""
    v = view_with(armed=True, phase=phase, row=row, waypoint=waypoint, n_waypoints=plan.n)
    at = plan.kappas[min(waypoint, plan.n - 1)]
    c = dataclasses.replace(v.snapshot.control, t=t, kappa_meas=at.copy())
    snap = dataclasses.replace(v.snapshot, control=c, t=t)
    return dataclasses.replace(v, snapshot=snap, executing=plan)


def circle_radii(points, center):
    """The radii of the circles drawn (each segment's start's distance from ``center``)."""
    pts = np.asarray(points, float)  # the scene keeps float32
    return np.unique(np.round(np.hypot(pts[:, 0, 0] - center[0], pts[:, 0, 1] - center[1]), 4))


def test_the_screen_follows_the_object_the_arm_works_on(rig):
    app, objects_panel, control, ctl, operator, _ = rig
    waypoints = app.add_panel(WaypointsPanel)
    place_scene(app, objects_panel, operator)
    s = app.grasp_session
    s.remove("Object 3")
    wait_for(lambda: len(s.view().objects) == 2)
    s.select("Object 1")
    show(control, view_with(armed=True))
    from fakes import user
    user(control.row.button, operator)
    (row_id, objects, _, _), = ctl.sent
    assert len(objects) == 2
    scene, run_scene = app.grasp_scene.plan_scene, app.grasp_scene.run_scene

    # Object 1 of 2, at waypoint 3 of its plan (the controller's, not the Grasp planner's).
    first = executing(OBJECTS[0])
    assert first.n >= 3
    running = RowReport(row_id, "running", 0, 2, (), None)
    show(control, arm_view(first, "approach", 2, 8.0, running))
    wait_for(lambda: run_scene.shown is not None and run_scene.shown.waypoint == 2)
    assert run_scene.label.text == (f"Arm: Object 1 (object 1 of 2) · waypoint 3 of {first.n}")
    radii = np.hypot(first.palms[:, 0] - OBJECTS[0][0], first.palms[:, 1] - OBJECTS[0][1])
    np.testing.assert_allclose(circle_radii(run_scene.circles.points, OBJECTS[0]),
                               np.unique(np.round(radii, 4)), atol=2e-4)
    np.testing.assert_allclose(run_scene.palms.points[:, :2], first.palms[:, :2], atol=1e-3)  # float16
    np.testing.assert_allclose(run_scene.palm_now.position[:2], first.palms[2, :2])
    wait_for(lambda: 'data-index="3"' in waypoints.run_info.content)
    assert waypoints.run_info.visible
    assert f'data-count="{first.n}"' in waypoints.run_info.content
    assert 'data-object="Object 1"' in waypoints.run_info.content
    assert app.header.text("phase").startswith(f"object 1 of 2: approach · waypoint 3 of "
                                               f"{first.n} · ARMED · ≈ ")

    # Meanwhile the operator selects Object 2 and plans it: drawn apart, not as the arm's.
    s.select("Object 2")
    s.request_plan()
    wait_for(lambda: (o := s.view().outcome) is not None and o.obj is not None
             and o.obj.name == "Object 2" and (o.plan is not None or o.refusal), PLAN_S)
    assert s.view().outcome.plan is not None, s.view().outcome.refusal
    wait_for(lambda: "Next plan (not running)" in waypoints.info.content)
    assert scene.dimmed and scene.dim_circles.visible and not scene.circles.visible
    assert not any(h.visible for h in scene.labels["waypoints"])  # the arm's are numbered
    assert run_scene.label.text.startswith("Arm: Object 1 (object 1 of 2)")
    target = control.execute.target_md.content
    assert "The arm is running Object 1 (object 1 of 2); next: Execute acts on Object 2" in target
    bar_first = control.progress.bar.value

    # Object 2's turn: everything follows the arm to it.
    released = ObjectOutcome(0, RowObject(*OBJECTS[0], R), "released", None, 0.6, 30.0)
    second = executing(OBJECTS[1], started=40.0, start=first.carry[-1])
    running = RowReport(row_id, "running", 1, 2, (released,), None)
    show(control, arm_view(second, "approach", 0, 45.0, running))
    wait_for(lambda: run_scene.shown is not None and run_scene.shown.index == 1)
    assert run_scene.label.text == f"Arm: Object 2 (object 2 of 2) · waypoint 1 of {second.n}"
    radii = np.hypot(second.palms[:, 0] - OBJECTS[1][0], second.palms[:, 1] - OBJECTS[1][1])
    np.testing.assert_allclose(circle_radii(run_scene.circles.points, OBJECTS[1]),
                               np.unique(np.round(radii, 4)), atol=2e-4)
    wait_for(lambda: 'data-object="Object 2"' in waypoints.run_info.content)
    assert 'data-index="1"' in waypoints.run_info.content
    assert control.progress.bar.value > max(bar_first, 50.0)  # past the first of two objects
    # Its release: the bar is nearly full; then the row is done and the bar is gone.
    show(control, arm_view(second, "release", second.n - 1, 80.0, running))
    assert control.progress.bar.value >= 95.0
    assert 'data-object="2"' in control.progress.line.content
    done = RowReport(row_id, "done", None, 2, (released, dataclasses.replace(
        released, index=1, object=RowObject(*OBJECTS[1], R))), None)
    show(control, dataclasses.replace(arm_view(second, "released", 0, 81.0, done),
                                      executing=None))
    wait_for(lambda: run_scene.shown is None)
    assert not control.progress.bar.visible
    wait_for(lambda: not waypoints.run_info.visible)  # (the panel's own refresh follows)
    assert not run_scene.circles.visible
    wait_for(lambda: not scene.dimmed, PLAN_S)  # the worker's part, once it is not planning


def test_execute_of_the_operators_plan_shows_the_arms_waypoint(rig):
    app, objects_panel, control, ctl, operator, _ = rig
    waypoints = app.add_panel(WaypointsPanel)
    s = app.grasp_session
    s.request_plan()
    wait_for(lambda: (o := s.view().outcome) is not None and o.plan is not None, PLAN_S)
    plan = s.view().outcome.plan
    s.inspect(plan.n - 1)  # the operator inspects the last waypoint ...
    wait_for(lambda: s.view().index == plan.n - 1)
    mine = ExecutingPlan(np.asarray(plan.kappas, float), np.asarray(plan.palm_poses, float),
                         tuple(plan.center[:2]), SOFT.bin.kappa[None], 0, 1.0)
    control.execute.target = None
    show(control, arm_view(mine, "approach", 1, 5.0))  # ... the arm goes to waypoint 2
    wait_for(lambda: "Arm at waypoint 2 of" in waypoints.info.content)
    assert 'data-index="2"' in waypoints.info.content
    assert 'data-mine="1"' in waypoints.run_info.content
    scene = app.grasp_scene.plan_scene
    wait_for(lambda: app.grasp_scene.run_scene.shown is not None)
    assert not scene.dimmed and not scene.circles.visible  # drawn once, by the run layer
    assert app.grasp_scene.run_scene.circles.visible
    line = control.progress.line.content
    assert 'data-waypoint="2"' in line and f'data-waypoints="{plan.n}"' in line
    assert float(line.split('data-left="')[1].split('"')[0]) > 0


def test_the_estimate_before_execute_is_the_plans(rig):
    app, objects_panel, control, ctl, operator, _ = rig
    s = app.grasp_session
    s.request_plan()
    wait_for(lambda: (o := s.view().outcome) is not None and o.plan is not None, PLAN_S)
    wait_for(lambda: 'data-estimate="' in control.execute.target_md.content
             and 'data-estimate=""' not in control.execute.target_md.content)
    text = control.execute.target_md.content
    seconds = float(text.split('data-estimate="')[1].split('"')[0])
    # Independent bound: at least the state machine's fixed waits, and the approach's longest
    # single-segment change at the trajectory's top speed.
    plan = s.view().outcome.plan
    sm, v = SOFT.state_machine, float(SOFT.trajectory.max_velocity[0])
    k = np.asarray(plan.kappas, float)
    assert seconds > sm.grasp_time_s + sm.release_time_s + np.max(np.abs(k[-1] - k[0])) / v
    assert "(estimated from the plan)" in text
