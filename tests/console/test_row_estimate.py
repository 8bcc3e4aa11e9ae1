"""The row's remaining time (console.core.run_state.run_of) against a simulated row of three on
core's simulated clock (SimLoop, no wall clock): from the first object's plan to the last
release the time left is always known, also while a later object settles and is planned (before,
"estimating" between objects), and elapsed + left stays within FACTOR of the row's duration."""

from __future__ import annotations

import types

import pytest

from console.core.run_state import row_seconds, run_of
from core import robots
from core.control.row import bin_at
from core.control.row_stack import RowControlStack
from core.control.run_estimate import LegTimer, executing_plan
from tests.core.test_control_row import B, D, E, _armed_loop

FACTOR = 1.2  # the stated bound: (elapsed + left) / the row's duration within [1/FACTOR, FACTOR]


def test_a_rows_time_left_counts_the_objects_not_yet_begun_and_holds_between_objects():
    arm = robots.load("soft-arm")
    sim, loop = _armed_loop(arm, 1, RowControlStack)
    stack = loop.stack
    sim.place_object(B.x, B.y, B.r)
    loop.submit(lambda s, t: s.start_row(
        7, [B, D, E], bin_at(arm, 0.15, 0.25), t,
        lambda obj: sim.place_object(obj.x, obj.y, obj.r)))
    timer = LegTimer(arm)
    t0, seen, planned = loop.t, [], False
    while loop.t - t0 < 400.0:
        c = loop.tick()
        report = stack.row_report()
        if report is not None and not report.running and loop.t - t0 > 1.0:
            break
        if loop.ticks % 100 or report is None:  # once a simulated second
            continue
        plan = executing_plan(stack.machine)
        planned = planned or plan is not None
        view = types.SimpleNamespace(snapshot=types.SimpleNamespace(control=c), row=report,
                                     executing=plan)
        run = run_of(view, arm, timer, ("Object 1", "Object 2", "Object 3"))
        if planned and run is not None:
            seen.append((loop.t - t0, run, c.phase))
    total = loop.t - t0
    assert stack.row_report().state == "done" and stack.row_report().released == 3
    between = [(t, run) for t, run, phase in seen if run.index > 0
               and phase in ("settling", "planning")]
    assert between, "never saw a later object settle or be planned"
    for t, run, phase in seen:
        assert run.row_remaining_s is not None, (t, phase, run.index)
        assert 1 / FACTOR <= (t + run.row_remaining_s) / total <= FACTOR, \
            (t, phase, run.index, run.row_remaining_s, total)
        assert run.time_text().startswith("≈ "), run.time_text()
    assert [run.index for _, run, _ in seen][-1] == 2 and seen[-1][1].name == "Object 3"


def test_the_rows_pace_is_its_finished_objects_mean_time():
    done = [types.SimpleNamespace(started_s=10.0, ended_s=40.0),
            types.SimpleNamespace(started_s=40.0, ended_s=80.0)]
    row = types.SimpleNamespace(outcomes=tuple(done))
    # Object 3 of 4 runs with 12 s left: it, and one more at the pace of 35 s.
    assert row_seconds(row, 2, 4, 90.0, 12.0, 10.0) == (pytest.approx(47.0), None)
    # Between objects (no plan yet), 5 s after the last release: 30 s of this one left.
    total, here = row_seconds(row, 2, 4, 85.0, None, 0.0)
    assert total == pytest.approx(30.0 + 35.0) and here == pytest.approx(5.0 / 35.0)
    # The first object: its own whole estimate for each later one; nothing known before a plan.
    first = types.SimpleNamespace(outcomes=())
    assert row_seconds(first, 0, 3, 20.0, 50.0, 20.0) == (pytest.approx(50.0 + 2 * 70.0), None)
    assert row_seconds(first, 0, 3, 2.0, None, 0.0) == (None, None)


def test_an_object_taken_before_the_ones_queued_ahead_of_it_counts_in_the_order_taken():
    """Seen in the demo's screenshots: the row took the third object first (the other two
    waited behind it, their ways blocked) and the screen said "object 3 of 3 · ≈ 22 s left"
    with a bar two thirds full and nothing released. The object's place, the time left and the
    bar count the objects finished before it (row.outcomes), its name its place in the queue."""
    arm = robots.load("soft-arm")
    c = types.SimpleNamespace(armed=True, phase="planning", kappa_meas=None,
                              kappa_ref=[0.0] * 6, t=35.0, waypoint=0)
    names = ("Object 1", "Object 2", "Object 3")
    first = types.SimpleNamespace(running=True, current=2, n=3, outcomes=())
    run = run_of(types.SimpleNamespace(snapshot=types.SimpleNamespace(control=c), row=first,
                                       executing=None), arm, LegTimer(arm), names)
    assert run.name == "Object 3" and run.index == 0
    assert run.object_text() == "Object 3 (object 1 of 3)" and run.fraction == 0.0
    done = types.SimpleNamespace(started_s=0.0, ended_s=30.0)
    second = types.SimpleNamespace(running=True, current=0, n=3, outcomes=(done,))
    run = run_of(types.SimpleNamespace(snapshot=types.SimpleNamespace(control=c), row=second,
                                       executing=None), arm, LegTimer(arm), names)
    assert run.name == "Object 1" and run.object_text() == "Object 1 (object 2 of 3)"
    # 30 s a object: this one 25 s more (5 s since the last ended), then one more object
    assert run.row_remaining_s == pytest.approx(25.0 + 30.0)
    assert 1 / 3 <= run.fraction < 2 / 3
    from console.panels.soft_arm.control_row import row_html
    report = types.SimpleNamespace(running=True, current=2, n=3, outcomes=(), released=0,
                                   state="running", row_id=1, reason=None)
    line = row_html(types.SimpleNamespace(row=report, snapshot=types.SimpleNamespace(control=c)),
                    None)
    assert "object 1 of 3 (object 3): planning · 0 released so far" in line
    # the header's phase counts the same way (it said "object 3 of 3" beside "object 2 of 3")
    from console.panels.soft_arm.control_row import row_header_phase
    approach = types.SimpleNamespace(**{**vars(c), "phase": "approach", "n_waypoints": 6})
    view = types.SimpleNamespace(row=report, snapshot=types.SimpleNamespace(control=approach))
    assert row_header_phase(view, None) == (
        "object 1 of 3: approach · waypoint 1 of 6 · ARMED", "busy")
    later = types.SimpleNamespace(**{**vars(report), "outcomes": (done,)})
    view = types.SimpleNamespace(row=later, snapshot=types.SimpleNamespace(control=approach))
    assert row_header_phase(view, None)[0].startswith("object 2 of 3: approach")
