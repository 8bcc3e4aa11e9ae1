"""A second press of "Clear table into bin" while a row runs (a double click: the button is
disabled only once the next view shows the row) is refused by the control process. Seen in a
walk through the console: the refused press became the row the panel named and took objects
off for, so the running row's objects were listed as "object 1..3" instead of their names, its
released objects stayed on the table, and the operator read "Taking 3 objects" for the refused
press too. The running row keeps its names and its released objects leave the table; only the
accepted press says "Taking"."""

from __future__ import annotations

import concurrent.futures as cf

from test_row_console import OBJECTS, R, FakeRowControl, place_scene, rig, show, view_with  # noqa: F401

from core.control.row import ObjectOutcome, RowObject
from core.control.row_stack import RowReport
from fakes import user
from tests import ws_client


class RefusesWhileRunning(FakeRowControl):
    """The control process: the first row runs, a second one is refused while it does."""

    def run_row(self, row_id, *args, **kwargs):
        fut = super().run_row(row_id, *args, **kwargs)
        if len(self.sent) == 1:
            return fut
        refused: cf.Future = cf.Future()
        refused.set_exception(ValueError("a row of objects is running (object 1 of 3): press "
                                         "STOP first"))
        return refused


def test_a_second_press_while_the_row_runs_keeps_the_running_rows_names(rig):
    app, objects_panel, control, ctl, operator, _ = rig
    control.ctl = ctl = RefusesWhileRunning()
    place_scene(app, objects_panel, operator)
    names = tuple(o.name for o in app.grasp_session.view().objects)
    show(control, view_with(armed=True))
    user(control.row.button, operator)
    user(control.row.button, operator)  # the double click's second press
    first_id, second_id = ctl.sent[0][0], ctl.sent[1][0]
    assert first_id != second_id
    assert [t for t, _ in operator.notes] == ["Clear table into bin", "Refused"]

    rows = [RowObject(x, y, R) for x, y in OBJECTS]
    released = ObjectOutcome(0, rows[0], "released", None, 0.6, 30.0)
    running = RowReport(first_id, "running", 1, 3, (released,), None)
    show(control, view_with(phase="approach", row=running, waypoint=0, n_waypoints=5))
    status = control.row.status.content
    assert f"object 2 of 3 ({names[1]}): approach" in status
    assert f'<li data-status="released">{names[0]}: released</li>' in status
    ws_client.wait_for(lambda: names[0] not in {o.name for o in app.grasp_session.view().objects},
                       10.0, "the released object taken off the table")
