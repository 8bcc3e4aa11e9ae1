"""Browser test of clicks on the soft arm console's 3D canvas: a click on the table places an
object where the click ray meets z = 0, "Plan grasp" reports Algorithm 1's number of waypoints
(computed here with ``plan_grasp``), stepping reaches the last waypoint on the final circle
r_o + g_off, and an object typed out of reach shows the reason; then the View panel's camera
presets move the presser's camera, and Measure turns two clicks on the table into a distance
everyone sees, placing nothing.

The console is built in this process (``serve.build``) so the test can read what the browser's
camera is on the server side (``client.camera``) and what the panel measured. The expected
distance is computed here from the two clicked pixels: each pixel's ray through the browser's
camera (its pose and field of view as the browser reports them) meets the table plane z = 0.
Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import math
import re
import socket
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest
import viser.transforms as vtf
from browser_tabs import (click_scene, close_notices_until_none, open_folder, open_tab,
                          wait_until)

from core.planning.grasp import plan_grasp
from core.robots import load
from tests.ws_client import wait_for

pytestmark = pytest.mark.browser
ROBOT = load("soft-arm")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def soft_console(serve_module: Any, tmp_path: Path) -> Iterator[tuple[Any, Any, str]]:
    """serve.py's soft-arm console (mock device), in this process: (server, app, url)."""
    port = _free_port()
    args = serve_module.parse_args(["--robot", "soft-arm", "--hardware", "mock", "--port",
                                    str(port), "--rt-cpu", "none", "--no-token",
                                    "--data-dir", str(tmp_path)])
    server, app, _ = serve_module.build(args, load("soft-arm"), "view test")
    app.start()
    try:
        yield server, app, f"http://127.0.0.1:{port}/"
    finally:  # serve.py's shutdown steps
        for step in serve_module._shutdown_steps(app, server):
            step[1]()
        if app.grasp_session is not None:
            app.grasp_session.close()


def the_client(server: Any) -> Any:
    clients = list(server.get_clients().values())
    assert len(clients) == 1
    return clients[0]


def pixel_ray(cam: Any, px: float, py: float, width: float, height: float) -> tuple:
    """The world ray of canvas pixel (px, py) for the browser's camera (viser's camera frame is
    OpenCV's: x right, y down, z forward)."""
    t = math.tan(cam.fov / 2)
    aspect = width / height
    d_cam = np.array([(2 * px / width - 1) * t * aspect, (2 * py / height - 1) * t, 1.0])
    d = vtf.SO3(np.asarray(cam.wxyz)).as_matrix() @ d_cam
    return np.asarray(cam.position, float), d


def table_point(cam: Any, px: float, py: float, width: float, height: float) -> np.ndarray:
    o, d = pixel_ray(cam, px, py, width, height)
    s = -o[2] / d[2]
    assert s > 0
    return (o + s * d)[:2]


def project(cam: Any, point, width: float, height: float) -> tuple[float, float]:
    """Canvas pixel of a world point for the browser's camera (its pose and field of view as the
    browser reports them; viser's camera frame is OpenCV's: x right, y down, z forward)."""
    local = vtf.SO3(np.asarray(cam.wxyz)).as_matrix().T @ (
        np.asarray(point, float) - np.asarray(cam.position, float))
    t = math.tan(cam.fov / 2)
    x, y = local[0] / (local[2] * t * width / height), local[1] / (local[2] * t)
    return (x + 1) / 2 * width, (y + 1) / 2 * height


def summary(page):
    return page.locator('[data-testid="plan-summary"]')


def wait_state(page, states: tuple[str, ...], timeout: float = 15.0) -> str:
    def state() -> str | None:
        now = summary(page).get_attribute("data-state")
        return now if now in states else None
    return wait_until(f"summary state in {states}", state, timeout, show=lambda: (
        f"{summary(page).get_attribute('data-state')!r}: {summary(page).inner_text()}"))


def number(page, label: str):
    return page.get_by_label(label, exact=True)


