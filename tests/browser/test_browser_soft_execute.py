"""Browser tests of issue 19 (items 1, 3, 4) on the soft arm's Operate tab (serve.py --hardware
mock, ``--no-token``).

* 19.1: two objects placed by clicking the table, Object 2 selected (a click on it) and planned;
  after Arm, *Execute grasp-and-place* grasps Object 2: the notification and the state line
  name it, and at the grasp the palm (the readout, mm) is at Object 2, not at the old Control
  panel's own object (-160, 280) mm.
* 19.4: during that run the state line counts the planner's waypoints ("approach waypoint k of
  n" with n = the Grasp planner's and the Waypoints panel's count); on first load the planner
  and the Waypoints panel tell the same plan.
* 19.3: a clean start shows no fault (header Link field, Control panel), and Execute while
  disarmed is refused ("Arm first") and does not arm.

The arm is a test copy of the soft arm that moves three times faster with shorter waits
(tests/robot_files.py QUICK_MOTION; its link and watchdog are the shipped ones): the tests are
about which object Execute grasps and what the panels say, not the shipped timing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from browser_tabs import (
    click_scene,
    close_notices,
    close_notices_until_none,
    open_console,
    open_tab,
    wait_until,
)
from robot_files import QUICK_MOTION, robot_copy

# alone: the palm readout follows the drawn arm at the page's frame rate, and the check samples
# it near the object (two Chromiums on 2 cores halve the rate; conftest's SUITE_PART=alone)
pytestmark = [pytest.mark.browser, pytest.mark.alone]
OBJECT_2 = (-0.13, 0.17)  # the paper's spot C: 114 mm from the old Control panel object
OBJECT_3 = (-0.08, 0.33)  # spot E
OLD_CONTROL_OBJECT = (-0.16, 0.28)
RUNNING = ("settling", "planning", "approach", "grasp", "move_to_bin", "release")


def notes(page: Any) -> list[str]:
    return page.locator(".mantine-Notification-root").all_inner_texts()


def told(page: Any) -> Callable[[], str]:
    """What the page says (for a failed wait): the Control panel's state and the notices."""
    return lambda: f"state {state(page).all_inner_texts()}; notifications {notes(page)}"


def open_operate(page: Any, url: str) -> None:
    """Load the console (its per-browser Session widgets there, the demo object planned), hold
    control (desk mode gives it to the first tab; take it if a slow start lost it), and open
    the Operate tab once the Control panel shows the loop."""
    page.set_viewport_size({"width": 1024, "height": 900})
    open_console(page, url, "Control", '[data-testid="plan-summary"][data-state="ok"]',
                 role="any", timeout_ms=90_000)
    hold_control(page)
    show_tab(page, "Operate")
    page.locator('[data-testid="control-link"]').wait_for(timeout=60_000)


def hold_control(page: Any) -> None:
    """Hold control: desk mode gives it to the first tab, but a loaded machine's software
    renderer can stall the tab past its 2 s lease (control released): take it back then."""
    holder = page.locator('[data-testid="holder"]')
    close_notices(page)  # (a notification can cover the tabs)
    if "nobody" not in holder.inner_text():
        return
    show_tab(page, "Session")
    page.get_by_role("button", name="Take control").click(force=True)
    wait_until("take control", lambda: "nobody" not in holder.inner_text(), 20.0,
               show=told(page))
    close_notices(page)
    show_tab(page, "Operate")


def show_tab(page: Any, name: str) -> None:
    """``open_tab``, but the click goes through a notification that arrived meanwhile (the
    "Control released" notices of a stalled tab pile up over the tab bar)."""
    tab = page.get_by_role("tab", name=name, exact=True)
    if tab.get_attribute("aria-selected") != "true":
        tab.click(force=True)
    open_tab(page, name)


def failure_shot(page: Any, path: Path) -> None:
    """A screenshot for the failure report; its own failure must not hide the test's."""
    from playwright.sync_api import Error as PlaywrightError
    try:
        page.screenshot(path=str(path), timeout=10_000)
    except PlaywrightError:
        pass


def state(page: Any) -> Any:
    return page.locator('[data-testid="control-state"]')


def click_table(page: Any, xy: tuple[float, float], count: int) -> None:
    """Click the table at ``xy`` until the Objects panel shows ``count`` objects and selects
    the one there (a busy software renderer can drop a canvas click)."""
    from test_planner_browser import project

    box = page.locator("canvas").first.bounding_box()
    assert box is not None
    info = page.locator('[data-testid="objects-info"]')
    for attempt in range(3):
        hold_control(page)
        # The browser's own "Software WebGL" notice can arrive late and stays until closed; a
        # click while one is shown was lost in a full-suite run (as in test_planner_browser).
        close_notices_until_none(page)
        click_scene(page, *project((*xy, 0.0), box["width"], box["height"]))
        try:
            page.wait_for_function(
                "n => document.querySelector('[data-testid=\"objects-info\"]')"
                ".innerText.startsWith(n + ' objects')", arg=str(count), timeout=8_000)
            return
        except Exception:  # noqa: BLE001 - clicked again below, or reported
            if attempt == 2:
                raise AssertionError(f"click at {xy}: {info.inner_text()!r}; {notes(page)}")


