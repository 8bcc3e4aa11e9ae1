"""Browser test of issue #17.3 in the console: clear three objects into a clicked bin.

An in-process console (Objects and Control panels, the real control process on the simulated
arm, desk mode) in headless Chromium: three objects on the table (Object 1 and two placed by
clicks), the bin placed by a click after choosing "Table click places: Bin", Arm, *Clear table
into bin*. Checked in the page: the header's phase and the Control panel say "object k of 3"
while the row runs (a screenshot is taken mid-row, ``artifacts/browser_row_mid.png``), and the
panel lists three released objects at the end; on the server: the control process's report says
3 released and the released objects left the Objects panel's table.

The arm is a test copy of the soft arm that moves three times faster with shorter waits
(tests/robot_files.py QUICK_MOTION): the test is about the console's row, not the shipped timing.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from browser_tabs import close_notices, close_notices_until_none, open_console
from lab_rig import wait_for
from robot_files import QUICK_MOTION, robot_copy
from test_planner_browser import project

pytestmark = pytest.mark.browser
OBJECT_2, OBJECT_3 = (-0.16, 0.28), (-0.08, 0.33)
BIN_XY = (0.09, 0.40)  # clear of the objects and the straight arm (its box is 100 mm wide)
ROW_TIMEOUT_S = 400.0


def notes(page: Any) -> list[str]:
    return page.locator(".mantine-Notification-root").all_inner_texts()


@pytest.fixture
def row_console(tmp_path: Path) -> Iterator[tuple[Any, str]]:
    """The console: Objects + Control panels, the control process on the quick soft arm, desk
    mode with a long lease (a loaded machine's software renderer may stall the tab; a lost
    lease would STOP the row)."""
    import viser

    from console.core.access import AccessControl
    from console.panels.soft_arm import planner
    from console.panels.soft_arm.control import ControlPanel
    from console.panels.soft_arm.objects import ObjectsPanel
    from core.robots import load
    from fakes import console_app

    robot = load(robot_copy("soft-arm", tmp_path, QUICK_MOTION))
    planner.GraspSession.compute_reach = False  # (the shading plays no part here)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(robot, server, panels=(ObjectsPanel, ControlPanel), soft_control="process",
                      access=AccessControl(None, first_client_takes_control=True, lease_s=60.0,
                                           first_answer_s=120.0))
    app.start()
    try:
        yield app, f"http://127.0.0.1:{server.get_port()}/"
    finally:
        app.stop_motion("test over")
        app.stop()
        app.panel(ControlPanel).close()
        app.grasp_session.close()
        server.stop()
        planner.GraspSession.compute_reach = True


def click_table(page: Any, xy: tuple[float, float], done: str, what: str) -> None:
    """Click the table at ``xy`` until the JS predicate ``done`` holds (a busy software renderer
    can drop a canvas click, and a notification over the canvas takes it)."""
    box = page.locator("canvas").first.bounding_box()
    assert box is not None
    px, py = project((*xy, 0.0), box["width"], box["height"])
    for attempt in range(3):
        try:
            close_notices_until_none(page)
        except AssertionError:  # a starved page closes a notice slowly: click anyway, retry
            pass
        page.mouse.click(box["x"] + px, box["y"] + py)
        try:
            page.wait_for_function(done, timeout=10_000)
            return
        except Exception:  # noqa: BLE001 - clicked again, or reported
            if attempt == 2:
                raise AssertionError(f"{what}: {notes(page)}") from None


def objects_info(n: int) -> str:
    return ("() => document.querySelector('[data-testid=\"objects-info\"]')"
            f".innerText.startsWith('{n} objects')")


def test_three_objects_are_cleared_into_a_clicked_bin(page, row_console,
                                                      artifacts_dir: Path) -> None:
    from console.panels.soft_arm.control import ControlPanel

    app, url = row_console
    control = app.panel(ControlPanel)
    session = app.grasp_session
    try:
        page.set_viewport_size({"width": 1280, "height": 900})
        page.set_default_timeout(120_000)  # a starved software renderer acts slowly
        open_console(page, url, "Control", '[data-testid="control-state"]', timeout_ms=90_000)
        wait_for(lambda: app.access.holder is not None, timeout=30.0)  # desk mode: this tab
        state = page.locator('[data-testid="control-state"]')
        row = page.locator('[data-testid="row-status"]')

        # Three objects: Object 1 is there; two more by clicks.
        click_table(page, OBJECT_2, objects_info(2), "second object")
        click_table(page, OBJECT_3, objects_info(3), "third object")
        # The bin: "Table click places: Bin", then a click.
        close_notices(page)
        page.get_by_label("Table click places").click()
        page.get_by_role("option", name="Bin", exact=True).click()
        wait_for(lambda: page.get_by_label("Table click places").input_value() == "Bin", 60.0)
        click_table(page, BIN_XY, "() => document.querySelector('[data-testid=\"objects-info\"]')"
                    ".dataset.bin !== ''", "bin")
        assert len(session.view().objects) == 3 and session.view().bin is not None
        page.screenshot(path=str(artifacts_dir / "browser_row_scene.png"), timeout=120_000)

        # Without arming: refused, nothing runs.
        close_notices(page)
        page.get_by_role("button", name="Clear table into bin").click()
        wait_for(lambda: any("Arm first" in t for t in notes(page)), 60.0)
        assert control.ctl.view.row is None
        close_notices(page)
        page.get_by_role("button", name="Arm", exact=True).click()
        wait_for(lambda: "ARMED" in state.inner_text(), 60.0)
        page.get_by_role("button", name="Clear table into bin").click()
        wait_for(lambda: row.get_attribute("data-state") == "running", 60.0)

        header = page.locator('[data-testid="header-phase"]')
        seen: set[int] = set()  # k of the header's "object k of 3: <phase>"
        shot = False
        end = time.monotonic() + ROW_TIMEOUT_S
        while control.ctl.view.row.running:  # the server's row (a starved page lags behind)
            assert time.monotonic() < end, f"row still running: {control.ctl.view.row}"
            text = header.inner_text()
            now = {k for k in (1, 2, 3) if f"object {k} of 3: " in text}
            seen |= now
            if now - {1} and not shot:  # mid-row: object 1 released, the next one under way
                page.screenshot(path=str(artifacts_dir / "browser_row_mid.png"),
                                timeout=120_000)
                shot = True
            time.sleep(0.2)
        report = control.ctl.view.row
        assert report.state == "done", row.inner_text()
        assert report.released == 3 and [o.status for o in report.outcomes] == ["released"] * 3
        wait_for(lambda: row.get_attribute("data-released") == "3", 120.0)  # the page follows
        assert row.locator('li[data-status="released"]').count() == 3
        # (a starved page may miss a whole turn while it takes the screenshot: 1 and 2 or 3)
        assert 1 in seen and len(seen) >= 2, seen
        wait_for(lambda: not session.view().objects, 60.0)  # the released ones left the table
        wait_for(lambda: page.locator('[data-testid="objects-info"]').inner_text()
                 .startswith("0 objects"), 60.0)
        page.screenshot(path=str(artifacts_dir / "browser_row_done.png"), timeout=120_000)
        assert shot, f"no screenshot mid-row; the header said object {seen} of 3"
    except BaseException:
        from playwright.sync_api import Error as PlaywrightError
        try:  # its own failure must not hide the test's
            page.screenshot(path=str(artifacts_dir / "browser_row_failure.png"), timeout=30_000)
        except PlaywrightError:
            pass
        raise
