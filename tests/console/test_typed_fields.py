"""A field the operator has just typed survives the panel's echo of the field typed before it.

viser stores a browser's value before the field's callback runs; typing x then y, the echo of
x's edit (the object or obstacle with the old y) used to write the old y back in between, and
y's callback then applied the old y (a CI run lost a typed tip-target y so; the tip target's own
test is in test_extensible_panels). Here the echo is replayed at that moment, deterministically.
"""

from __future__ import annotations


import pytest
from fakes import FakeClient
from test_planner_console import gated, user, wait_for  # noqa: F401 (fixture)

from console.panels.common.typed_fields import TypedFields


class Field:
    """A stand-in number handle: ``.value`` as viser's handle holds it."""

    def __init__(self, value: float) -> None:
        self.value = value


def test_show_skips_a_typed_field_until_read_and_typed_too_restores_it():
    x, y = Field(1.0), Field(2.0)
    fields = TypedFields((x, y))
    y.value = 5.0                         # typed, its callback not run yet
    fields.show([10.0, 2.0])              # the echo of x's edit
    assert (x.value, y.value) == (10.0, 5.0)
    assert fields.read() == [10.0, 5.0]   # y's callback takes it
    fields.show([10.0, 7.0])              # from now on y follows the panel's state
    assert y.value == 7.0
    fields.show([10.04, 7.0])             # within the tolerance: not rewritten
    assert x.value == 10.0
    y.value = 9.0                         # typed, then refused: goes back all the same
    fields.show([2.0], [y], typed_too=True)
    assert y.value == 2.0


def test_objects_panel_keeps_a_typed_y_past_the_echo_of_x(gated):
    from console.panels.soft_arm.objects import ObjectsPanel

    app, s = gated, gated.grasp_session
    op_panel, op = app.panel(ObjectsPanel), FakeClient(81)
    app.access.take(op.client_id, "tok", name="Alice")
    name = wait_for(lambda: s.view().selected)
    old = next(o for o in s.view().objects if o.name == name)
    user(op_panel.x, op, old.x * 1e3 + 20.0)                       # x typed and applied
    wait_for(lambda: next(o for o in s.view().objects if o.name == name).x > old.x + 0.019)
    op_panel.y._impl.value = old.y * 1e3 - 15.0                    # y typed, callback queued
    op_panel.refresh(s.view())                                      # the echo of x's edit
    assert op_panel.y.value == pytest.approx(old.y * 1e3 - 15.0)
    user(op_panel.y, op)                                            # y's callback
    wait_for(lambda: abs(next(o for o in s.view().objects if o.name == name).y
                         - (old.y - 0.015)) < 1e-9, what="the typed y applied")


def test_obstacle_editor_keeps_a_typed_y_past_the_echo_of_x(gated):
    from console.panels.soft_arm.objects import ObjectsPanel

    app, s = gated, gated.grasp_session
    editor, op = app.panel(ObjectsPanel).obstacles, FakeClient(82)
    app.access.take(op.client_id, "tok", name="Alice")
    wait_for(lambda: s.view().outcome)  # the demo object's plan done: edits apply at once
    s.place_obstacle(-0.25, 0.05, r=0.01)
    obs = wait_for(lambda: s.view().obstacles and s.view().obstacles[0])
    wait_for(lambda: editor.x.value == pytest.approx(obs.x * 1e3))
    user(editor.x, op, obs.x * 1e3 + 10.0)
    wait_for(lambda: s.view().obstacles[0].x > obs.x + 0.009)
    editor.y._impl.value = obs.y * 1e3 + 12.0                     # y typed, callback queued
    editor.refresh(s.view())                                       # the echo of x's edit
    assert editor.y.value == pytest.approx(obs.y * 1e3 + 12.0)
    user(editor.y, op)
    wait_for(lambda: abs(s.view().obstacles[0].y - (obs.y + 0.012)) < 1e-9,
             what="the typed y applied")


def test_a_field_typed_with_nothing_selected_still_shows_the_next_selection(gated):
    """A value typed while nothing is selected is taken (the obstacle editor's r: the next
    obstacle's radius; the rest: nothing to change), so the next selection's echo shows that
    one's values, not the typed ones."""
    from console.panels.soft_arm.objects import ObjectsPanel

    app, s = gated, gated.grasp_session
    objects, op = app.panel(ObjectsPanel), FakeClient(83)
    editor = objects.obstacles
    app.access.take(op.client_id, "tok", name="Alice")
    wait_for(lambda: s.view().outcome)
    assert s.view().obstacle_selected is None
    user(editor.x, op, 123.0)                    # nothing selected: nothing to move
    user(editor.r, op, 30.0)                     # the next obstacle's radius
    s.place_obstacle(-0.25, 0.05, r=0.012)       # placed (and selected) by another way
    wait_for(lambda: editor.r.value == pytest.approx(12.0) and editor.x.value
             == pytest.approx(-250.0), what="the new obstacle's values shown")
    name = s.view().selected
    s.select(None)                               # objects: the same with x typed, none selected
    wait_for(lambda: s.view().selected is None)
    user(objects.x, op, 77.0)
    s.select(name)
    obj = next(o for o in s.view().objects if o.name == name)
    wait_for(lambda: objects.x.value == pytest.approx(obj.x * 1e3),
             what="the selected object's x shown")