# Every palm readout the page shows, recorded in the page as it changes (a MutationObserver):
# the readout changes up to READOUT_HZ times a second, faster than a loaded machine's round trips
# to Chromium can poll it (a CI run polled past the 0.8 s grasp hold: nearest sample 49 mm off).
RECORD_PALMS = """() => {
  window.__palms = [];
  if (window.__palmObserver) return;
  const text = id => document.querySelector(`[data-testid="${id}"]`)?.textContent;
  window.__palmObserver = new MutationObserver(() => {
    const x = text("palm-0"), y = text("palm-1");
    if (x === undefined || y === undefined) return;
    const p = [parseFloat(x.replace("⚠", "")), parseFloat(y.replace("⚠", ""))];
    const last = window.__palms[window.__palms.length - 1];
    if (!last || last[0] !== p[0] || last[1] !== p[1]) window.__palms.push(p);
  });
  window.__palmObserver.observe(document.body,
                                {subtree: true, childList: true, characterData: true});
}"""


def palm_mm(page: Any) -> tuple[float, float]:
    return tuple(float(page.locator(f'[data-testid="palm-{i}"]').inner_text().replace("⚠", ""))
                 for i in range(2))  # type: ignore[return-value]


def run_to_grasp(page: Any, n: int, palms: list) -> set[str] | None:
    """Arm, Execute, and follow the run to the grasp, checking the object and the waypoint
    count on the way; the approach waypoints seen, or None if a lost lease stopped it."""
    summary = page.locator('[data-testid="plan-summary"]')
    hold_control(page)
    if "ARMED" not in state(page).inner_text():
        page.get_by_role("button", name="Arm", exact=True).click()
        wait_until("armed", lambda: "ARMED" in state(page).inner_text(), 20.0, show=told(page))
    close_notices(page)
    page.get_by_role("button", name="Execute grasp-and-place").click()
    wait_until("told which object", lambda: any("Object 2" in t for t in notes(page)), 10.0,
               show=told(page))
    lost = lambda: "went silent" in state(page).inner_text()  # a stalled tab lost its lease
    wait_until("running", lambda: state(page).get_attribute("data-phase") in RUNNING or lost(),
               20.0, show=told(page))
    if lost():
        return None
    counted: set[str] = set()
    while (ph := state(page).get_attribute("data-phase")) not in ("grasp", "move_to_bin"):
        text = state(page).inner_text()
        if ph == "stopped" and "went silent" in text:
            return None
        assert ph in RUNNING, text
        assert state(page).get_attribute("data-object") == "Object 2" and "Object 2" in text
        assert state(page).get_attribute("data-waypoints") in ("", str(n)), text
        if text.startswith("State: approach"):  # (one read: the phase moves on meanwhile)
            assert f" of {n} (Grasp planner's plan)" in text, text
            counted.add(text.split(" of ")[0].rsplit(" ", 1)[-1])
        assert page.locator('[data-testid="waypoint-info"]').get_attribute(
            "data-count") == str(n) and summary.get_attribute("data-waypoints") == str(n)
        palms.append(palm_mm(page))
        time.sleep(0.05)
    return counted


@pytest.fixture(scope="module")
def operate_page(module_page: Any, module_console_server: Callable[..., str],
                 tmp_path_factory: Any) -> Any:
    """One soft-arm console (``--no-token``, the quick test copy) loaded once for both tests (a
    load costs seconds of software rendering): the clean start is checked first, then the run
    on the same console."""
    robot = robot_copy("soft-arm", tmp_path_factory.mktemp("robot"), QUICK_MOTION)
    open_operate(module_page, module_console_server(str(robot), "--no-token"))
    return module_page


