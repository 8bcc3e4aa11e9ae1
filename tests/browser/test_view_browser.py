"""Browser test of the View panel: camera presets move the presser's camera, and Measure turns two
clicks on the table into a distance everyone sees, placing nothing.

The console is built in this process (``serve.build``) so the test can read what the browser's
camera is on the server side (``client.camera``) and what the panel measured. The expected
distance is computed here from the two clicked pixels: each pixel's ray through the browser's
camera (its pose and field of view as the browser reports them) meets the table plane z = 0.
Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest
import viser.transforms as vtf
from browser_tabs import close_notices, open_tab

from core.robots import load
from tests.ws_client import wait_for

pytestmark = pytest.mark.browser


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


def test_top_down_moves_my_camera_and_two_clicks_measure_a_distance(
        page, soft_console, artifacts_dir: Path) -> None:
    from console.panels.common.view import ViewPanel

    server, app, url = soft_console
    view = app.panel(ViewPanel)
    page.goto(url)
    open_tab(page, "Operate", timeout_ms=60_000)
    page.locator('[data-testid="plan-summary"][data-state="ok"]').wait_for(timeout=60_000)
    client = wait_for(lambda: len(server.get_clients()) == 1 and the_client(server), 30,
                      "client")
    wait_for(lambda: client.camera._state.update_timestamp != 0.0, 30, "camera reported")
    close_notices(page)
    page.set_default_timeout(90_000)                                # a loaded CI machine
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

    page.get_by_role("button", name="Reset view").click()
    first = app.camera_presets[0]
    wait_for(lambda: np.allclose(client.camera.position, first.position, atol=0.01), 30,
             "the camera back where the console opened")
    page.get_by_role("button", name="Clear measurement").click()
    wait_for(lambda: not view.line.visible and not view.label.visible, 30, "measurement cleared")
