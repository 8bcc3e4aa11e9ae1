"""Browser test of the Control panel on the simulated arm (serve.py --hardware mock).

Chromium places an object at one of the paper's spots (core.control.trials.paper_locations),
presses *Execute grasp-and-place* and reads the state machine's phase from the Control panel
until it shows "released". Then it starts the grasp again, presses *STOP* while the arm is
on its way, and reads the panel: the phase must become "stopped", the tip readout must settle
(bounded) and then hold, having carried on toward the object by no more than the soft segments
catching up with the held cylinder volumes, while over the same time before STOP it moved (so
the hold check can fail). A screenshot of the Control panel mid-run goes to
``artifacts/browser_control_panel.png``.

The arm is a test copy of the soft arm that moves three times faster with shorter waits
(tests/robot_files.py QUICK_MOTION; its link, watchdog and plant are the shipped ones): the tests
are about what the Control panel and STOP do, not the shipped timing.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser_tabs import close_notices, open_console, open_tab, wait_until
from robot_files import QUICK_MOTION, robot_copy

from core.control.trials import paper_locations

pytestmark = pytest.mark.browser
SPOT = "E"  # (-0.08, 0.33): the quickest of the five (about 9 s approach, 9 s return in sim at
# the shipped speed; a third of that on the QUICK_MOTION copy)
# What the test reads after STOP is the drawn arm: the readout and the kappa table show the
# frame the 3D view last sent, and the view sends a held arm's frame only when the drawn frames,
# averaged over up to 2 s, leave a 0.5 mm band (console.scene.dead_band). So a held arm's readout
# stays on one frame for seconds, then jumps to a newer single frame, each carrying the
# measurement's noise (0.2 mm marker noise -> fitted tip ~0.5 mm per axis, kappa 0.04 (segment
# 1) to 0.34 1/m (segment 6) per frame): two windows on either side of such a jump differ by
# up to ~3 sigma of a difference of two frames, 2.5 mm and 1.5 1/m. And the arm itself settles
# after STOP: the segments lag the held cylinder volumes (tau 0.125-0.25 s) and a segment still
# more than 0.3 1/m behind may stick for up to 1 s and then slip (soft-arm.toml [sim]); in sim
# the tip carried on by 2-3.5 mm (at most 5.8 mm) and was within 0.3 mm of its end within 1.2 s.
# So: wait (at most SETTLE_S) until two successive windows agree within TIP_TOL_MM, then the
# tip must stay there over HOLD_S, and it may be at most CARRY_MM (plus what it covers at its
# pre-STOP speed in READOUT_LAG_S, the readout's lag) from where the readout showed it when the
# panel first said "stopped". (Those figures are the shipped speed's; on the QUICK_MOTION copy
# one browser run measured 24.6 mm/s before STOP and a carry of 0.9 mm, allowed 18.3 mm.)
KAPPA_TOL = 1.5  # 1/m
TIP_TOL_MM = 2.5
TIP_MOVING_MM = 2.0  # per WINDOW_S before STOP (measured: 3-21 mm/s early in the approach)
CARRY_MM = 6.0
READOUT_LAG_S = 0.5  # view published at 30 Hz, readout at most 10 Hz, websocket, this page
WINDOW_S = 1.0
SETTLE_S = 8.0
HOLD_S = 3.0
LEASE_LOST = "went silent"  # the reason the console gives when a silent tab loses control
RUNNING = ("settling", "planning", "approach", "grasp", "move_to_bin", "release")


def phase(page: Any) -> str:
    return page.locator('[data-testid="control-state"]').get_attribute("data-phase") or ""


def state_text(page: Any) -> str:
    return page.locator('[data-testid="control-state"]').inner_text()


def wait_phase(page: Any, wanted: tuple[str, ...], timeout: float, avoid: tuple[str, ...] = ()
               ) -> str:
    """Poll the panel's phase until it is one of ``wanted`` (fail at once on ``avoid``)."""
    deadline = time.monotonic() + timeout
    while True:
        ph = phase(page)
        if ph in wanted:
            return ph
        if ph in avoid or time.monotonic() > deadline:
            notes = page.locator(".mantine-Notification-root").all_inner_texts()
            link = page.locator('[data-testid="control-link"]').all_inner_texts()
            fault = page.get_by_text("Fault:").all_inner_texts()
            raise AssertionError(f"phase {ph!r}, wanted {wanted}: {state_text(page)!r}; "
                                 f"link {link}; fault {fault}; notifications: {notes}")
        time.sleep(0.05)


