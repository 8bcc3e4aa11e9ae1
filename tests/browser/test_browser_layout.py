"""Issue #18: STOP and the arm's phase are on screen without scrolling at desktop, tablet and
phone sizes, on every tab, for both default consoles; every tab is shot at desktop and tablet
size (``artifacts/layout/``) for people to look at.

Issue #31: at each size the arm (the soft arm with its object and the planned approach circles)
is in the 3D view and not behind the control panel; so is a far object's plan (an object at
(-300, 80) mm: its outer approach circles reach past the arm's reach, and the console frames
what is planned, ``console.scene.plan_frame``). The arm's points are projected with the camera
the browser reports to the console (its pose, field of view and canvas size, read on the server
side of the console built in this process), their bounding box on the page compared with the
canvas's and the panel's rectangles as the page measures them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import viser.transforms as vtf
from browser_tabs import close_notices, open_tab
from playwright.sync_api import Error as PlaywrightError

from console.scene.window_fit import POSE_TOLERANCE_M
from tests.ws_client import wait_for

pytestmark = pytest.mark.browser

SIZES = {"desktop": (1600, 1000), "tablet": (820, 1180), "phone": (390, 844)}
TABS = {"soft-arm": ("Operate", "Hardware", "Experiments", "Session"),
        "extensible": ("Operate", "Hardware", "Experiments", "Session")}
SHOT_SIZES = ("desktop", "tablet")

# True when the element's centre is on screen and nothing else (a notification, the 3D
# canvas) is drawn over it there: what a person can see and press without scrolling. The element
# is found in the same call: the header is one HTML block that viser replaces whenever a field
# changes, so an element found in one round trip and measured in the next can be a detached old
# one (zero size: a failed run, 2026-12-04).
_ON_SCREEN = """find => {
    const el = find();
    if (el === null || el === undefined) return false;
    const r = el.getBoundingClientRect();
    const x = r.left + r.width / 2, y = r.top + r.height / 2;
    if (r.width <= 0 || r.height <= 0 || x < 0 || y < 0
        || r.right > innerWidth || r.bottom > innerHeight) return false;
    const top = document.elementFromPoint(x, y);
    return top !== null && (el === top || el.contains(top));
}"""


def drawn(page: Any) -> None:
    """Wait until the page has laid out and painted what changed (two animation frames)."""
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


FIND = {
    "STOP": """() => [...document.querySelectorAll('button')]
                    .find(b => b.textContent.includes('STOP') && b.textContent.includes('(Esc)'))""",
    "the phase": """() => document.querySelector('[data-testid="header-phase"]')""",
}


def _on_screen(page: Any, what: str) -> bool:
    """Whether ``what`` (a key of :data:`FIND`) is on screen and uncovered, measured in one call
    in the page; it may take up to 5 s to become so (a tab's panels settling)."""
    try:
        page.wait_for_function(f"() => ({_ON_SCREEN})({FIND[what]})", timeout=5_000)
    except PlaywrightError:
        return False
    return True


# The page rectangles of the 3D canvas and of the control panel (the outermost box holding
# STOP that does not also hold the canvas: docked beside it, or viser's phone sheet over it).
_RECTS = """() => {
    const canvas = [...document.querySelectorAll('canvas')]   // the 3D view's (WebGL) canvas
        .filter(c => !(c.getAttribute('style') || '').includes('pointer-events: none'))
        .sort((a, b) => b.clientWidth * b.clientHeight - a.clientWidth * a.clientHeight)[0];
    const stop = [...document.querySelectorAll('button')].find(b => b.textContent.includes('STOP'));
    if (!canvas || !stop) return null;
    let panel = stop;
    while (panel.parentElement && !panel.parentElement.contains(canvas)) panel = panel.parentElement;
    const box = e => { const r = e.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; };
    return {canvas: box(canvas), panel: box(panel)};
}"""


def scene_parts(app: Any) -> dict[str, np.ndarray]:
    """World points (m) of what must stay in view, by part: the arm's drawn surfaces at its
    shown pose; for the soft arm also each object's rim and the plan's approach circles and
    waypoints."""
    g = app.view.geometry(np.asarray(app.store.display.q))
    parts = {k: g[k] for k in ("body", "gripper", "backbone", "platforms") if k in g}
    parts.update({f"rack {i + 1}": r for i, r in enumerate(g.get("racks", []))})
    if app.grasp_scene is not None:
        a = np.linspace(0.0, 2 * math.pi, 24)
        for o in app.grasp_session.view().objects:
            parts[f"object {o.name}"] = np.stack([o.x + o.r * np.cos(a), o.y + o.r * np.sin(a),
                                                  0 * a], -1)
        plan = app.grasp_scene.plan_scene
        assert plan.circles.visible, "no approach circles drawn"
        parts["approach circles"] = plan.circles.points
        parts["waypoints"] = plan.palms.points
        if plan.circles_failed.visible:
            parts["failed circles"] = plan.circles_failed.points
    return {k: np.asarray(v, float).reshape(-1, 3) for k, v in parts.items()}


def scene_points(app: Any) -> np.ndarray:
    """All of :func:`scene_parts` in one array."""
    return np.concatenate(list(scene_parts(app).values()))


def on_page(camera: Any, points: np.ndarray, canvas: list[float]) -> tuple[float, ...]:
    """Bounding box (left, top, right, bottom, page px) of ``points`` seen by a browser's
    reported camera (viser's camera frame is OpenCV's: x right, y down, z forward)."""
    rot = vtf.SO3(np.asarray(camera.wxyz)).as_matrix()
    local = (points - np.asarray(camera.position, float)) @ rot         # camera coordinates
    assert np.all(local[:, 2] > 0), "part of the arm is behind the camera"
    t = math.tan(camera.fov / 2)
    w, h = canvas[2] - canvas[0], canvas[3] - canvas[1]
    px = canvas[0] + (local[:, 0] / local[:, 2] / (t * w / h) + 1) / 2 * w
    py = canvas[1] + (local[:, 1] / local[:, 2] / t + 1) / 2 * h
    return float(px.min()), float(py.min()), float(px.max()), float(py.max())


def _framing(app: Any, client: Any) -> str:
    """What the console's window fit knows of this browser's camera (for a failure's words):
    the canvas it framed for, the one reported, and whether the camera is where it put it."""
    fit = app.window_fit
    pose = fit.framed_pose(client.client_id)
    cam = client.camera
    tol = POSE_TOLERANCE_M
    at = pose is not None and bool(np.allclose(cam.position, pose.position, atol=tol)
                                   and np.allclose(cam.look_at, pose.look_at, atol=tol))
    return (f"framed for {fit.framed_size(client.client_id)}, reported "
            f"{cam.image_width}x{cam.image_height}, camera at the framed pose: {at}, "
            f"framed look_at {None if pose is None else np.round(pose.look_at, 3).tolist()}, "
            f"camera look_at {np.round(cam.look_at, 3).tolist()}, fov {math.degrees(cam.fov):.1f} "
            f"deg (framed {'-' if pose is None else f'{math.degrees(pose.fov):.1f}'}), up "
            f"{np.round(cam.up_direction, 3).tolist()}, wxyz {np.round(cam.wxyz, 3).tolist()}")


def arm_in_view(page: Any, app: Any, size: str) -> str | None:
    """None when the arm's box is inside the canvas and clear of the panel, else why not."""
    rects = page.evaluate(_RECTS)
    if rects is None:
        return "no canvas or panel yet"
    canvas, panel = rects["canvas"], rects["panel"]
    clients = list(app.server.get_clients().values())
    camera = clients[0].camera
    # (The reported size is the drawing buffer's: CSS pixels times the page's adaptive pixel
    # ratio; its aspect is the canvas's.)
    aspect = (canvas[2] - canvas[0]) / (canvas[3] - canvas[1])
    if abs(camera.image_width / max(camera.image_height, 1) / aspect - 1) > 0.02:
        return f"the camera reported a {camera.image_width}x{camera.image_height} canvas"
    box = on_page(camera, scene_points(app), canvas)
    where = f"{size}: the arm at {[round(v) for v in box]}"
    if not (box[0] >= canvas[0] and box[1] >= canvas[1] and box[2] <= canvas[2]
            and box[3] <= canvas[3]):
        outside = []  # which parts, where (page px) and their world extent (mm)
        for name, pts in scene_parts(app).items():
            b = on_page(camera, pts, canvas)
            if b[0] < canvas[0] or b[1] < canvas[1] or b[2] > canvas[2] or b[3] > canvas[3]:
                lo, hi = (np.round(1e3 * pts.min(0)).tolist(), np.round(1e3 * pts.max(0)).tolist())
                outside.append(f"{name} at {[round(v) for v in b]} (x, y, z mm {lo}..{hi})")
        return (f"{where} is not all in the 3D view {[round(v) for v in canvas]}: "
                f"{'; '.join(outside)}; camera at "
                f"{np.round(np.asarray(camera.position), 3).tolist()}; {_framing(app, clients[0])}")
    if box[0] < panel[2] and panel[0] < box[2] and box[1] < panel[3] and panel[1] < box[3]:
        return f"{where} is behind the panel {[round(v) for v in panel]}"
    return None


@pytest.mark.parametrize("robot", ["soft-arm", "extensible"])
def test_stop_and_phase_need_no_scrolling_and_the_arm_is_clear_of_the_panel_at_any_size(
        browser: Any, served_console: Any, artifacts_dir: Path, robot: str,
        monkeypatch: pytest.MonkeyPatch) -> None:
    from console.core.grasp_session import GraspSession
    monkeypatch.setattr(GraspSession, "compute_reach", False)  # (the shading: not here)
    app = served_console(robot, start=True)
    url = f"http://127.0.0.1:{app.server.get_port()}/"
    if app.grasp_session is not None:  # the selected object's approach circles drawn
        app.grasp_session.request_plan()
    shots = artifacts_dir / "layout"
    shots.mkdir(exist_ok=True)
    context = browser.new_context(viewport={"width": 1600, "height": 1000})
    try:
        page = context.new_page()
        page.goto(url)
        stop = page.get_by_role("button", name="STOP (Esc)")
        stop.wait_for(timeout=60_000)
        phase = page.locator('[data-testid="header-phase"]')
        phase.wait_for(timeout=60_000)
        page.locator('[data-testid="header-control"]').wait_for(timeout=30_000)
        # The browser's own notice arrives at mount (software rendering here): wait for it
        # rather than a fixed time, so it is closed below and covers nothing.
        notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
        try:
            notice.wait_for(timeout=10_000)
        except PlaywrightError:
            pass  # (a GPU-rendered browser shows none)
        for size, (width, height) in SIZES.items():  # one page, resized: as a user turns a tablet
            resize(page, width, height)
            in_view_or_shot(page, app, size, shots / f"{robot}-{size}-arm.png")
            for tab in TABS[robot] if size in SHOT_SIZES else ("Operate",):
                open_tab(page, tab)
                drawn(page)
                shot = shots / f"{robot}-{size}-{tab.lower()}.png"
                for what in FIND:
                    if not _on_screen(page, what):
                        page.screenshot(path=str(shot))
                        raise AssertionError(f"{what} is off screen or covered: {size}, {tab} "
                                             f"(see {shot})")
                assert page.evaluate("() => scrollY") == 0
                page.screenshot(path=str(shot))
        session = app.grasp_session
        if session is not None:
            # A far object (issue 31): its plan's outer circles reach past the arm's reach.
            name = session.place(-0.30, 0.08)
            session.request_plan()

            def planned() -> bool:
                v = session.view()
                return (v.outcome is not None and v.outcome.obj is not None
                        and v.outcome.obj.name == name and v.outcome.plan is not None
                        and v.planning_s is None)
            wait_for(planned, 60, "the far object's plan")
            for size, (width, height) in reversed(SIZES.items()):
                resize(page, width, height)
                in_view_or_shot(page, app, size, shots / f"{robot}-{size}-far-plan.png")
                page.screenshot(path=str(shots / f"{robot}-{size}-far-plan.png"))
    finally:
        context.close()


def resize(page: Any, width: int, height: int) -> None:
    """Resize the page (as a user turns a tablet), close the notices and open Operate."""
    page.set_viewport_size({"width": width, "height": height})
    page.wait_for_function("w => innerWidth === w", arg=width)
    drawn(page)
    close_notices(page)
    open_tab(page, "Operate")


def in_view_or_shot(page: Any, app: Any, size: str, shot: Path) -> None:
    """Wait (20 s at most) until the arm and what is planned are in the 3D view and clear of
    the panel; else screenshot the page to ``shot`` and fail with why."""
    why: list[str | None] = [None]

    def clear() -> bool:
        why[0] = arm_in_view(page, app, size)
        return why[0] is None
    try:
        wait_for(clear, 20, "the arm in view", interval=0.1)
    except AssertionError:
        page.screenshot(path=str(shot))
        raise AssertionError(f"{why[0]} (see {shot})") from None