def _click_to_place_plan_step_to_the_last_waypoint_and_refusal(page, cam: Any,
                                                              artifacts_dir: Path) -> None:
    info = page.locator('[data-testid="objects-info"]')
    assert info.inner_text().startswith("1 object")
    box = page.locator("canvas").first.bounding_box()
    target = (-0.15, 0.25)
    px, py = project(cam, (*target, 0.0), box["width"], box["height"])
    # A software-rendered page busy drawing sometimes drops a canvas click before viser turns
    # it into a scene click (no event reaches the server, no refusal either): click again,
    # as a person would, at most twice more.
    for attempt in range(3):
        click_scene(page, box["x"] + px, box["y"] + py)
        try:
            page.wait_for_function(
                "() => document.querySelector('[data-testid=\"objects-info\"]')"
                ".innerText.startsWith('2 objects')", timeout=8_000)
            break
        except Exception as exc:  # say why: a refusal, or a click that missed the table
            notes = [n.inner_text() for n in page.locator(".mantine-Notification-root").all()]
            role = page.locator('[data-testid="role"]').get_attribute("data-role")
            if notes or attempt == 2:
                page.screenshot(path=str(artifacts_dir / "grasp-click-failed.png"))
                raise AssertionError(f"no object placed by the click; notifications: {notes}; "
                                     f"objects: {info.inner_text()!r}; this tab is {role}"
                                     ) from exc
    x = float(number(page, "x (mm)").input_value()) / 1e3  # mm in the fields (issue 18)
    y = float(number(page, "y (mm)").input_value()) / 1e3
    assert math.hypot(x - target[0], y - target[1]) < 0.01, (x, y)
    radius = float(number(page, "radius (mm)").input_value()) / 1e3

    page.get_by_role("button", name="Plan grasp").click()
    wait_state(page, ("ok",))
    expected = plan_grasp(ROBOT, np.zeros(6), (x, y), radius)
    text = summary(page).inner_text()
    m = re.match(r"(\d+) waypoints?, ([\d.]+) ms", text.strip())  # (then what it kept clear of)
    assert m, text
    assert int(m.group(1)) == expected.n == expected.num_moves
    page.screenshot(path=str(artifacts_dir / "grasp-planned.png"))

    wp = page.locator('[data-testid="waypoint-info"]')
    assert wp.get_attribute("data-index") == "1"
    open_folder(page, "Waypoints", page.get_by_role("button", name="Next waypoint"))  # folded
    for _ in range(expected.n - 1):
        page.get_by_role("button", name="Next waypoint").click()
    page.wait_for_function(
        "n => document.querySelector('[data-testid=\"waypoint-info\"]').dataset.index == n",
        arg=str(expected.n), timeout=10_000)
    assert wp.get_attribute("data-count") == str(expected.n)
    assert float(wp.get_attribute("data-ra")) == pytest.approx(radius + ROBOT.gripper.g_off,
                                                               abs=2e-6)
    assert f"Waypoint {expected.n} of {expected.n}" in wp.inner_text()
    page.get_by_role("button", name="Previous waypoint").click()
    page.wait_for_function(
        "n => document.querySelector('[data-testid=\"waypoint-info\"]').dataset.index == n",
        arg=str(expected.n - 1), timeout=10_000)
    page.screenshot(path=str(artifacts_dir / "grasp-waypoint.png"))

    # Typing a position out of reach re-plans the selected object and says why it cannot work.
    open_folder(page, "Edit objects", number(page, "x (mm)"))  # folded by default
    for label, value in (("x (mm)", "600"), ("y (mm)", "600")):
        box = number(page, label)
        box.fill(value)
        box.press("Enter")
    wait_state(page, ("refused",))
    text = summary(page).inner_text()
    assert "Refused" in text and "out of reach" in text and " mm from the arm's base" in text
    assert wp.get_attribute("data-index") == ""          # nothing left to inspect
    page.screenshot(path=str(artifacts_dir / "grasp-refused.png"))


