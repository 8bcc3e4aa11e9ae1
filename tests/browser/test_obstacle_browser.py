"""Obstacles in a real browser (#17.1, planar arm): a person switches "Table click places" to
Obstacle, clicks the table between the straight arm and the object, presses Plan grasp, and
the plan drawn goes around the obstacle.

The console runs in this process (ConsoleApp with the grasp panels), so the plan is checked on
the server's own state: every arm and gripper point along every straight line in kappa between
waypoints (dense sampling of core.kinematics.planar) keeps the set clearance from the obstacle,
while the plain Algorithm 1 plan for the same object would not. Screenshots:
``artifacts/browser_obstacle_*.png``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from browser_tabs import close_notices, open_tab
from console.app import ConsoleApp
from tests.ws_client import wait_for
from console.panels.soft_arm.objects import ObjectsPanel
from core.kinematics import planar
from core.planning.grasp import plan_grasp
from core.robots import load

pytestmark = pytest.mark.browser
ROBOT = load("soft-arm")
SPOT = (-0.062, 0.188)      # between the straight arm (x = 0) and Object 1 at (-0.2, 0.2)


def project(point, width: float, height: float) -> tuple[float, float]:
    """Pixel of a world point for the console's initial camera (as test_planner_browser)."""
    from test_planner_browser import project as console_project

    return console_project(point, width, height)


def dense_gap(kappas: np.ndarray, x: float, y: float, r: float) -> np.ndarray:
    """Arm (backbone +- half-width, straight gripper +- its half-width) to disk gap."""
    bb = planar.sample_backbone(kappas, ROBOT.lengths, 64, ROBOT.base_pose)
    body = np.hypot(bb[..., 0] - x, bb[..., 1] - y).min(axis=-1) - ROBOT.half_width
    tip = bb[..., -1, :]
    s = np.linspace(0.0, ROBOT.gripper.length, 65)
    gx = tip[..., 0:1] + s * np.cos(tip[..., 2:3])
    gy = tip[..., 1:2] + s * np.sin(tip[..., 2:3])
    grip = np.hypot(gx - x, gy - y).min(axis=-1) - ROBOT.gripper.half_width
    return np.minimum(body, grip) - r


def swept(kappa_meas: np.ndarray, kappas: np.ndarray) -> np.ndarray:
    chain = np.vstack([kappa_meas, kappas])
    tau = np.linspace(0.0, 1.0, 201)
    return chain[:-1, None, :] + tau[:, None] * (chain[1:] - chain[:-1])[:, None, :]


def wait_until(what: str, fn, timeout: float) -> Any:
    return wait_for(fn, timeout, what)


@pytest.fixture
def grasp_page(browser: Any, server: Any) -> Iterator[tuple[Any, ConsoleApp]]:
    from console.panels.soft_arm import panel_set, planner

    planner.GraspSession.compute_reach = False   # the shading is not what is tested here
    from console.core.access import AccessControl

    # The lease is not what is tested: on a machine loaded far past its cores a software-
    # rendered tab went silent past the 7 s lease between taking control and clicking.
    access = AccessControl(None, lease_s=60.0, first_answer_s=120.0)
    app = ConsoleApp(ROBOT, server, panels=panel_set.grasp_panels(), access=access)
    app.start()
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    try:
        page = context.new_page()
        page.set_default_timeout(60_000)
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        open_tab(page, "Operate", 180_000)   # a machine loaded past its cores loads slowly
        page.locator('[data-testid="plan-summary"][data-state="ok"]').wait_for()
        yield page, app
    finally:
        context.close()
        app.grasp_session.close()
        app.grasp_session._thread.join(5)
        app.stop()
        planner.GraspSession.compute_reach = True


def hold_control(app: ConsoleApp) -> None:
    """This browser holds control (a software-rendered tab on a loaded machine can go silent
    long enough to lose it; take it back as a person would)."""
    (client_id,) = app.server.get_clients()
    if not app.access.is_operator(client_id):
        app.access.take(client_id, None, "tester")


def retry(app: ConsoleApp, act, done, what: str, timeout: float = 8.0) -> None:
    """Do ``act`` as the operator until ``done()``: a tab on a loaded machine can go silent
    past the lease and lose control, and then its action is refused (as for a person, who
    takes control back and does it again)."""
    for attempt in range(3):
        hold_control(app)
        act()
        try:
            wait_until(what, done, timeout)
            return
        except AssertionError as exc:
            if attempt == 2:
                (client_id,) = app.server.get_clients()
                raise AssertionError(f"{exc}; this tab holds control: "
                                     f"{app.access.is_operator(client_id)}") from exc


