"""A refusal stays on screen until the operator's next action (it closed by itself after 8 s, so
an operator who looked away missed why the bin was not placed), and it is worded in mm about the
bin: a click with "Table click places: Bin" beyond the arm's reach is refused in a notification
that does not close by itself; the operator's next action (here: changing what a click places)
takes it away, and a second refusal replaces the first rather than stacking."""

from __future__ import annotations

from fakes import click_at, user
from test_row_console import rig, wait_for  # noqa: F401


def test_a_refusal_stays_until_the_operators_next_action(rig) -> None:
    app, objects_panel, _, _, operator, _ = rig
    user(objects_panel.click_place, operator, "Bin")
    click_at(objects_panel, operator, 0.6, 0.1)  # 0.6 m out: beyond any reach
    assert wait_for(lambda: operator.shown_now)
    (title, body), = operator.shown_now  # no auto-close: still shown, however long it takes
    assert title == "Bin" and body.startswith("Not placed: The bin at (600, 100) mm is out of "
                                              "reach"), body
    assert " cm" not in body and "object" not in body.split(":")[1]
    click_at(objects_panel, operator, 0.61, 0.1)  # refused again: replaces, does not stack
    assert wait_for(lambda: len(operator.shown) == 2 and operator.shown[0].removed)
    assert [t for t, _ in operator.shown_now] == ["Bin"]
    user(objects_panel.click_place, operator, "Object")  # the next action
    assert operator.shown_now == []
