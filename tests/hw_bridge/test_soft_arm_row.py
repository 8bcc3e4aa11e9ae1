"""Several objects in a row through the soft arm's control process on the device emulator (issue
#17.3): RunRow is refused while disarmed (nothing placed) and for bad input, takes two objects
to a bin placed on the table one after another (each put into the emulator's world by the
process's placer thread when its turn begins), refuses other tasks meanwhile, and the
operator's STOP ends a row with the rest skipped.

Independent expectations: every object ends at the placed bin point (the emulator's own world,
through its scene channel), each object appears at its spot in the mocap stream when its turn
begins, and the report's outcomes are in queue order.

Two objects, on a test copy of the soft arm that moves three times faster with shorter waits
(tests/robot_files.py QUICK_MOTION): what this test adds is the process around the row (the
placer, the report, STOP); the row itself runs three objects on core's control cycle in
tests/core/test_control_row.py. The same process on the simulated arm (objects put into the
world from the loop thread) runs a three-object row to "3 released" in the console in
tests/console/test_row_process.py."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robot_files import QUICK_MOTION, robot_copy

from core.control.row import bin_at
from core.robots import load
from hw_bridge.soft_arm_process import ControlProcess

R = 0.0165
OBJECTS = ((-0.22, 0.20, R), (-0.08, 0.33, R))
BIN_XY = (0.05, 0.40)  # clear of the objects (its box is 100 mm wide)


def wait_for(pred, timeout=20.0, what="condition", every=None):
    end = time.monotonic() + timeout
    while True:
        try:
            if every is not None:
                every()
            if pred():
                return
        except (AttributeError, TypeError):
            pass  # view not there yet
        if time.monotonic() > end:
            raise AssertionError(f"{what} not reached within {timeout} s")
        time.sleep(0.02)


def quick_robot(tmp_path: Path) -> Any:
    """The soft arm with QUICK_MOTION, no stick-slip and a link that tolerates a starved process:
    watchdog 1 s, link timeout 0.8 s (shipped: 50 / 40 ms). On a shared, loaded machine the
    shipped timing trips the emulator's watchdog within seconds (test_soft_arm_emulator's
    subject); the row is this test's. With stick-slip at three times the shipped speed the
    approach brushed its object (pushed ~10 mm, then a re-plan) in 4 of 6 diagnostic runs on a
    loaded machine (2026-12-04), 2 of which then failed the row (a re-plan's carry around the
    waiting object not found within its budget; pushed again three times); the state machine's
    re-plans are tested on a simulated clock (tests/core/test_control_state_machine.py,
    test_replan_obstacles.py). Without stick-slip 3 of 3 such runs released both objects
    without a re-plan."""
    changes = {**QUICK_MOTION, "bridge.watchdog_ms": 1000, "bridge.link_timeout_ms": 800,
               "sim.stall_rate_hz": 0.0}
    return load(robot_copy("soft-arm", tmp_path, changes, name="soft-arm-quick-slack-link"))


@pytest.mark.slow(67)  # s on 2 busy cores (2026-12-05)
def test_two_objects_to_a_placed_bin_then_stop_a_row(tmp_path):
    robot = quick_robot(tmp_path)
    bin_params = bin_at(robot, *BIN_XY)
    ctl = ControlProcess(robot, seed=2, device="emulator", sched_priority=None)
    try:
        wait_for(lambda: ctl.view.link.state == "inactive", what="configured link")
        with pytest.raises(RuntimeError, match=r"Arm first \(press Arm\)"):
            ctl.run_row(1, OBJECTS, BIN_XY, bin_params.kappa).result(10)
        time.sleep(0.3)
        assert ctl.view.object_xy is None and ctl.view.row is None  # nothing placed or run
        ctl.arm().result(10)
        wait_for(lambda: ctl.view.snapshot.control.prepressurised, timeout=60.0,
                 what="pre-pressure")
        # Bad input: a clear message, nothing runs.
        with pytest.raises(RuntimeError, match="6 curvatures within ±16.7 1/m"):
            ctl.run_row(9, OBJECTS, BIN_XY, [99.0] * 6).result(10)
        with pytest.raises(RuntimeError, match="radius"):
            ctl.run_row(9, [(-0.1, 0.3, 0.0)], BIN_XY, bin_params.kappa).result(10)
        time.sleep(0.2)
        assert ctl.view.row is None and ctl.view.snapshot.control.phase == "idle"

        ctl.run_row(1, OBJECTS, BIN_XY, bin_params.kappa).result(10)
        seen: dict[int, tuple[float, float]] = {}  # where each object was first seen on its turn

        def watch() -> None:
            v = ctl.view
            if v.fault:  # a starved link (as in test_soft_arm_emulator on a loaded machine)
                raise AssertionError(f"the link failed during the row: {v.fault}")
            r, c = v.row, v.snapshot.control
            if r is not None and r.running and r.current not in seen and c.object_xy is not None:
                spot = OBJECTS[r.current]
                if np.hypot(c.object_xy[0] - spot[0], c.object_xy[1] - spot[1]) < 0.005:
                    seen[r.current] = (float(c.object_xy[0]), float(c.object_xy[1]))

        wait_for(lambda: ctl.view.row is not None and ctl.view.row.running, what="row running")
        # (before anything else: the object lies at its spot only until it is grasped)
        wait_for(lambda: 0 in seen, what="object 1 at its spot", every=watch)
        with pytest.raises(RuntimeError, match=r"object 1 of 2\): press STOP first"):
            ctl.grasp_at(-0.1, 0.3, R).result(10)
        wait_for(lambda: ctl.view.row.state != "running", timeout=400.0, what="row done",
                 every=watch)
        report = ctl.view.row
        assert report.row_id == 1 and report.state == "done" and report.n == 2
        assert [(o.index, o.status, o.reason) for o in report.outcomes] == [
            (0, "released", None), (1, "released", None)]
        assert sorted(seen) == [0, 1]  # each appeared at its own spot when its turn began
        # The last object lies in the placed bin in the emulator's world (its scene channel;
        # the view's world may be a tick behind the report: wait for it).

        def in_bin() -> bool:
            v = ctl.view
            return v.object_xy is not None and not v.captured and np.hypot(
                v.object_xy[0] - BIN_XY[0], v.object_xy[1] - BIN_XY[1]) < bin_params.drop_radius_m

        wait_for(in_bin, what=f"the last object in the placed bin (at {ctl.view.object_xy})")

        # A second row, stopped by the operator: the rest is skipped with the reason.
        ctl.run_row(2, OBJECTS[:2], BIN_XY, bin_params.kappa).result(10)
        wait_for(lambda: ctl.view.row.row_id == 2 and ctl.view.row.running, what="row 2")
        ctl.stop_arm("operator STOP").result(10)
        # (the view's report and telemetry may be a tick apart: wait for both)
        wait_for(lambda: ctl.view.row.state == "stopped"
                 and ctl.view.snapshot.control.phase == "stopped", what="row 2 stopped")
        report = ctl.view.row
        assert [(o.status, o.reason) for o in report.outcomes] == [
            ("failed", "operator STOP"), ("skipped", "row stopped: operator STOP")]
        assert ctl.view.snapshot.control.reason == "operator STOP"
    finally:
        ctl.close()
