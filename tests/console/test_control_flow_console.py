"""The soft arm's Control panel on the control process, end to end without a browser: the console
``serve.py --no-token`` builds for the quick soft arm (``serve.build``, in this process).

* On mock hardware (``--hardware mock``) the selected object typed at the paper's spot E is
  grasped and placed to "released" from *Execute grasp-and-place*, measured all the while; the
  released object leaves the table. A second run, stopped by the header's STOP during the
  approach, holds the arm: the state line says "STOP pressed by" its presser, the target
  curvatures stay as they were at the STOP, and the measured tip, which moved before the STOP,
  settles and then holds, no further from where it was at the STOP than the segments catching up
  with the held cylinder volumes take it.
* On the default device (``--hardware emulator``: the emulator on a pty, mocap over UDP), with
  *Click to grasp* on, one click on the table at spot E sent by a raw websocket client (a real
  tab: viser's own dispatch, the client guard, the lease's probes answered) places the object
  where the click's ray meets the table and the arm grasps and releases it.

These were tests/browser/test_browser_control.py (Chromium reading the page). Independent
expectations: the paper's spot E, the tip's planar forward kinematics of the loop's measured
curvatures, the plant's settling after a STOP (data/robots/soft-arm.toml [sim]: the segments lag
the held volumes by 0.125-0.25 s, and one lagging its drive may stick for up to 1 s, then slip up
to 50 % past; at the shipped speed the tip carried on by at most 5.8 mm, on the quick copy up to
what it covers at its pre-STOP speed while stuck and slipping). A real click's mapping from
pixels to the table stays tested in tests/browser/test_canvas_browser.py.
"""

from __future__ import annotations

import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import viser
from robot_files import QUICK_MOTION, robot_copy

from console.core.grasp_session import GraspSession
from console.panels.soft_arm.control import ControlPanel
from console.panels.soft_arm.objects import ObjectsPanel
from core.control.trials import paper_locations
from core.kinematics import planar
from fakes import FakeClient, user
from tests.ws_client import RawClient, wait_for

# A patient link (0.5 s for a STATE and for the device's watchdog, not the shipped 40 / 50 ms):
# this test is about what the console and the control process do, not link timing, and the
# suite runs it beside another test on two busy cores (link gaps: benchmarks/link_gaps.py).
PATIENT_LINK = {"bridge.watchdog_ms": 500, "bridge.link_timeout_ms": 500}

SPOT = "E"  # (-0.08, 0.33): the quickest of the five spots
RUNNING = ("settling", "planning", "approach", "grasp", "move_to_bin", "release")
RUN_TIMEOUT_S = 60.0
WINDOW_S = 1.0
TIP_MOVING_MM = 2.0  # per WINDOW_S before STOP (the browser saw 3-21 mm/s early in the approach)
TIP_TOL_MM = 1.0  # two windows' mean tips (no readout frames here: every published view)
SETTLE_S = 30.0  # (about 2 s: an arm that went on after STOP fails the carry check)
HOLD_S = 3.0
CARRY_MM = 6.0  # the plant's carry after STOP at the shipped speed (at most 5.8 mm in sim)
SIM = tomllib.loads((Path(__file__).resolve().parents[2] / "data" / "robots" / "soft-arm.toml")
                    .read_text())["sim"]
# A segment lagging its drive may stick for up to stall_duration_s[1], building up what it would
# have covered at the pre-STOP speed, then slip past it by up to slip_overshoot of that: on the
# QUICK_MOTION copy this is what the carry is made of (one run: 9.8 mm at 9.6 mm/s, still
# within 0.7 s). An arm that went on over the settle and hold windows would be further.
CATCH_UP_S = SIM["stall_duration_s"][1] * (1.0 + SIM["slip_overshoot"])
KAPPA_TOL = 0.5  # 1/m, mean measured curvature per segment over a window


@pytest.fixture
def served(served_console: Callable[..., Any], tmp_path: Path,
           monkeypatch: pytest.MonkeyPatch) -> Callable[[str], Any]:
    """``served(hardware)``: the console serve.py builds for the quick soft arm with
    ``--hardware`` that, ``--no-token``, not started (conftest ``served_console``)."""
    monkeypatch.setattr(GraspSession, "compute_reach", False)  # (no part here)
    robot = robot_copy("soft-arm", tmp_path, {**QUICK_MOTION, **PATIENT_LINK})
    return lambda hardware: served_console(robot, hardware)


def control_of(app: Any) -> Any:
    """The loop's control telemetry in its latest published view (None before the first)."""
    view = app.panel(ControlPanel).ctl.view
    return None if view is None else view.snapshot.control