def clear_notices(page: Any, timeout: float = 20.0) -> None:
    """Close notifications until none is left (they can cover the canvas and the buttons);
    on a loaded machine they can close by themselves while being closed."""
    notices = page.locator(".mantine-Notification-root")
    deadline = time.monotonic() + timeout
    while notices.count() and time.monotonic() < deadline:
        close_notices(page)
        time.sleep(0.3)


def choose(page: Any, label: str, option: str) -> None:
    """Pick ``option`` in the dropdown labelled ``label`` with the mouse."""
    page.get_by_label(label, exact=True).click()
    page.get_by_role("option", name=option, exact=True).click()


def test_person_places_an_obstacle_and_the_plan_goes_around_it(grasp_page,
                                                                 artifacts_dir: Path) -> None:
    page, app = grasp_page
    session = app.grasp_session
    try:
        run_the_test(page, app, session, artifacts_dir)
    except BaseException:
        page.screenshot(path=str(artifacts_dir / "browser_obstacle_failure.png"), timeout=60_000)
        raise


def run_the_test(page: Any, app: ConsoleApp, session: Any, artifacts_dir: Path) -> None:
    hold_control(app)
    clear_notices(page)
    objects = app.panel(ObjectsPanel)
    retry(app, lambda: choose(page, "Table click places", "Obstacle"),
          lambda: objects.click_place.value == "Obstacle", "click mode")
    box = page.locator("canvas").first.bounding_box()
    assert box is not None
    info = page.locator('[data-testid="obstacles-info"]')
    for attempt in range(5):   # a busy software renderer can drop a canvas click
        hold_control(app)
        clear_notices(page)
        px, py = project((*SPOT, 0.0), box["width"], box["height"])
        page.mouse.click(box["x"] + px, box["y"] + py)
        try:
            wait_until("obstacle placed", lambda: session.view().obstacles, 12)
            break
        except AssertionError:
            if attempt == 4:
                page.screenshot(path=str(artifacts_dir / "browser_obstacle_click_failed.png"))
                raise
    (obs,) = session.view().obstacles
    assert math.hypot(obs.x - SPOT[0], obs.y - SPOT[1]) < 0.01, obs
    wait_until("the page lists it", lambda: info.get_attribute("data-count") == "1", 10)
    assert len(session.view().objects) == 1          # an obstacle, not an object

    retry(app, lambda: page.get_by_role("button", name="Plan grasp").click(), lambda: (
        (o := session.view().outcome) and o.plan is not None and o.plan.obstacles), "planned",
        timeout=30)
    planned = session.view().outcome
    plan = planned.plan
    clearance = session.view().clearance
    assert clearance == pytest.approx(0.010)
    assert plan.success, plan.summary()
    # The server's plan keeps the clearance at every point between waypoints ...
    gaps = dense_gap(swept(plan.kappa_meas, plan.kappas), obs.x, obs.y, obs.r)
    assert gaps.min() >= clearance - 1e-9, gaps.min()
    assert np.all(plan.obstacle_path_clearance >= clearance)
    # ... where the plain Algorithm 1 plan would not: the plan goes around the obstacle.
    plain = plan_grasp(ROBOT, plan.kappa_meas, plan.center, plan.radius)
    assert dense_gap(swept(plain.kappa_meas, plain.kappas), obs.x, obs.y, obs.r).min() < clearance
    # The page says so too.
    summary = page.locator('[data-testid="plan-summary"]')
    wait_until("summary", lambda: summary.get_attribute("data-state") == "ok"
               and summary.get_attribute("data-obstacle-mm"), 10)
    assert float(summary.get_attribute("data-obstacle-mm")) >= 10.0 - 1e-6
    assert "from the obstacles" in summary.inner_text()
    # Step to the last waypoint so the drawn ghost arm is the grasp pose around the obstacle.
    for k in range(1, plan.n):
        retry(app, lambda: page.get_by_role("button", name="Next waypoint").click(),
              lambda k=k: session.view().index >= k, f"waypoint {k + 1}")
    page.mouse.move(5, 5)
    time.sleep(1.0)
    page.screenshot(path=str(artifacts_dir / "browser_obstacle_plan.png"))
