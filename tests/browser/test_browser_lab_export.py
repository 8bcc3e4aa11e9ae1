"""Recording, replay and export from the GUI, and exported HTML opened from disk (file://)
with no network request, showing the arm and the plan (on the lab rig of lab_rig.py)."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.register_assert_rewrite("lab_rig")
from browser_tabs import open_tab  # noqa: E402
from lab_rig import (SOFT, Lab, lab, session_button, stop_button,  # noqa: E402,F401 (lab)
                     wait_for)

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


def test_exported_scene_opens_from_disk_and_shows_the_arm_and_the_plan(
        lab, artifacts_dir: Path) -> None:
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


def test_record_replay_and_export_a_run_from_the_gui(lab, artifacts_dir: Path) -> None:
    app = lab.app
    alice, bob = lab.pages(2)  # Bob, a viewer, will replay and export
    lab.take_control(alice, "Alice")
    session_button(alice, "Start recording").click()
    wait_for(lambda: app.recorder.recording)
    alice.get_by_role("button", name="Run demo motion").click()
    wait_for(lambda: app.services.demo.running)
    time.sleep(0.8)
    stop_button(alice).click()
    alice.get_by_role("button", name="Stop recording").click()
    wait_for(lambda: not app.recorder.recording)
    names = app.data.list("recordings", ".mcap")
    assert len(names) == 1

    open_tab(bob, "Session")
    bob.get_by_text("Replay", exact=True).click()
    bob.get_by_role("button", name="Load recording").wait_for()
    bob.get_by_role("button", name="Load recording").click()
    info = bob.locator('[data-testid="replay-info"]')
    wait_for(lambda: names[0] in info.inner_text())
    session = wait_for(lambda: next((s for s in app.panels[-1].player.all()
                                     if s.rec is not None), None))
    rec = session.rec
    assert rec.duration > 0.5 and any("STOP" in e.text for e in rec.events)
    assert any(e.who == "Alice" and "demo" in e.text for e in rec.events)
    bob.get_by_role("button", name="Play replay").click()
    wait_for(lambda: float(info.get_attribute("data-t") or 0) > 0.3)
    ghost = session.ghost
    t = session.pos
    from core.kinematics import planar as pk
    tip = pk.forward_kinematics(rec.q_at(t), SOFT.lengths, SOFT.base_pose)[-1]
    body = np.asarray(ghost.body.vertices, dtype=float)
    k, m = ghost.body_topology.sides, ghost.body_topology.n_rings
    drawn_tip = body[: m * k].reshape(m, k, 3).mean(axis=1)[-1]
    assert np.linalg.norm(drawn_tip[:2] - tip[:2]) < 0.03  # played on between read and draw
    assert app.store.command.source == "stop"  # replay never commands the arm

    # Markers (started recording, the demo, STOP, ...): from the end, back two and on one.
    from console.playback.replay_markers import current_marker, next_marker, previous_marker
    wait_for(lambda: not session.playing, timeout=15.0)  # the replay ran to its end
    markers = session.markers
    assert len(markers) >= 3 and any(m.category == "stop" for m in markers)
    marker = bob.locator('[data-testid="replay-marker"]')
    pos = session.pos
    for name in ("◀ Previous marker", "◀ Previous marker", "Next marker ▶"):
        target = (previous_marker if name.startswith("◀") else next_marker)(markers, pos)
        assert target is not None
        pos = min(target.t, rec.duration)
        index = current_marker(markers, pos)[0]
        bob.get_by_role("button", name=name).click()
        # (the first jump, from the end, lands on the marker already shown there: wait for the
        # server's jump itself; a loaded run read the position before the click arrived)
        wait_for(lambda: abs(session.pos - pos) <= 1e-6)
        wait_for(lambda: marker.count() == 1 and marker.get_attribute("data-index") == str(index))
        assert markers[index].text in marker.inner_text()
        np.testing.assert_allclose(rec.q_at(session.pos), rec.q_at(pos))
    assert app.store.command.source == "stop"

    bob.get_by_role("button", name="Export run (HTML)").click()
    files = wait_for(lambda: list(app.data.folder("exports").glob("*.html")), timeout=15.0)
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