def phase(app: Any) -> str:
    c = control_of(app)
    return "" if c is None else c.phase


def measured(app: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The measured curvatures, the tip (mm) by forward kinematics and the target curvatures of
    the latest view; None while a marker is occluded (no complete measurement)."""
    c = control_of(app)
    kappa = None if c is None else c.kappa_meas
    if kappa is None or np.ndim(kappa) != 1 or not np.all(np.isfinite(kappa)):
        return None
    tip = planar.forward_kinematics(kappa, app.robot.lengths, app.robot.base_pose)[-1][:2]
    return np.asarray(kappa, float), tip * 1e3, np.asarray(c.kappa_ref, float).copy()


def window(app: Any, seconds: float = WINDOW_S) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean measured curvatures, mean tip (mm) and every target row over ``seconds``."""
    kappa, tip, target = [], [], []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = measured(app)
        if m is not None:
            kappa.append(m[0])
            tip.append(m[1])
            target.append(m[2])
        time.sleep(0.02)
    assert tip, "no complete measurement in a window"
    return np.mean(kappa, axis=0), np.mean(tip, axis=0), np.array(target)


def wait_phase(app: Any, wanted: tuple[str, ...], avoid: tuple[str, ...] = (),
               timeout: float = RUN_TIMEOUT_S) -> None:
    control = app.panel(ControlPanel)

    def there() -> bool:
        ph = phase(app)
        assert ph not in avoid, (ph, control.state_md.content)
        return ph in wanted

    wait_for(there, timeout=timeout, what=lambda: f"phase in {wanted}: {control.state_md.content}")


def type_object(objects: Any, operator: FakeClient, x: float, y: float) -> None:
    user(objects.x, operator, round(x * 1e3))  # mm in the fields
    user(objects.y, operator, round(y * 1e3))


@pytest.mark.slow(24)  # s on 2 busy cores (2026-12-05)
def test_grasp_and_place_reaches_released_and_stop_holds_the_arm(
        served: Callable[[str], Any]) -> None:
    app = served("mock")
    objects, control = app.panel(ObjectsPanel), app.panel(ControlPanel)
    session = app.grasp_session
    operator = FakeClient(1)
    app.access.take(operator.client_id, None, name="Alice")
    wait_for(lambda: phase(app) == "idle", timeout=30.0, what="the control process's first view")
    wait_for(lambda: "round trip p99" in control.link_md.content, what="the link line")
    assert "mock device" in control.link_md.content, control.link_md.content

    # 1. The full grasp-and-place: settle, plan, approach, grasp, carry, release.
    x, y = paper_locations()[SPOT]
    type_object(objects, operator, x, y)
    wait_for(lambda: [(o.x, o.y) for o in session.view().objects] == [(x, y)],
             what=lambda: f"Object 1 at {(x, y)}: {session.view().objects}")
    user(control.arm_btn, operator)  # Execute does not arm
    wait_for(lambda: control_of(app).armed, timeout=30.0, what=lambda: f"armed ({operator.notes})")
    user(control.execute.execute_btn, operator)
    wait_phase(app, ("grasp", "move_to_bin"), avoid=("stopped", "released"))
    wait_for(lambda: measured(app), what="measured while it runs")
    wait_for(lambda: "ARMED" in control.link_md.content, what="the link line: ARMED")
    wait_phase(app, ("released",), avoid=("stopped", "idle"))
    assert control_of(app).armed
    # The released object left the table (a single grasp clears it, as a row does).
    wait_for(lambda: not session.view().objects and session.view().selected is None,
             what=lambda: f"the released object off the table: {session.view().objects}")
    type_object(objects, operator, x, y)
    user(objects.add_button, operator)
    wait_for(lambda: session.view().selected is not None, what="a new object on the table")
    (obj,) = session.view().objects
    assert (obj.x, obj.y) == (x, y)

    # 2. Start again, STOP on the way: the arm holds where it is.
    user(control.execute.execute_btn, operator)
    wait_phase(app, RUNNING, avoid=("stopped",), timeout=30.0)  # ("released" showed until now)
    wait_phase(app, ("approach",), avoid=("stopped", "idle", "released"))
    time.sleep(0.3)  # into the approach
    _, tip0, _ = window(app)
    _, tip1, _ = window(app)
    assert phase(app) in RUNNING, control.state_md.content
    moved = float(np.linalg.norm(tip1 - tip0))
    assert moved > TIP_MOVING_MM, f"the tip barely moved before STOP ({moved:.1f} mm)"
    # A tip that went on at that speed would leave the tolerance within HOLD_S: the check can fail.
    assert moved / WINDOW_S * HOLD_S > 2 * TIP_TOL_MM
    user(app.header.stop_btn, operator)
    wait_phase(app, ("stopped",), timeout=30.0)
    m = wait_for(lambda: measured(app), what="a measurement at the STOP")
    tip_stop, ref_stop = m[1], m[2]
    wait_for(lambda: "STOP pressed by" in control.state_md.content,
             what=lambda: f"the state line names the STOP: {control.state_md.content}")
    hold_after_stop(app, moved / WINDOW_S, tip_stop, ref_stop)


def hold_after_stop(app: Any, speed: float, tip_stop: np.ndarray, ref_stop: np.ndarray) -> None:
    """After STOP: the tip settles within SETTLE_S, then holds over HOLD_S, and it did not go
    on beyond the plant's carry from ``tip_stop``; the target stays ``ref_stop``. ``speed``:
    the tip's speed before STOP (mm/s)."""
    _, tip_prev, ref_prev = window(app)
    refs, tips = [ref_prev], [tip_prev]
    deadline = time.monotonic() + SETTLE_S
    while True:  # settle: two successive windows agree
        k_set, tip_set, ref = window(app)
        refs.append(ref)
        tips.append(tip_set)
        if np.linalg.norm(tip_set - tip_prev) <= TIP_TOL_MM:
            break
        assert time.monotonic() < deadline, (
            f"the tip did not settle within {SETTLE_S:.0f} s of STOP: windows "
            f"{np.round(tips, 1).tolist()} mm")
        tip_prev = tip_set
    time.sleep(max(0.0, HOLD_S - WINDOW_S))
    k_end, tip_end, ref_end = window(app)
    refs.append(ref_end)
    assert phase(app) == "stopped"
    assert np.all(np.vstack(refs) == ref_stop), "the target moved after STOP"
    held = np.max(np.abs(k_end - k_set))
    assert held <= KAPPA_TOL, f"mean measured kappa moved by {held:.2f} 1/m: {k_set} -> {k_end}"
    drift = float(np.linalg.norm(tip_end - tip_set))
    assert drift <= TIP_TOL_MM, f"the held tip moved by {drift:.2f} mm: {tip_set} -> {tip_end}"
    carry = float(np.linalg.norm(tip_end - tip_stop))
    allowed = CARRY_MM + speed * CATCH_UP_S
    assert allowed < speed * (HOLD_S + 2 * WINDOW_S)  # an arm that went on fails the check
    assert carry <= allowed, (
        f"the tip went on after STOP: {carry:.1f} mm from where it was at the STOP (allowed "
        f"{allowed:.1f} mm; {speed:.1f} mm/s before STOP): {tip_stop} -> {tip_end}")


def test_click_to_grasp_on_the_default_emulator_console(served: Callable[[str], Any]) -> None:
    app = served("emulator")
    control = app.panel(ControlPanel)
    session = app.grasp_session
    app.start()  # a real tab: the lease probes it, as it does a browser
    tab = RawClient(app.server)
    try:
        app.access.take(tab.client_id, None, name="tester")
        wait_for(lambda: phase(app) == "idle", timeout=30.0,
                 what="the control process's first view")
        wait_for(lambda: "emulator" in control.link_md.content, timeout=30.0,
                 what=lambda: f"the link line: {control.link_md.content}")
        assert tab.update(control.arm_btn._impl.uuid, value=True)  # a click on Arm
        wait_for(lambda: control_of(app).armed, timeout=30.0, what="armed")
        assert tab.update(control.execute.click_mode._impl.uuid, value=True)
        wait_for(lambda: control.execute.click_mode.value is True, what="Click to grasp on")
        x, y = paper_locations()[SPOT]
        # The click's ray from 1 m above the spot, straight down (a real page's mapping from
        # pixels to this ray is test_canvas_browser.py's).
        assert tab.send(viser._messages.ScenePointerMessage(
            "click", (x, y, 1.0), (0.0, 0.0, -1.0), ((0.5, 0.5),), None))
        wait_phase(app, RUNNING, avoid=("stopped",), timeout=30.0)
        selected = session.view().selected
        placed = next(o for o in session.view().objects if o.name == selected)
        assert np.hypot(placed.x - x, placed.y - y) < 0.01, placed  # the Objects panel's
        wait_phase(app, ("grasp", "move_to_bin"), avoid=("stopped", "idle"))
        wait_phase(app, ("released",), avoid=("stopped", "idle"))
        assert control_of(app).armed
        wait_for(lambda: "ARMED" in control.link_md.content and "emulator" in
                 control.link_md.content, what=lambda: f"the link line: {control.link_md.content}")
        assert app.access.is_operator(tab.client_id)
    finally:
        tab.close()
