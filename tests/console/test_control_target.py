"""What the soft arm's Control panel acts on and says (issues 19.1, 19.4, 18): Execute's target is
the Objects panel's selected object with the Grasp planner's plan for exactly that object; the
state line counts waypoints as the planner does; the tracking-error plot's range and values."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from console.panels.soft_arm.control_plots import MIN_ERROR_RANGE, error_range, tracking_error
from console.panels.soft_arm.control_text import (
    execute_target,
    header_phase,
    state_html,
    waypoint_text,
)
from console.core.grasp_state import Outcome, SessionView
from console.core.table_scene import TableObject
from core.planning.grasp import plan_grasp
from core.planning.obstacles import Obstacle
from core.robots import load

SOFT = load("soft-arm")
ONE = TableObject("Object 1", -0.20, 0.20, 0.0165)
TWO = TableObject("Object 2", -0.13, 0.17, 0.0165)


def session_view(selected: str | None, outcome: Outcome | None) -> SessionView:
    return SessionView((ONE, TWO), selected, outcome, 0, False, 2.0, True, "off",
                       clearance=0.010)


@pytest.fixture(scope="module")
def plan_two():
    """Object 2's plan as the session makes it: around Object 1 (another object on the table
    is an obstacle), with the session's clearance."""
    plan = plan_grasp(SOFT, np.zeros(6), (TWO.x, TWO.y), TWO.r,
                      obstacles=[Obstacle(ONE.name, ONE.x, ONE.y, ONE.r)], clearance=0.010)
    assert plan.success and plan.n >= 2
    return plan


def test_execute_acts_on_the_selected_object_and_its_own_plan(plan_two) -> None:
    target = execute_target(session_view("Object 2", Outcome(TWO, plan_two, None, 3)))
    assert (target.name, target.x, target.y, target.r) == ("Object 2", TWO.x, TWO.y, TWO.r)
    assert target.plan is plan_two
    assert "Object 2 at (-130, 170) mm, r 16.5 mm" in target.describe()
    assert f"Grasp planner's {plan_two.n}-waypoint plan" in target.describe()
    # A plan of another object (or of this one before it moved) is not executed for it.
    other = execute_target(session_view("Object 1", Outcome(TWO, plan_two, None, 3)))
    assert other.name == "Object 1" and other.plan is None
    moved = dataclasses.replace(TWO, x=-0.12)
    stale = execute_target(SessionView((ONE, moved), "Object 2",
                                       Outcome(TWO, plan_two, None, 3), 0, False, 2.0, True, ""))
    assert stale.x == -0.12 and stale.plan is None
    assert "controller plans the approach" in stale.describe()
    with pytest.raises(ValueError, match="No object selected"):
        execute_target(session_view(None, None))


def telemetry(phase: str, waypoint: int, n: int, replans: int = 0):
    from core.control.stack import Telemetry
    return Telemetry(t=3.0, armed=True, phase=phase, reason=None, waypoint=waypoint,
                     n_waypoints=n, replans=replans, tracking_ok=True, prepressurised=True,
                     kappa_meas=np.zeros(6), kappa_ref=np.zeros(6), kappa_target=np.zeros(6),
                     commands=np.zeros(13), saturated=np.zeros(6, bool), gripper_closed=False,
                     object_xy=None)


def test_the_state_line_counts_the_planners_waypoints(plan_two) -> None:
    from hw_bridge.loop import LoopSnapshot, LoopStats
    from hw_bridge.soft_arm_process import ControlView

    n = plan_two.n
    c = telemetry("approach", 2, n)
    assert waypoint_text(c, True) == f" · approach waypoint 3 of {n} (Grasp planner's plan)"
    assert waypoint_text(telemetry("approach", 0, 3, replans=1), True) == \
        " · approach waypoint 1 of 3 (controller's re-plan 1)"
    assert waypoint_text(telemetry("grasp", n - 1, n), True) == \
        f" · plan of {n} waypoints (Grasp planner's plan)"
    assert waypoint_text(telemetry("idle", 0, 0)) == ""
    snap = LoopSnapshot(300, 3.0, c, 10.0, 0.5, 0.1, 0.3, 0.1, 0, None)
    view = ControlView(snap, LoopStats(300, 0, 0, 0, *([0.0] * 9)), "default", None, None,
                       False, None)
    target = execute_target(session_view("Object 2", Outcome(TWO, plan_two, None, 3)))
    html = state_html(view, target)
    assert f'data-waypoint="3" data-waypoints="{n}" data-object="Object 2"' in html
    assert f"approach waypoint 3 of {n}" in html and "Object 2 at" in html
    text, tone = header_phase(view, target)
    assert text == f"approach · Object 2 · waypoint 3 of {n} · ARMED" and tone == "busy"


