"""Play in the Waypoints panel says why it does nothing: seen in a walk through the console,
Play with no plan (the planner refused the selected object) did nothing without a word, while
"Move arm here" said "No plan to move along."; a one-waypoint plan has nothing to play either
(the same check, not tested here)."""

from __future__ import annotations

from test_planner_console import gated  # noqa: F401

from fakes import FakeClient, user
from ws_client import wait_for


def test_play_without_a_plan_to_play_tells_the_operator(gated) -> None:
    from console.panels.soft_arm.waypoints import WaypointsPanel

    app, s = gated, gated.grasp_session
    wp = app.panel(WaypointsPanel)
    operator = FakeClient(7)
    app.access.take(operator.client_id, "tok")
    wait_for(lambda: s.view().outcome)
    s.update("Object 1", x=0.6, y=0.1)  # out of reach: refused, no plan
    wait_for(lambda: s.view().outcome and s.view().outcome.plan is None
             and s.view().outcome.refusal, 30.0)
    user(wp.play_button, operator)
    assert operator.notes[-1] == ("Waypoints", "No plan to play: the Grasp planner has none "
                                               "for the selected object.")
    assert not s.view().playing

    s.update("Object 1", x=-0.2, y=0.2)
    plan = wait_for(lambda: s.view().outcome and s.view().outcome.plan, 30.0)
    assert plan.n > 1
    notes = len(operator.notes)
    user(wp.play_button, operator)  # a plan of several waypoints plays, with no notice
    assert s.view().playing and len(operator.notes) == notes
