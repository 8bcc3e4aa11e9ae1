"""Two browsers on one console: an operator and a viewer (two Chromium contexts, one in-process
console in lab mode with an operator token, so the test sees the server side).

Checked: a viewer's jog, "Run demo motion" and the Control panel's "Execute grasp-and-place" are
refused with the reason shown to them and move nothing; STOP from the viewer (button and Esc
hotkey) stops the operator's (demo) motion through the stop hooks; a held jog ends when let go
and a STOP latches it; closing (or freezing) the operator's tab stops the arm and releases the
lock. Recording and export:
test_browser_lab_export.py; the rig: lab_rig.py. That a viewer can neither add, edit, plan nor
place objects nor connect the hardware is tested without a browser
(tests/console/test_planner_console.py, test_hw_panel.py, test_lab_access.py).
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from console.core.hold_to_run import HOLD_SOURCE

pytest.register_assert_rewrite("lab_rig")
from browser_tabs import open_tab, wait_until  # noqa: E402
from lab_rig import (field, jog_button, lab,  # noqa: E402,F401 (lab: fixture)
                     notifications, press, session_button, stop_button, wait_for)

pytestmark = pytest.mark.browser


def test_viewer_is_refused_and_stop_from_the_viewer_stops_the_operators_motion(
        lab, artifacts_dir: Path) -> None:
    app = lab.app
    alice, bob = lab.pages(2)
    open_tab(alice, "Session")
    open_tab(bob, "Session")
    field(alice, "Operator token").fill("typed-by-alice")
    time.sleep(0.5)
    assert field(bob, "Operator token").input_value() == ""  # per-browser: never shown to Bob
    lab.take_control(alice, "Alice")
    open_tab(alice, "Session")
    assert field(alice, "Operator token").input_value() == ""  # cleared once used
    assert bob.locator('[data-testid="role"]').get_attribute("data-role") == "viewer"
    wait_for(lambda: "Alice" in bob.locator('[data-testid="holder"]').inner_text())

    before = app.store.command
    press(bob, jog_button(bob, "κ₁", "+"))
    time.sleep(0.5)
    bob.mouse.up()
    wait_for(lambda: any("Only the operator can jog — Alice holds control; ask them or take "
                         "control with the token" in n for n in notifications(bob)))
    # Operator-only buttons are shown disabled to a viewer (a crafted click is refused by the
    # server: tests/console/test_viewer_sees_disabled.py), and a line says who operates.
    demo = session_button(bob, "Run demo motion")
    wait_until("Run demo motion disabled for the viewer", demo.is_disabled, 30)
    open_tab(bob, "Operate")
    execute = bob.get_by_role("button", name="Execute grasp-and-place")  # the Control panel's
    execute.scroll_into_view_if_needed()
    wait_until("Execute disabled for the viewer", execute.is_disabled, 30)
    wait_until("the viewer told who operates",
               lambda: "You are viewing: Alice operates" in bob.locator("body").inner_text(), 30)
    open_tab(alice, "Operate")
    assert not alice.get_by_role("button", name="Execute grasp-and-place").is_disabled()
    assert "You are viewing" not in alice.locator("body").inner_text()
    assert app.store.command is before and not app.services.demo.running
    view = app.services.soft_control.view  # the control process: never armed, no task started
    assert view is None or view.snapshot.control is None or (
        not view.snapshot.control.armed and view.snapshot.control.phase == "idle")

    session_button(alice, "Run demo motion").click()
    wait_for(lambda: app.services.demo.running and app.store.command.source == "demo")
    wait_for(lambda: app.store.command.seq > before.seq + 10)
    stop_button(bob).click()
    wait_for(lambda: lab.stops)
    who = re.fullmatch(r"STOP pressed by client (\d+)", lab.stops[-1][1])
    assert who and int(who.group(1)) != app.access.holder.client_id, lab.stops  # Bob, not Alice
    stopped = app.store.command
    time.sleep(0.5)
    assert not app.services.demo.running and app.store.command.seq == stopped.seq
    assert app.access.holder is not None and app.access.holder.name == "Alice"
    wait_for(lambda: any("stopped the arm" in n for n in notifications(alice)))
    bob.screenshot(path=str(artifacts_dir / "browser_lab_viewer.png"))
    alice.screenshot(path=str(artifacts_dir / "browser_lab_operator.png"))

    # The hotkey: Esc in the viewer's page stops the motion too.
    n_stops = len(lab.stops)
    session_button(alice, "Run demo motion").click()
    wait_for(lambda: app.services.demo.running)
    bob.mouse.click(300, 700)  # focus the 3D view, not a text field
    bob.keyboard.press("Escape")
    wait_for(lambda: len(lab.stops) > n_stops, timeout=3.0)
    assert not app.services.demo.running


@pytest.mark.alone  # hold-to-run renewals and the lease probe from a software-rendered page
def test_held_jog_release_stop_latch_and_closing_or_freezing_the_operators_tab(lab) -> None:
    """What the operator's page does to motion: a held jog moves while held and ends when let
    go; a STOP from the viewer latches it while the button is still held; closing the tab stops
    the arm and frees control; a tab frozen longer than the lease loses control and stops the
    arm. (The expiry and the lease themselves run on a simulated clock in
    tests/console/test_console_core.py and test_lab_access.py; their wall-clock figures in a
    real browser are benchmarks/lease_gaps.py's.)"""
    app = lab.app
    alice, bob = lab.pages(2)
    lab.take_control(alice, "Alice")
    mouse = press(alice, jog_button(alice, "κ₂", "+"))
    wait_for(lambda: app.store.command.source == HOLD_SOURCE, timeout=10.0)
    time.sleep(0.8)
    mouse.up()
    wait_for(lambda: not app.hold.active, timeout=10.0)  # expiry, or the release ended it
    last = app.store.command
    # How far it got depends on how often this busy software-rendered page sent renewals;
    # the server saw the hold (above), so it moved.
    assert last.q[1] > 0.0, "the held jog should have bent segment 2"
    time.sleep(0.5)
    assert app.store.command.seq == last.seq, "the jog went on after its release"

    mouse = press(alice, jog_button(alice, "κ₂", "+"))
    wait_for(lambda: app.store.command.seq > last.seq + 3, timeout=10.0)
    stop_button(bob).click()
    wait_for(lambda: app.store.command.source == "stop", timeout=10.0)
    frozen = app.store.command
    time.sleep(1.0)  # Alice is still holding the button
    assert app.store.command.seq == frozen.seq
    mouse.up()

    # Closing the operator's tab stops the arm and frees control.
    session_button(alice, "Run demo motion").click()
    wait_for(lambda: app.services.demo.running, timeout=10.0)
    n_stops = len(lab.stops)
    alice.context.close()
    wait_for(lambda: len(lab.stops) > n_stops, timeout=10.0)
    assert "Alice's tab" in lab.stops[-1][1], lab.stops
    assert app.access.holder is None and not app.services.demo.running
    wait_for(lambda: "nobody" in bob.locator('[data-testid="holder"]').inner_text())

    # A tab frozen longer than the lease while the arm moves loses control and stops the arm
    # (a still console keeps a frozen tab's lease: it can start nothing, console.lease).
    carol = lab.page()
    lab.take_control(carol, "Carol")
    session_button(carol, "Run demo motion").click()
    wait_for(lambda: app.services.demo.running, timeout=10.0)
    probes = app.lease.probes
    wait_for(lambda: app.lease.probes >= probes + 2, timeout=10.0)  # lease round trips answer
    assert app.access.holder is not None
    n_stops = len(lab.stops)
    lease_s = app.access.lease_s  # 7 s (console.core.access.LEASE_S: measured browsers x 2)
    carol.evaluate("s => { const end = Date.now() + s * 1000; while (Date.now() < end) {} }",
                   lease_s + 1.5)
    wait_for(lambda: len(lab.stops) > n_stops, timeout=10.0)
    assert "silent" in lab.stops[-1][1], lab.stops
    assert app.access.holder is None and not app.services.demo.running