def test_tracking_error_keeps_a_still_arms_noise_small() -> None:
    rng = np.random.default_rng(1)
    ref = np.zeros((50, 6))
    meas = rng.normal(0.0, 0.35, (50, 6))  # the sim's marker noise on a still arm
    meas[3, 2] = np.nan  # a frame with an occluded marker
    err = tracking_error(ref, meas)
    assert np.isnan(err[3, 2]) and np.allclose(err[0], np.abs(meas[0]))
    assert error_range(err) == MIN_ERROR_RANGE  # noise (< 1.5 1/m) stays in the bottom third
    assert np.nanmax(err) < MIN_ERROR_RANGE / 3
    big = err.copy()
    big[10, 0] = 7.3  # a real tracking error grows the range to show it
    assert error_range(big) == 9.0


def test_a_one_waypoint_plan_is_one_waypoint() -> None:
    """Seen in a walk through the console: "plan of 1 waypoints" after a right-side grasp."""
    assert waypoint_text(telemetry("released", 0, 1)) == " · plan of 1 waypoint (controller's plan)"


def test_the_arms_run_and_the_planner_summary_say_one_waypoint_for_a_one_waypoint_plan() -> None:
    """Seen in the demo's screenshots (scripts/demo_screenshots.py): "Arm: Object 2 · grasp
    (after 1 waypoints)" on the arm and "1 waypoints, 0.7 ms" in the Grasp planner."""
    from types import SimpleNamespace

    from console.core.run_state import RunView
    from console.scene.plan_view import outcome_html

    run = RunView("grasp", SimpleNamespace(n=1), None, "Object 2", None, 1, 5.0, 5.0, 0.5)
    assert run.waypoint_text() == "grasp (after 1 waypoint)"
    five = RunView("grasp", SimpleNamespace(n=5), None, "Object 2", None, 1, 5.0, 5.0, 0.5)
    assert five.waypoint_text() == "grasp (after 5 waypoints)"
    for n, words in ((1, "1 waypoint, 0.7 ms"), (5, "5 waypoints, 0.7 ms")):
        plan = SimpleNamespace(n=n, total_ms=0.7, success=True, obstacles=(),
                               obstacle_path_clearance=None, carry=None)
        html = outcome_html(SimpleNamespace(refusal=None, plan=plan, carry_note=None, others=()))
        assert f"<b>{words}</b>" in html


def test_the_arms_label_follows_the_phase_after_the_approach() -> None:
    """Seen in the demo's screenshots: the label at the object said "grasp (after 1 waypoint)"
    while the header said move_to_bin: a run's key (what redraws the plan and its label)
    left out the phases after the approach."""
    from types import SimpleNamespace

    import numpy as np

    from console.core.run_state import RunView
    from console.scene.run_view import run_label

    plan = SimpleNamespace(n=1, kappas=np.zeros((1, 6)), center=(-0.08, 0.33), replans=0)
    grasp = RunView("grasp", plan, None, "Object 2", None, 1, 5.0, 5.0, 0.5)
    carry = RunView("move_to_bin", plan, None, "Object 2", None, 1, 4.0, 4.0, 0.6)
    assert run_label(carry) == "Arm: Object 2 · move_to_bin (after 1 waypoint)"
    assert grasp.key() != carry.key()
    later = RunView("move_to_bin", plan, None, "Object 2", None, 1, 2.0, 2.0, 0.8)
    assert later.key() == carry.key()                       # the times alone: no redraw