def test_clean_start_shows_no_fault_and_execute_does_not_arm(
        operate_page: Any, artifacts_dir: Path) -> None:
    """Issue 19.3 and 19.4's first load (the first test on this console)."""
    page = operate_page
    try:
        # First load: the planner and the Waypoints panel tell the same plan of Object 1.
        summary = page.locator('[data-testid="plan-summary"]')
        wp = page.locator('[data-testid="waypoint-info"]')
        n = summary.get_attribute("data-waypoints")
        assert n and int(n) >= 2 and "Place an object" not in summary.inner_text()
        wait_until("waypoints agree", lambda: wp.get_attribute("data-count") == n, 10.0,
                   show=told(page))
        assert f"Waypoint 1 of {n}" in wp.inner_text()
        # A clean start: no fault in the header nor in the Control panel, for 5 s.
        header = page.locator('[data-testid="header-link"]')
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            for text in (header.inner_text(), page.locator(
                    '[data-testid="control-link"]').inner_text()):
                assert "link lost" not in text and "ault" not in text, text
            assert page.get_by_text("Fault:").count() == 0
            assert not any("fault" in t.lower() for t in notes(page)), notes(page)
            time.sleep(0.2)
        assert "mock device" in header.inner_text()
        page.screenshot(path=str(artifacts_dir / "browser_soft_clean_start.png"))
        # Execute while disarmed: refused with what to do, and nothing arms.
        assert "disarmed" in state(page).inner_text()
        hold_control(page)
        page.get_by_role("button", name="Execute grasp-and-place").click()
        wait_until("told to arm first",
                   lambda: any("Arm first" in t for t in notes(page)), 10.0, show=told(page))
        time.sleep(2.0)
        assert "disarmed" in state(page).inner_text() and "ARMED" not in state(page).inner_text()
        # (idle, or stopped if a loaded machine's slow tab lost its lease, which STOPs)
        assert state(page).get_attribute("data-phase") in ("idle", "stopped"), \
            state(page).inner_text()
        assert "disarmed" in page.locator('[data-testid="control-link"]').inner_text()
    except BaseException:
        failure_shot(page, artifacts_dir / "browser_soft_clean_start_failure.png")
        raise


def test_execute_grasps_the_selected_planned_object_and_counts_its_waypoints(
        operate_page: Any, artifacts_dir: Path) -> None:
    """Issues 19.1 and 19.4 (on the console the clean-start test left: disarmed, Object 1)."""
    page = operate_page
    try:
        hold_control(page)
        show_tab(page, "Operate")
        close_notices(page)
        click_table(page, OBJECT_2, 2)
        click_table(page, OBJECT_3, 3)
        info = page.locator('[data-testid="objects-info"]')
        assert info.get_attribute("data-selected") == "Object 3"
        click_table(page, OBJECT_2, 3)  # a click on an object selects it
        wait_until("Object 2 selected",
                   lambda: info.get_attribute("data-selected") == "Object 2", 10.0,
                   show=told(page))
        summary = page.locator('[data-testid="plan-summary"]')
        hold_control(page)
        page.get_by_role("button", name="Plan grasp").click()
        planned = page.locator('[data-testid="plan-summary"][data-state="ok"]')
        wait_until("planned", lambda: planned.count() == 1, 20.0, show=told(page))
        n = int(summary.get_attribute("data-waypoints") or 0)
        assert n >= 2
        wait_until("Waypoints panel shows the plan", lambda: page.locator(
            '[data-testid="waypoint-info"]').get_attribute("data-count") == str(n), 10.0,
            show=told(page))
        target = page.locator('[data-testid="control-target"]')
        wait_until("Execute's target", lambda: "Object 2" in target.inner_text(), 10.0,
                   show=told(page))
        assert f"{n}-waypoint plan" in target.inner_text()

        for attempt in range(3):  # only a lost lease (a stalled tab) may start it again
            palms: list = []
            page.evaluate(RECORD_PALMS)
            counted = run_to_grasp(page, n, palms)
            if counted is not None:
                break
            assert attempt < 2, f"lost control three times: {state(page).inner_text()}"
        assert counted, "never saw the approach"
        # The gripper closes on Object 2: the palm (readout, mm; it follows the measured arm at
        # the render rate) comes to it during the run, not to the old Control panel object
        # 114 mm away.
        end = time.monotonic() + 3.0
        while time.monotonic() < end and state(page).get_attribute("data-phase") in (
                "grasp", "move_to_bin"):
            palms.append(palm_mm(page))
            time.sleep(0.1)
        page.screenshot(path=str(artifacts_dir / "browser_soft_execute_object2.png"))
        palms += [tuple(p) for p in page.evaluate("window.__palms")]
        assert palms
        palm = min(palms, key=lambda p: math.hypot(p[0] - OBJECT_2[0] * 1e3,
                                                   p[1] - OBJECT_2[1] * 1e3))
        d2 = math.hypot(palm[0] - OBJECT_2[0] * 1e3, palm[1] - OBJECT_2[1] * 1e3)
        d_old = math.hypot(palm[0] - OLD_CONTROL_OBJECT[0] * 1e3,
                           palm[1] - OLD_CONTROL_OBJECT[1] * 1e3)
        # the palm aims g_off + r = 26.5 mm beside the object's centre
        # (and at most 53 mm off it, the capture region); the old object is 114 mm away
        assert d2 < 55.0 and d_old > d2 + 30.0, (palm, d2, d_old, palms)
    except BaseException:
        failure_shot(page, artifacts_dir / "browser_soft_execute_failure.png")
        raise
