"""Control / trials / capture panels without a browser: the loop process obeys Arm, moves,
holds on STOP (from any source), refuses bad input; trials and capture helpers."""

from __future__ import annotations

import time

import numpy as np
import pytest
import viser

from console.app import ConsoleApp
from console.panels.capture import merge
from console.panels.control import ControlPanel, table_point
from console.panels.trials import results_markdown
from core.control.capture import characterise
from core.control.trials import TrialResult
from core.robots import load

SOFT = load("soft-arm")


def wait_for(pred, timeout=30.0):
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise AssertionError("condition not reached")
        time.sleep(0.02)


@pytest.fixture
def app():
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    a = ConsoleApp(SOFT, srv, panels=(ControlPanel,))
    a.start()
    try:
        yield a
    finally:
        a.stop()
        a.panel(ControlPanel).close()
        srv.stop()


def control(app):
    view = app.panel(ControlPanel).ctl.view
    return None if view is None else view.snapshot.control


def test_arm_move_and_stop_hold_through_the_loop_process(app):
    panel = app.panel(ControlPanel)
    wait_for(lambda: control(app) is not None)
    panel._arm()
    wait_for(lambda: control(app).armed and control(app).prepressurised)
    panel.ctl.goto(np.full(6, 6.0)).result(10)
    wait_for(lambda: control(app).kappa_ref[0] > 1.0)  # moving
    app.stop_motion("test STOP")  # as the Session panel's STOP / hotkey does
    wait_for(lambda: control(app).phase == "stopped")
    held = control(app).commands.copy()
    t = control(app).t
    wait_for(lambda: control(app).t > t + 0.5)
    assert np.array_equal(control(app).commands, held)  # cylinder volumes frozen
    assert control(app).reason == "test STOP"
    with pytest.raises(RuntimeError, match="beyond"):
        panel.ctl.goto(np.full(6, 99.0)).result(10)
    # The 3D view shows the measured arm while armed.
    wait_for(lambda: app.store.display.source == "control")
    # Execute a planner's plan (as "Execute current plan" does): the approach starts.
    from core.planning.grasp import plan_grasp
    plan = plan_grasp(SOFT, np.zeros(6), (-0.16, 0.28), 0.0165)
    panel.ctl.execute(plan, -0.16, 0.28, 0.0165).result(10)
    wait_for(lambda: control(app).phase == "approach" and control(app).n_waypoints == len(plan.kappas))
    app.stop_motion("second STOP")
    wait_for(lambda: control(app).phase == "stopped" and control(app).reason == "second STOP")


def test_click_ray_meets_the_table():
    assert table_point((0.0, 0.0, 1.0), (0.1, -0.2, -1.0)) == pytest.approx((0.1, -0.2))
    assert table_point((0.0, 0.0, 1.0), (0.0, 0.0, 1.0)) is None  # looking up
    assert table_point((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)) is None  # parallel


def test_capture_chunks_merge_to_the_full_map():
    full = characterise(SOFT, spacing=0.01)
    ys = full.ys
    parts = [characterise(SOFT, spacing=0.01, y_range=(float(c[0]), float(c[-1])))
             for c in np.array_split(ys, 3)]
    merged = merge(parts[::-1])
    assert np.array_equal(merged.ys, full.ys) and np.array_equal(merged.outcome, full.outcome)


def test_results_table_counts_successes():
    res = [TrialResult([-0.1, 0.2, 0.0165], True, None, 10.0, 8.0, "A"),
           TrialResult([-0.1, 0.2, 0.0165], False, "tracking lost for 0.50 s", 5.0, 0.0, "A")]
    md = results_markdown(res)
    assert "**1/2 successes**" in md and "tracking lost" in md and md.count("\n| ") == 2  # two result rows
