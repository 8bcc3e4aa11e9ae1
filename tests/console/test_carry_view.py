"""The carry to the bin in the plan view (#17), and the planner showing that a long plan runs."""

from __future__ import annotations

import math
import re
import threading
import time

import numpy as np
import pytest

from console.scene.carry_view import PATH_SAMPLES
from console.core.planning_clock import PlanningClock
from console.scene.plan_view import outcome_html
from console.core.table_bin import locate_bin
from console.core.table_scene import TableObject
from core.kinematics import planar as pk
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import Obstacle
from core.robots import load
from fakes import FakeClient
from test_planner_console import gated, user, wait_for  # noqa: F401 (fixture)

ROBOT = load("soft-arm")
CUP = TableObject("Cup", -0.20, 0.20, 0.0165)
# Between the grasp pose and the bin: the straight carry sweeps the gripper through it
# (tests/core/test_clear_path.py).
BEHIND = Obstacle("Obstacle 1", -0.25, 0.27, 0.015)
FAR = Obstacle("Far", 0.30, 0.05, 0.02)
BIN_XY = (-0.12, 0.10)


def palm_by_fk(kappa, side: str) -> np.ndarray:
    """The palm point of ``kappa`` from the arm's forward kinematics: the tip pose, then the
    gripper's palm offset (along, to the closing side) in the tip's frame."""
    tip = pk.forward_kinematics(np.asarray(kappa, float), ROBOT.lengths, ROBOT.base_pose)[-1]
    g = ROBOT.gripper
    n = g.g_off if side == "left" else -g.g_off
    c, s = math.cos(tip[2]), math.sin(tip[2])
    return np.array([tip[0] + g.w_off_along * c - n * s, tip[1] + g.w_off_along * s + n * c])


def _operator(app, cid: int) -> FakeClient:
    operator = FakeClient(cid)
    app.access.take(operator.client_id, "tok", name="Alice")
    return operator


def _settled(s):
    """The outcome once no plan is pending (the session's own plans after a scene change)."""
    def idle():
        with s._cond:
            return s._request is None and s._outcome is not None and s._outcome
    return wait_for(idle, timeout=30, what="the session idle")


def _plan(s, pp, operator, seq_before: int | None = None):
    """Plan grasp pressed once the session is idle; the new outcome."""
    if seq_before is None:
        seq_before = _settled(s).seq
    user(pp.plan_button, operator)
    return wait_for(lambda: (o := s.view().outcome) and o.seq > seq_before and o, timeout=30,
                    what="a new plan")


def _drawn(layer) -> bool:
    return layer.path.visible and layer.targets.visible and layer.ghosts.visible


