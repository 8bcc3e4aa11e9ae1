"""Exported HTML opened from disk (file://) with no network request: the scene shows the arm
and the plan, a recorded run the arm and its markers (on the lab rig of lab_rig.py). Recording,
replay and export through the GUI: tests/console/test_lab_record_replay_flow.py."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.register_assert_rewrite("lab_rig")
from lab_rig import Lab, lab, session_button, wait_for  # noqa: E402,F401 (lab)

pytestmark = pytest.mark.browser


def pixels(png: bytes) -> np.ndarray:
    """RGB array of a PNG screenshot (Pillow comes with viser, through imageio)."""
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int32)


def near(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> int:
    return int(np.sum(np.all(np.abs(img - np.array(rgb)) <= tol, axis=-1)))


def open_offline(browser: Any, path: Path) -> tuple[Any, list[str]]:
    """Open ``path`` from disk with every http(s) request recorded and refused."""
    context = browser.new_context(viewport={"width": 1000, "height": 700})
    requested: list[str] = []

    def refuse(route: Any) -> None:
        requested.append(route.request.url)
        route.abort()

    context.route(re.compile(r"^https?://"), refuse)
    page = context.new_page()
    page.goto(path.as_uri())
    page.locator("canvas").first.wait_for(timeout=20_000)
    return page, requested


def _scene_shows_the_arm_and_the_plan(lab, artifacts_dir: Path) -> None:
    app = lab.app
    q = np.array([6.0, 4.0, 2.0, 0.0, -3.0, -5.0])
    state = app.store.request(q, "planner")
    wait_for(lambda: app.last_drawn_seq >= state.seq)
    pts = np.array([[0.25, 0.05, 0.001], [0.20, 0.20, 0.001], [0.05, 0.35, 0.001]])
    app.server.scene.add_line_segments("/plan/path", np.stack([pts[:-1], pts[1:]], axis=1),
                                       (255, 0, 255), thickness=0.015)
    app.server.scene.add_icosphere("/plan/target", radius=0.03, color=(255, 0, 255),
                                   position=(0.25, 0.05, 0.03))
    viewer = lab.page()
    session_button(viewer, "Export scene (HTML)").click()
    files = wait_for(lambda: list(app.data.folder("exports").glob("scene-*.html")))
    page, requested = open_offline(lab.browser, files[0])
    try:
        canvas = page.locator("canvas").first
        shots: list[np.ndarray] = []

        def plan_drawn() -> bool:  # the software renderer takes a while
            shots.append(pixels(canvas.screenshot()))
            return near(shots[-1], (255, 0, 255), 60) > 200

        wait_for(plan_drawn, timeout=10.0)
        img = shots[-1]
        page.screenshot(path=str(artifacts_dir / "browser_lab_exported_scene.png"))
        assert requested == []
        assert near(img, (255, 0, 255), 60) > 200, "plan (magenta) not visible"
        assert near(img, (96, 178, 204), 45) > 200, "arm body not visible"
        assert near(img, (226, 222, 214), 20) > 5000, "table not visible"
    finally:
        page.context.close()


def _run_shows_the_arm_and_its_markers(lab, artifacts_dir: Path) -> None:
    from fakes import ScopedClient

    from console.playback.replay import ReplaySession
    from console.recording.recorder import Recorder

    app = lab.app
    exports = app.data.folder("exports")
    before = set(exports.glob("*.html"))
    recorder = Recorder(app.data, app.model, name_of=lambda c: "Alice")
    path = recorder.start("run", client=None)
    events = [lambda: recorder.action("started the demo motion", None),
              lambda: recorder.log("phase", {"phase": "approach", "reason": None}),
              lambda: recorder.action("STOP: STOP pressed by Bob", None), lambda: None]
    for k, event in zip((0.0, 4.0, 8.0, 12.0), events):
        recorder.on_state(app.store.report(np.full(6, k), "hardware"))
        time.sleep(0.05)
        event()
        time.sleep(0.05)
    recorder.stop()
    session = ReplaySession(app, ScopedClient(app.server), order=50.0)
    assert session.load(path.name)
    markers = session.markers
    assert [m.category for m in markers] == ["action", "phase", "stop"]
    session.export()
    files = sorted(set(exports.glob("*.html")) - before)
    assert len(files) == 1
    page, requested = open_offline(lab.browser, files[0])
    try:
        canvas = page.locator("canvas").first
        wait_for(lambda: near(pixels(canvas.screenshot()), (96, 178, 204), 45) > 200,
                 timeout=10.0)  # the arm is drawn
        page.screenshot(path=str(artifacts_dir / "browser_lab_exported_run.png"))
        assert requested == []
        items = page.locator('[data-testid="run-markers"] li')
        assert items.count() == len(markers)
        assert float(items.first.get_attribute("data-t") or -1) == pytest.approx(markers[0].t,
                                                                                 abs=1e-3)
    finally:
        page.context.close()


def test_exported_scene_and_run_open_from_disk_and_show_the_arm_plan_and_markers(
        lab, artifacts_dir: Path) -> None:
    """What the exported pages draw, opened from disk with no network request: the scene
    (exported from the Session tab) shows the arm and the plan; a run recorded here and exported
    by a replay session (recording, replay and export through the GUI:
    tests/console/test_lab_record_replay_flow.py) draws the arm and lists its markers."""
    _scene_shows_the_arm_and_the_plan(lab, artifacts_dir)
    _run_shows_the_arm_and_its_markers(lab, artifacts_dir)
