"""The control stack with a row on it (core.control.row_stack): a loop that only calls
``update`` (as the control process's does) takes three objects to a placed bin, each put into
the world when its turn begins; STOP through the stack ends the row with the rest skipped; no
other task starts mid-row; a disarmed stack refuses the row."""

import numpy as np
import pytest
from test_control_row import B, D, E, R, _armed_loop

from core import robots
from core.control.grasp_place import Phase, immediate
from core.control.row import bin_at, bin_drop_point
from core.control.row_stack import RowControlStack

BIN_XY = (0.15, 0.25)


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


@pytest.fixture(scope="module")
def bin_params(arm):
    return bin_at(arm, *BIN_XY)


def _armed(arm, seed=1):
    sim, loop = _armed_loop(arm, seed, RowControlStack)
    return sim, loop.stack, loop


def test_the_loop_takes_three_objects_to_the_placed_bin_by_update_alone(arm, bin_params):
    sim, stack, loop = _armed(arm)
    placed, dropped = [], []

    def place(obj):  # each later object, when its turn begins; notes where the last one lies
        dropped.append(sim.obj.xy.copy())
        placed.append(obj)
        sim.place_object(obj.x, obj.y, obj.r)

    sim.place_object(B.x, B.y, B.r)
    loop.submit(lambda s, t: s.start_row(7, [B, D, E], bin_params, t, place))
    loop.run(1.0)
    report = stack.row_report()
    assert report.row_id == 7 and report.running and report.current == 0 and report.n == 3
    loop.run(300.0, until=lambda c: not stack.row_running)
    report = stack.row_report()
    assert report.state == "done" and report.released == 3 and report.reason is None
    assert [o.status for o in report.outcomes] == ["released"] * 3
    assert placed == [D, E]
    dropped.append(sim.obj.xy.copy())  # the last one
    drop = bin_drop_point(arm, bin_params.kappa, R)
    assert np.hypot(drop[0] - BIN_XY[0], drop[1] - BIN_XY[1]) < 0.002
    for xy in dropped:  # every object lies in the placed bin, not at the robot file's bin
        assert np.hypot(*(xy - np.asarray(BIN_XY))) < bin_params.drop_radius_m
    assert stack.machine.bin is arm.bin  # the row's bin was for the row only


def test_stop_through_the_stack_ends_the_row_and_other_tasks_wait(arm, bin_params):
    sim, stack, loop = _armed(arm)
    sim.place_object(B.x, B.y, B.r)
    loop.submit(lambda s, t: s.start_row(1, [B, D, E], bin_params, t, lambda o: None))
    loop.run(8.0, until=lambda c: c.phase == Phase.APPROACH.value)
    with pytest.raises(RuntimeError, match=r"object 1 of 3\): press STOP first"):
        stack.require_no_row()
    with pytest.raises(RuntimeError, match="press STOP first"):
        stack.start_row(2, [D], bin_params, loop.t)
    loop.submit(lambda s, t: s.stop(t, "operator STOP"))  # what the StopArm command calls
    loop.run(1.0)
    report = stack.row_report()
    assert report.state == "stopped" and report.reason == "operator STOP"
    assert [(o.status, o.reason) for o in report.outcomes] == [
        ("failed", "operator STOP"), ("skipped", "row stopped: operator STOP"),
        ("skipped", "row stopped: operator STOP")]
    assert loop.control.phase == Phase.STOPPED.value and loop.control.reason == "operator STOP"
    stack.require_no_row()  # over: other tasks may run again
    held = loop.control.commands.copy()
    loop.run(0.5)
    assert np.array_equal(loop.control.commands, held)  # holding


def test_a_disarmed_stack_refuses_the_row_and_keeps_nothing(arm, bin_params):
    stack = RowControlStack(arm, 0.01, immediate(lambda req: None))
    with pytest.raises(RuntimeError, match="not armed"):
        stack.start_row(1, [B], bin_params, 0.0)
    assert stack.row is None and stack.row_report() is None
    with pytest.raises(ValueError, match="at least one object"):
        stack.start_row(1, [], bin_params, 0.0)