def test_a_plan_around_an_obstacle_to_the_bin_draws_its_carry_and_replans_replace_it(gated):
    from console.panels.soft_arm.planner import PlannerPanel

    app, s = gated, gated.grasp_session
    pp, layer = app.panel(PlannerPanel), gated.grasp_scene.carry_layer
    operator = _operator(app, 51)
    s.set_clearance(0.010)
    s.set_bin(locate_bin(ROBOT, *BIN_XY))
    s.set_scene([CUP], [BEHIND])
    out = _plan(s, pp, operator)
    plan = out.plan
    assert plan is not None and plan.success and plan.carry is not None, outcome_html(out)
    assert len(plan.carry) >= 2                                 # vias, then the bin pose
    wait_for(lambda: _drawn(layer), what="the carry drawn")
    want = np.array([palm_by_fk(k, plan.side) for k in plan.carry])
    # viser keeps a point cloud in float16 (0.12 mm steps here), line segments in float32.
    np.testing.assert_allclose(layer.targets.points[:, :2], want, atol=2e-4)
    drawn = layer.path.points                    # the path, then copies of its last segment
    n = PATH_SAMPLES * len(plan.carry)
    path = drawn[:n]
    np.testing.assert_array_equal(drawn[n:], np.broadcast_to(path[-1], drawn[n:].shape))
    assert np.all(np.hypot(*(path[:, 1, :2] - path[:, 0, :2]).T) > 0)   # none of them empty
    np.testing.assert_allclose(path[0, 0, :2], palm_by_fk(plan.kappas[-1], plan.side),
                               atol=1e-6)                       # from the grasp pose
    np.testing.assert_allclose(path[-1, 1, :2], want[-1], atol=1e-6)  # to the bin pose
    np.testing.assert_allclose(path[1:, 0], path[:-1, 1])       # one connected polyline
    for w in want:                                              # through every target
        assert np.min(np.hypot(*(path[:, 1, :2] - w).T)) < 1e-6
    vias = len(plan.carry) - 1
    wait_for(lambda: f"carry to the bin: {vias} via shape" in pp.summary.content,
             what="the summary's vias")
    from console.panels.common.view import legend_html
    assert "Carry to the bin" in legend_html("planar")

    # Replanned with the obstacle out of the way: the straight carry replaces the detour.
    s.set_scene([CUP], [FAR])
    out = wait_for(lambda: (o := s.view().outcome) and o.plan is not None
                   and o.plan.obstacles == (FAR,) and o, timeout=30)
    assert out.plan.carry is not None and len(out.plan.carry) == 1
    wait_for(lambda: len(layer.targets.points) == 1, what="the straight carry drawn")
    np.testing.assert_allclose(layer.targets.points[0, :2],
                               palm_by_fk(out.plan.carry[0], out.plan.side), atol=2e-4)
    wait_for(lambda: "carry to the bin: straight" in pp.summary.content,
             what="the summary's straight carry")  # the panel refreshes after the layer

    # No bin, no carry: the layer is hidden.
    s.set_bin(None)
    out = _plan(s, pp, operator)
    assert out.plan is not None and out.plan.carry is None
    wait_for(lambda: not (layer.path.visible or layer.targets.visible or layer.ghosts.visible),
             what="the carry hidden")
    wait_for(lambda: "carry to the bin" not in pp.summary.content and "Planning" not in
             pp.summary.content, what="the summary without a carry")

    # Back with the bin and the obstacle, then the plan cleared (the object removed).
    s.set_bin(locate_bin(ROBOT, *BIN_XY))
    s.set_scene([CUP], [BEHIND])
    wait_for(lambda: (o := s.view().outcome) and o.plan is not None
             and o.plan.carry is not None and len(o.plan.carry) >= 2, timeout=30)
    wait_for(lambda: _drawn(layer) and len(layer.targets.points) >= 2)
    s.remove("Cup")  # the table emptied: no outcome at all (nothing refused)
    wait_for(lambda: s.view().outcome is None)
    wait_for(lambda: not (layer.path.visible or layer.targets.visible or layer.ghosts.visible),
             what="the carry hidden with the plan")


def test_a_carry_that_is_refused_keeps_the_grasp_and_says_why(gated):
    from console.panels.soft_arm.planner import PlannerPanel

    app, s = gated, gated.grasp_session
    pp, layer = app.panel(PlannerPanel), app.grasp_scene.carry_layer
    operator = _operator(app, 52)
    table_bin = locate_bin(ROBOT, *BIN_XY)
    tip = pk.forward_kinematics(np.asarray(table_bin.kappa), ROBOT.lengths, ROBOT.base_pose)[-1]
    on_bin = Obstacle("Jar", float(tip[0]) + 0.03, float(tip[1]), 0.01)  # where the bin pose is
    s.set_clearance(0.010)
    s.set_bin(table_bin)
    s.set_scene([CUP], [on_bin])
    out = _plan(s, pp, operator)
    if out.plan is None:
        pytest.fail(f"the grasp itself was refused: {out.refusal}")
    assert out.plan.success and out.plan.carry is None
    assert out.carry_note and "Jar" in out.carry_note
    # the panel draws the outcome after the session publishes it: wait for the page's words
    wait_for(lambda: "no carry to the bin" in pp.summary.content and "Jar" in pp.summary.content,
             timeout=30, what="the refused carry in the summary")
    assert not layer.path.visible