def kappa_measured(page: Any, timeout: float = 2.0) -> np.ndarray:
    """The panel's measured kappa per segment; waits out frames with an occluded marker ("–")."""
    cells = page.locator('[data-testid^="kappa-meas-"]')
    deadline = time.monotonic() + timeout
    while True:
        k = np.array([float(t.replace("–", "nan")) for t in cells.all_inner_texts()])
        if k.size and np.all(np.isfinite(k)):
            return k
        assert time.monotonic() < deadline, f"no complete measurement shown: {k}"
        time.sleep(0.05)


def kappa_target(page: Any) -> np.ndarray:
    cells = page.locator('[data-testid^="kappa-ref-"]')
    return np.array([float(t) for t in cells.all_inner_texts()])


def tip_mm(page: Any) -> np.ndarray:
    return np.array([float(page.locator(f'[data-testid="tip-{i}"]').inner_text()
                           .replace("⚠", "")) for i in range(2)])


def window(page: Any, seconds: float = WINDOW_S) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean measured kappa, mean tip (mm) and every target row read over ``seconds``."""
    kappa, tip, target = [], [], []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        kappa.append(kappa_measured(page))
        tip.append(tip_mm(page))
        target.append(kappa_target(page))
        time.sleep(0.1)
    return np.mean(kappa, axis=0), np.mean(tip, axis=0), np.array(target)


def take_control(page: Any) -> None:
    """Desk mode hands control to the first tab (the only one here), but a tab that stalls
    for 2 s while the software renderer starts loses it: then take it (``--no-token``)."""
    holder = page.locator('[data-testid="holder"]')
    if "nobody" not in holder.inner_text():
        return
    open_tab(page, "Session")
    page.get_by_role("button", name="Take control").click()
    deadline = time.monotonic() + 20.0
    while "nobody" in holder.inner_text():
        notes = page.locator(".mantine-Notification-root").all_inner_texts()
        assert time.monotonic() < deadline, f"could not take control: {notes}"
        time.sleep(0.05)
    open_tab(page, "Operate")


def execute_at(page: Any, x: float, y: float) -> None:
    """Put the selected object (Objects panel, mm) at (x, y) m, arm if needed (Execute does not
    arm: issue 19.3) and Execute it (issue 19.1: Execute acts on the selected object)."""
    page.get_by_label("x (mm)", exact=True).fill(f"{x * 1e3:g}")
    page.get_by_label("y (mm)", exact=True).fill(f"{y * 1e3:g}")
    page.keyboard.press("Tab")  # commit the number inputs
    take_control(page)
    if "ARMED" not in state_text(page):
        page.get_by_role("button", name="Arm", exact=True).click()
        deadline = time.monotonic() + 20.0
        while "ARMED" not in state_text(page):
            assert time.monotonic() < deadline, f"not armed: {state_text(page)!r}"
            time.sleep(0.05)
    page.get_by_role("button", name="Execute grasp-and-place").click()


def open_control(page: Any, url: str) -> None:
    """Load the console once every panel is built (this browser's Session role line shows) and
    the Control panel's state line is there."""
    open_console(page, url, "Control", '[data-testid="control-state"]', role="any")


def start_grasp(page: Any, x: float, y: float, until: tuple[str, ...], timeout: float,
                attempts: int = 3) -> None:
    """Execute at (x, y) until the panel shows a phase in ``until``.

    A run that stops only because this tab lost control (the lease: a tab silent for 2 s, which
    a loaded 2-core machine's software renderer can cause) is started again, at most
    ``attempts`` times; any other stop or an idle arm fails at once.
    """
    for attempt in range(attempts):
        execute_at(page, x, y)
        try:
            wait_phase(page, RUNNING, timeout=20.0)  # (the previous phase showed until now)
            wait_phase(page, until, timeout=timeout, avoid=("stopped", "idle", "released"))
            return
        except AssertionError:
            if LEASE_LOST not in state_text(page) or attempt == attempts - 1:
                raise


def quick_arm(tmp_path: Path) -> str:
    """The soft arm's test copy with QUICK_MOTION (tests/robot_files.py), as serve.py's --robot."""
    return str(robot_copy("soft-arm", tmp_path, QUICK_MOTION))


def test_grasp_and_place_reaches_released_and_stop_holds_the_arm(
        page, console_server: Callable[..., str], tmp_path: Path, artifacts_dir: Path) -> None:
    page.set_viewport_size({"width": 1024, "height": 760})  # less for the software renderer
    try:
        run_scenarios(page, console_server(quick_arm(tmp_path), "--no-token"), artifacts_dir)
    except BaseException:
        page.screenshot(path=str(artifacts_dir / "browser_control_failure.png"))
        raise


def run_scenarios(page: Any, url: str, artifacts_dir: Path) -> None:
    open_control(page, url)
    # The control process is up. (Arm reconnects a link that a fault closed.)
    link = page.locator('[data-testid="control-link"]')
    link.wait_for(timeout=60_000)
    assert "mock device" in link.inner_text() and "round trip p99" in link.inner_text()
    close_notices(page)

    # 1. The full grasp-and-place: settle, plan, approach, grasp, carry, release.
    x, y = paper_locations()[SPOT]
    for attempt in range(3):
        start_grasp(page, x, y, ("grasp", "move_to_bin"), timeout=40.0)
        assert np.all(np.isfinite(kappa_measured(page)))  # measured while it runs
        assert "ARMED" in link.inner_text()
        page.locator('[data-testid="control-state"]').scroll_into_view_if_needed()
        page.mouse.move(5, 5)
        page.screenshot(path=str(artifacts_dir / "browser_control_panel.png"))
        try:
            wait_phase(page, ("released",), timeout=40.0, avoid=("stopped", "idle"))
            break
        except AssertionError:  # as in start_grasp: only a lost lease may start it again
            if LEASE_LOST not in state_text(page) or attempt == 2:
                raise
    assert "ARMED" in state_text(page)
    # The released object left the table (a single grasp clears it, as a row does): a new one.
    selected = page.get_by_label("Selected", exact=True)
    wait_until("the released object off the table", lambda: selected.input_value() == "(none)",
               show=lambda: selected.input_value())
    page.get_by_label("x (mm)", exact=True).fill(f"{x * 1e3:g}")
    page.get_by_label("y (mm)", exact=True).fill(f"{y * 1e3:g}")
    page.keyboard.press("Tab")
    page.get_by_role("button", name="Add object").click()
    wait_until("a new object on the table", lambda: selected.input_value() not in ("", "(none)"),
               show=lambda: selected.input_value())

    # 2. Start again, STOP on the way: the arm holds where it is.
    for attempt in range(3):
        start_grasp(page, x, y, ("approach",), timeout=20.0)
        time.sleep(0.3)  # into the approach
        _, tip0, _ = window(page)
        _, tip1, _ = window(page)
        if phase(page) in RUNNING or LEASE_LOST not in state_text(page) or attempt == 2:
            break
    assert phase(page) in RUNNING, state_text(page)
    moved = np.linalg.norm(tip1 - tip0)
    assert moved > TIP_MOVING_MM, f"the tip barely moved before STOP ({moved:.1f} mm)"
    # A tip that went on at that speed would leave the tolerance within HOLD_S: the check can fail.
    assert moved / WINDOW_S * HOLD_S > 2 * TIP_TOL_MM
    page.get_by_role("button", name="STOP (Esc)").click()
    wait_phase(page, ("stopped",), timeout=5.0)
    tip_stop = tip_mm(page)  # the loop stopped the arm before the panel showed it
    assert "STOP pressed by" in state_text(page)  # the header's STOP, naming who pressed it
    hold_after_stop(page, moved / WINDOW_S, tip_stop)


def hold_after_stop(page: Any, speed: float, tip_stop: np.ndarray) -> None:
    """After STOP: the readout settles within SETTLE_S, then holds over HOLD_S, and the tip
    did not go on (toward its target or anywhere) beyond the plant's carry from ``tip_stop``,
    where the readout showed it when the panel said "stopped" (see the constants above);
    ``speed``: the tip's speed before STOP (mm/s)."""
    _, tip_prev, ref_prev = window(page)
    refs = [ref_prev]
    tips = [tip_prev]
    deadline = time.monotonic() + SETTLE_S
    while True:  # settle: two successive windows agree
        k_set, tip_set, ref = window(page)
        refs.append(ref)
        tips.append(tip_set)
        if np.linalg.norm(tip_set - tip_prev) <= TIP_TOL_MM:
            break
        assert time.monotonic() < deadline, (
            f"the tip did not settle within {SETTLE_S:.0f} s of STOP: windows "
            f"{np.round(tips, 1).tolist()} mm")
        tip_prev = tip_set
    t_set = time.monotonic() - WINDOW_S / 2
    time.sleep(max(0.0, HOLD_S - WINDOW_S))
    k_end, tip_end, ref_end = window(page)
    refs.append(ref_end)
    assert phase(page) == "stopped"
    assert np.all(np.vstack(refs) == refs[0][0]), "the target moved after STOP"
    held = np.max(np.abs(k_end - k_set))
    assert held <= KAPPA_TOL, f"mean measured kappa moved by {held:.2f} 1/m: {k_set} -> {k_end}"
    drift = np.linalg.norm(tip_end - tip_set)
    assert drift <= TIP_TOL_MM, (f"the held tip moved by {drift:.2f} mm over "
                                 f"{time.monotonic() - t_set:.1f} s: {tip_set} -> {tip_end}")
    # Not on toward the object (nor anywhere else): from where it was when STOP showed, the arm
    # moved only as far as the segments catching up with the held cylinder volumes take it. An
    # arm that went on for the settle and hold windows (>= 5 s at over TIP_MOVING_MM per second)
    # would be further.
    carry = float(np.linalg.norm(tip_end - tip_stop))
    allowed = CARRY_MM + speed * READOUT_LAG_S
    assert carry <= allowed, (
        f"the tip went on after STOP: {carry:.1f} mm from where it was when STOP showed "
        f"(allowed {allowed:.1f} mm; {speed:.1f} mm/s before STOP): {tip_stop} -> {tip_end}")


def test_click_to_grasp_on_the_default_emulator_console(
        page, console_server: Callable[..., str], tmp_path: Path, artifacts_dir: Path) -> None:
    """The demo as a person runs it: serve.py's default device (the emulator on a pty, mocap over
    UDP), *Click to grasp*, one click on the table at spot E: the object is placed where the
    click ray meets the table and the arm approaches, grasps, carries and releases it (the
    QUICK_MOTION copy of the soft arm, as the other test here)."""
    from test_planner_browser import project

    page.set_viewport_size({"width": 1024, "height": 760})
    try:
        open_control(page, console_server(quick_arm(tmp_path), "--no-token", "--hardware",
                                          "emulator"))
        link = page.locator('[data-testid="control-link"]')
        link.wait_for(timeout=60_000)
        assert "emulator" in link.inner_text(), link.inner_text()
        close_notices(page)
        take_control(page)
        page.get_by_role("button", name="Arm", exact=True).click()  # Execute does not arm
        deadline = time.monotonic() + 20.0
        while "ARMED" not in state_text(page):
            assert time.monotonic() < deadline, f"not armed: {state_text(page)!r}"
            time.sleep(0.05)
        page.get_by_label("Click to grasp", exact=True).check()
        x, y = paper_locations()[SPOT]
        box = page.locator("canvas").first.bounding_box()
        assert box is not None
        for attempt in range(3):  # a busy software-rendered page can drop a canvas click
            page.mouse.click(*project((x, y, 0.0), box["width"], box["height"]))
            try:
                wait_phase(page, RUNNING, timeout=15.0)
                break
            except AssertionError:
                if attempt == 2:
                    raise
        placed = (float(page.get_by_label("x (mm)", exact=True).input_value()) / 1e3,
                  float(page.get_by_label("y (mm)", exact=True).input_value()) / 1e3)
        assert np.hypot(placed[0] - x, placed[1] - y) < 0.01, placed  # the Objects panel's
        wait_phase(page, ("grasp", "move_to_bin"), timeout=40.0, avoid=("stopped", "idle"))
        page.mouse.move(5, 5)
        page.screenshot(path=str(artifacts_dir / "browser_click_to_grasp.png"))
        wait_phase(page, ("released",), timeout=40.0, avoid=("stopped", "idle"))
        assert "ARMED" in link.inner_text()
    except BaseException:
        page.screenshot(path=str(artifacts_dir / "browser_click_to_grasp_failure.png"))
        raise
