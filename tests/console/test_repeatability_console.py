"""The Repeatability panel's comparison in the console ``serve.py --robot extensible --slip 0.2``
builds, without a browser: the device emulator's racks slip on their pinions and it streams a
noisy tip, and one click runs two moves open loop and two closed loop on the tip to a bent point.

The closed loop's spread and mean error must come out below the open loop's (20 % slip: the open
loop misses by more than 5 mm), with Table I's hardware rows beside them and a dot per move in the
plot. ``serve.build`` runs in this process; a raw websocket tab holds the lease and types the
point, and FakeClient clicks with that tab's id press Connect, Arm device and Run. The panel's
arithmetic against a fake runner is in test_repeatability_compare.py, the runner's loops on the
slipping emulator in tests/hw_bridge/test_extensible_closed_loop.py; this is their wiring through
serve.py's --slip (was tests/browser/test_browser_repeatability.py).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from robot_files import robot_copy
from test_extensible_console_flows import arm_link, attr, served, tab  # noqa: F401 (fixtures)

from console.panels.common.hardware import HardwarePanel, extensible_link_health
from console.panels.extensible.repeatability import RepeatabilityPanel
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load
from fakes import FakeClient, user
from tests.ws_client import wait_for

ROBOT = load("extensible")
# A point with both segments bent (core.control.repeatability.sample_targets, seed 1): about
# 3 s of motor travel from retracted, so 2 + 2 moves take well under a minute.
POINT_MM = (-50.3, 151.8, 322.5)
MOVES = 2
# Twice the shipped speed limits (tip, racks, motors) and emulated motors (still 20 % above the
# planner's limit): the comparison is about positioning (slip is a fraction of each move's
# travel, whatever the speed), not the paper's 10 cm/s. Link timeout and watchdog 0.5 s: not
# about a loaded box's timing either.
QUICK_EXTENSION = {"limits.tip_speed": 0.2, "limits.rack_speed": 0.1, "limits.motor_speed": 0.1,
                   "emulator.motor_speed_counts": 9120.0,
                   "bridge.watchdog_ms": 500, "bridge.link_timeout_ms": 500}


def mm(html: str, testid: str) -> float:
    found = re.search(rf'data-testid="{testid}"[^>]*data-mm="([-0-9.]+)"', html)
    assert found, (testid, html)
    return float(found.group(1))


@pytest.mark.slow(22)  # s on 2 busy cores (2026-12-05)
def test_closed_loop_beats_open_loop_in_the_repeatability_panel(
        tab: Callable[..., Any], tmp_path: Path) -> None:
    assert solve_tip_ik(ROBOT, np.array(POINT_MM) / 1e3).reachable
    robot_file = robot_copy("extensible", tmp_path, QUICK_EXTENSION, name="extensible")
    app, client = tab(str(robot_file), "emulator", "--slip", "0.2")
    panel = app.panel(RepeatabilityPanel)
    hardware = app.panel(HardwarePanel)
    operator = FakeClient(client.client_id)
    assert attr(panel.note.content, "data-state") == "slip", panel.note.content
    # serve.py connected the emulator at start, disarmed: the operator connects and arms it.
    user(hardware.connect_btn, operator)
    wait_for(lambda: (h := extensible_link_health(app)) is not None and h.state == "inactive",
             timeout=30.0, what=lambda: f"the link configured ({extensible_link_health(app)})")
    arm_link(app, hardware, operator)

    for handle, value in zip(panel.inputs, POINT_MM):
        assert client.update(handle._impl.uuid, value=float(value))
    assert client.update(panel.count._impl.uuid, value=float(MOVES))
    wait_for(lambda: [float(h.value) for h in panel.inputs] == list(POINT_MM)
             and int(panel.count.value) == MOVES, what="the typed point and count")
    user(panel.run_btn, operator)
    wait_for(lambda: 'data-testid="rep-compare"' in panel.table.content, timeout=30.0,
             what="the comparison running")
    wait_for(lambda: attr(panel.table.content, "data-state") != "running", timeout=180.0,
             what=lambda: f"the comparison done ({panel.status.content}; told {operator.notes})")
    table, plot = panel.table.content, panel.plot.content
    assert attr(table, "data-state") == "done", (table, panel.status.content)
    for loop in ("open", "closed"):
        assert f'data-testid="rep-{loop}-moves">{MOVES}/{MOVES}<' in table
    open_spread, closed_spread = mm(table, "rep-open-spread"), mm(table, "rep-closed-spread")
    open_error, closed_error = mm(table, "rep-open-mean"), mm(table, "rep-closed-mean")
    assert closed_spread < open_spread, (open_spread, closed_spread)
    assert closed_error < open_error and open_error > 5.0, (open_error, closed_error)  # slip
    verdict = re.search(r'data-testid="rep-verdict"[^>]*>(.*?)</div>', table)
    assert verdict and "Closed loop beats open loop" in verdict.group(1), table
    assert mm(table, "rep-table-i-1") == 19.0 and mm(table, "rep-table-i-2") == 29.0
    assert plot.count('class="rep-dot-open"') == MOVES
    assert plot.count('class="rep-dot-closed"') == MOVES
    assert app.access.is_operator(client.client_id)