def test_the_planning_clock_reports_only_plans_longer_than_its_delay_and_none_after_stop():
    seen: list[float] = []
    clock = PlanningClock(seen.append, delay=0.3, period=0.1)
    try:
        clock.start()
        time.sleep(0.1)
        clock.stop()
        time.sleep(0.4)
        assert seen == []                                   # a quick plan shows nothing
        clock.start()
        time.sleep(0.65)
        clock.stop()
        n = len(seen)
        assert n >= 2 and 0.3 <= seen[0] < 0.45 and seen == sorted(seen)
        time.sleep(0.3)
        assert len(seen) == n                               # nothing after stop
    finally:
        clock.close()


def test_a_slow_plan_shows_planning_with_the_button_disabled_then_the_refusal(gated):
    from console.panels.soft_arm.planner import PlannerPanel

    app, s = gated, gated.grasp_session
    pp = app.panel(PlannerPanel)
    operator = _operator(app, 53)
    release = threading.Event()
    release.set()

    def slow_refusal(*args, **kwargs):
        release.wait(10)            # the long way round, held until the test has looked
        raise GraspRefused("obstacle", "Obstacle 1 is in the way: no approach found.")

    s.planner.plan = slow_refusal
    s.set_scene([CUP], [])
    seq = _settled(s).seq
    release.clear()
    started = time.perf_counter()
    user(pp.plan_button, operator)
    wait_for(lambda: "Planning…" in pp.summary.content, timeout=30, what="Planning…")
    assert time.perf_counter() - started >= 0.45          # not for a plan of a moment
    assert pp.plan_button.disabled and 'data-state="planning"' in pp.summary.content
    wait_for(lambda: (m := re.search(r"Planning… \((\d+\.\d) s\)", pp.summary.content))
             and float(m.group(1)) >= 1.0, timeout=30, what="the seconds counting")
    release.set()
    out = wait_for(lambda: (o := s.view().outcome) and o.seq > seq and o, timeout=30)
    assert out.refusal.startswith("Obstacle 1 is in the way")
    wait_for(lambda: "Obstacle 1 is in the way" in pp.summary.content and
             not pp.plan_button.disabled, what="the refusal shown, the button back")
    assert 'data-state="refused"' in pp.summary.content


def test_execute_and_click_to_grasp_show_the_machines_planning_then_its_refusal() -> None:
    """Execute without a plan and Click to grasp plan on the machine (its planning process):
    its phase "planning" is the header's busy field and the Control panel's state line while
    it runs, and the refusal is the state line's reason when it ends."""
    from console.panels.soft_arm.control_text import execute_target, header_phase, state_html
    from console.core.grasp_state import SessionView
    from core.control.stack import Telemetry
    from hw_bridge.loop import LoopSnapshot, LoopStats
    from hw_bridge.soft_arm_process import ControlView

    def view(phase: str, reason: str | None) -> ControlView:
        c = Telemetry(t=3.0, armed=True, phase=phase, reason=reason, waypoint=0,
                      n_waypoints=0, replans=0, tracking_ok=True, prepressurised=True,
                      kappa_meas=np.zeros(6), kappa_ref=np.zeros(6), kappa_target=np.zeros(6),
                      commands=np.zeros(13), saturated=np.zeros(6, bool),
                      gripper_closed=False, object_xy=None)
        snap = LoopSnapshot(300, 3.0, c, 10.0, 0.5, 0.1, 0.3, 0.1, 0, None)
        return ControlView(snap, LoopStats(300, 0, 0, 0, *([0.0] * 9)), "default", None,
                           None, False, None)

    target = execute_target(SessionView((CUP,), "Cup", None, 0, False, 2.0, True, "off"))
    planning = view("planning", "object settled at (-0.200, 0.200)")
    assert header_phase(planning, target) == ("planning · Cup · ARMED", "busy")
    assert 'data-phase="planning"' in state_html(planning, target)
    why = "planner refused: Obstacle 1 is in the way: no approach found."
    refused = view("stopped", why)
    assert header_phase(refused, target)[1] == "ok"
    html = state_html(refused, target)
    assert 'data-phase="stopped"' in html and f"<b>Reason:</b> {why}" in html
