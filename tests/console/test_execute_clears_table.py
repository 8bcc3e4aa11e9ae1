"""A single grasp-and-place takes its object off the table once released: seen in a walk through
the console, after Execute (or Click to grasp) put an object in the bin it stayed drawn at its
old spot, and a later "Clear table into bin" went back for it. As a row's released objects
(test_row_console), the object leaves the Objects panel when the arm reads "released" after
starting on it; a stop, or an object moved meanwhile, leaves the table as it is."""

from __future__ import annotations

from test_row_console import R, rig, show, view_with  # noqa: F401


def names(app) -> list[str]:
    return [o.name for o in app.grasp_session.view().objects]


def execute(control, operator) -> None:
    event = type("E", (), {"client": operator, "client_id": operator.client_id})()
    control.execute._execute(event)


def test_a_released_single_grasp_leaves_the_table(rig) -> None:
    app, _, control, ctl, operator, _ = rig
    s = app.grasp_session
    s.place(0.10, 0.30, R)  # Object 2, selected
    s.select("Object 1")
    show(control, view_with(armed=True, phase="released"))  # the last task's end, still shown
    execute(control, operator)
    assert ctl.sent[-1][0] in ("grasp_at", "execute") and ctl.sent[-1][1][:2] == (-0.20, 0.20)
    show(control, view_with(phase="released"))  # a view from before the command: not this one
    assert names(app) == ["Object 1", "Object 2"]
    show(control, view_with(phase="approach", waypoint=2, n_waypoints=9))
    show(control, view_with(phase="move_to_bin"))
    assert names(app) == ["Object 1", "Object 2"]  # carried, not yet released
    show(control, view_with(phase="released"))
    assert names(app) == ["Object 2"]  # released in the bin: off the table
    show(control, view_with(phase="released"))
    assert names(app) == ["Object 2"]  # and only once


def test_a_stopped_grasp_or_a_moved_object_stays_on_the_table(rig) -> None:
    app, _, control, _, operator, _ = rig
    s = app.grasp_session
    show(control, view_with(armed=True))
    execute(control, operator)
    show(control, view_with(phase="approach"))
    show(control, view_with(phase="stopped"))
    show(control, view_with(phase="released"))  # a later task's end is not this grasp's
    assert names(app) == ["Object 1"]
    execute(control, operator)
    show(control, view_with(phase="grasp"))
    s.update("Object 1", x=0.05, y=0.30)  # the operator moved it: not what the arm took
    show(control, view_with(phase="released"))
    assert names(app) == ["Object 1"]


def test_a_grasp_the_control_process_refuses_is_told_and_leaves_the_table(rig) -> None:
    """The refusal reaches the operator as "Refused" with the process's reason (the done
    callback called a method the Execute controls do not have: nothing was told), and a later
    "released" leaves the refused object on the table."""
    import concurrent.futures as cf

    app, _, control, ctl, operator, _ = rig

    def refuses(*args, **kwargs):
        fut = cf.Future()
        fut.set_exception(RuntimeError("object out of reach"))
        return fut

    ctl.grasp_at = ctl.execute = refuses
    show(control, view_with(armed=True))
    execute(control, operator)
    assert ("Refused", "object out of reach") in operator.notes
    show(control, view_with(phase="released"))  # another task's end
    assert names(app) == ["Object 1"]