def test_click_to_place_and_plan_then_top_down_and_two_clicks_measure_a_distance(
        page, soft_console, artifacts_dir: Path) -> None:
    from console.panels.common.view import ViewPanel

    server, app, url = soft_console
    view = app.panel(ViewPanel)
    page.goto(url)
    open_tab(page, "Operate", timeout_ms=60_000)
    page.locator('[data-testid="plan-summary"][data-state="ok"]').wait_for(timeout=60_000)
    # viser's real page starts the one once-a-second redraw the console's page lets rest while
    # it is still (console.web.resting_redraw; the script on a simulated clock:
    # test_resting_redraw_browser.py); the clicks below draw through it.
    assert page.evaluate("() => window.__restingRedraw && window.__restingRedraw.found") == 1, \
        "viser's page no longer starts the 1 s redraw that console/web/resting_redraw.py rests"
    client = wait_for(lambda: len(server.get_clients()) == 1 and the_client(server), 30,
                      "client")
    wait_for(lambda: client.camera._state.update_timestamp != 0.0, 30, "camera reported")
    # The console frames each browser's camera for its window (console.scene.window_fit):
    # click once the browser reports the camera where the console put it.
    wait_for(lambda: (pose := app.window_fit.framed_pose(client.client_id)) is not None
             and np.allclose(client.camera.position, pose.position, atol=1e-3), 30,
             "the camera framed for this window")
    close_notices_until_none(page)                                  # none over the canvas
    page.set_default_timeout(90_000)                                # a loaded CI machine
    _click_to_place_plan_step_to_the_last_waypoint_and_refusal(page, client.camera,
                                                               artifacts_dir)
    page.get_by_text("View", exact=True).click()                    # the folder opens
    page.get_by_role("button", name="Top-down").click()

    def looks_down() -> bool:
        cam = client.camera
        f = np.subtract(cam.look_at, cam.position)
        return f[2] / np.linalg.norm(f) < -0.99
    wait_for(looks_down, 30, "the browser's camera looking straight down")
    expected = view.pose_for(client, "Top-down")
    np.testing.assert_allclose(client.camera.look_at[:2], expected.look_at[:2], atol=0.01)

    box = page.locator("canvas").first.bounding_box()
    w, h = box["width"], box["height"]
    time.sleep(1.0)                                                 # the camera has settled
    cam = client.camera
    pixels = [(0.22 * w, 0.62 * h), (0.52 * w, 0.38 * h)]
    points = [table_point(cam, px, py, w, h) for px, py in pixels]
    x0, x1, y0, y1 = app.table_rectangle()
    for p in points:
        assert x0 < p[0] < x1 and y0 < p[1] < y1, p                 # both on the table
    want_mm = float(np.linalg.norm(points[1] - points[0]) * 1e3)

    objects = page.locator('[data-testid="objects-info"]')
    before = objects.inner_text()
    try:
        page.get_by_role("button", name="Measure distance").click(timeout=90_000)
    except Exception:
        page.screenshot(path=str(artifacts_dir / "view-measure-button.png"))
        raise
    wait_for(lambda: view.claims.claimed(client.client_id), 30, "measuring armed")
    status = page.locator('[data-testid="measure-status"]')
    # A software-rendered page busy drawing sometimes drops a canvas click: click again (at most
    # twice more), as a person would.
    for want_state, (px, py) in zip(("second", "done"), pixels):
        for attempt in range(3):
            page.mouse.click(box["x"] + px, box["y"] + py)
            try:
                wait_for(lambda s=want_state: status.get_attribute("data-state") == s, 8,
                         f"measure state {want_state}", interval=0.05)
                break
            except AssertionError:
                if attempt == 2:
                    page.screenshot(path=str(artifacts_dir / "view-measure-failed.png"))
                    raise
    m = view.measurement
    assert m is not None
    assert abs(m.distance * 1e3 - want_mm) < 1.0, (m.label, want_mm)
    assert view.label.visible and "mm" in view.label.text and view.line.visible
    assert "mm" in status.inner_text()
    assert abs(float(status.get_attribute("data-mm")) - want_mm) < 1.0
    time.sleep(0.5)
    assert objects.inner_text() == before                           # the clicks placed nothing
    page.screenshot(path=str(artifacts_dir / "view-measured.png"))

    first = view.pose_for(client, "Reset view")                     # framed for this window
    page.get_by_role("button", name="Reset view").click()
    wait_for(lambda: app.window_fit.framed_pose(client.client_id) == first, 30,
             "the console keeps the camera framed again")
    wait_for(lambda: np.allclose(client.camera.position, first.position, atol=0.01), 30,
             "the camera back where the console opened")
    page.get_by_role("button", name="Clear measurement").click()
    wait_for(lambda: not view.line.visible and not view.label.visible, 30, "measurement cleared")
