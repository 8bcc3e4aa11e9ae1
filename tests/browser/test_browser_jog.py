"""The Jog panel in a real browser, for both default consoles (built in this process, so the
test reads the server side): each slider's hold-to-jog − / + sit on the slider's own row and the
rows fit in one 1600x1000 screen; a mouse click on a slider's track and a number typed into its
box move the arm, and the tip readout the operator sees follows the pose computed here from
``core.kinematics`` (closed-form rack lengths for the extensible arm); the browser clamps a typed
number to the slider's range on blur (the bending limit, the racks' limits) and the page says so;
holding a row's + with the mouse jogs that coordinate until it is let go; a held bend of a
retracted extensible arm is refused with a note, and no text on the page reads "-0".
Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import math
import re
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from browser_tabs import close_notices, open_folder, open_tab, wait_until
from console.app import ConsoleApp
from console.core.hold_to_run import HOLD_SOURCE
from console.core.model import ExtensibleModel
from console.panel_sets import DEFAULT_PANELS
from console.panels.common.jog import JogPanel
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.robots import load

# alone: a held jog ends after its release (hold expiry 0.3 s) (conftest's SUITE_PART=alone)
pytestmark = [pytest.mark.browser, pytest.mark.alone]
READOUT_TOL = 0.051  # the readout shows one decimal (mm, degrees)
NEGATIVE_ZERO = re.compile(r"(?<![\d.])[-−]0(?:\.0+)?(?![\d.])")


def slider(page, label: str):
    """(thumb, number box, track) of the viser slider whose label is ``label``."""
    uid = page.locator("label", has_text=label).first.get_attribute("for")
    assert uid, f"no slider labelled {label!r}"
    root = page.locator(f'[id="{uid}"]')
    return (root.get_by_role("slider"), page.locator(f'[id="{uid}"] + div input'),
            root.locator(".mantine-Slider-track"))


def type_value(page, label: str, value: float) -> None:
    """Type a value and leave the field, as a person does: the browser clamps an out-of-range
    number to the slider's range on blur (the server refuses the raw one, console.web.client_guard)."""
    box = slider(page, label)[1]
    box.fill(f"{value:g}")
    box.press("Tab")


def read(page, testid: str) -> float:
    return float(page.locator(f'[data-testid="{testid}"]').inner_text().replace("⚠", ""))


def wait_for_readout(page, expected: dict[str, float], timeout: float = 20.0) -> None:
    """Poll the readout cells until each is within READOUT_TOL of ``expected``."""
    def actual() -> dict[str, float]:
        return {k: read(page, k) for k in expected}
    wait_until("the readout", lambda: all(abs(v - expected[k]) <= READOUT_TOL
                                          for k, v in actual().items()), timeout,
               show=lambda: f"{actual()} != expected {expected}")


def wrap_deg(theta: float) -> float:
    deg = math.degrees(theta) % 360.0
    return deg - 360.0 if deg > 180.0 else deg


def canvas_png(page) -> bytes:
    return page.locator("canvas").first.screenshot()


def _racks(robot, q: np.ndarray) -> np.ndarray:
    """Closed-form rack lengths: L0 + dL - dx cos(beta_j) - dy sin(beta_j)."""
    beta = -robot.phi + 2 * np.pi * np.arange(3) / 3
    return (robot.L0 + q[:, 2:3] - q[:, 0:1] * np.cos(beta) - q[:, 1:2] * np.sin(beta))


def _feasible(robot, q: np.ndarray) -> bool:
    """Racks within their limits and every bend |(dx, dy)| / d within theta_max."""
    r = _racks(robot, q)
    theta = np.hypot(q[:, 0], q[:, 1]) / robot.rack_radius
    return bool(np.all(r >= robot.rack_min - 1e-12) and np.all(r <= robot.rack_max + 1e-12)
                and np.all(theta <= robot.theta_max))


def _boundary(robot, q: np.ndarray, index: tuple[int, int], good: float, bad: float) -> float:
    """Bisection on the closed-form feasibility, independent of the app: the feasible value of
    q[index] nearest ``bad``, going from ``good`` (feasible) towards ``bad`` (infeasible)."""
    for _ in range(60):
        mid = 0.5 * (good + bad)
        trial = q.copy()
        trial[index] = mid
        good, bad = (mid, bad) if _feasible(robot, trial) else (good, mid)
    return good


@pytest.fixture(params=["soft-arm", "extensible"])
def jog_page(request: Any, browser: Any, server: Any) -> Iterator[tuple[Any, ConsoleApp]]:
    app = ConsoleApp(load(request.param), server, panels=DEFAULT_PANELS)
    app.start()
    context = browser.new_context(viewport={"width": 1600, "height": 1000})
    try:
        page = context.new_page()
        page.set_default_timeout(60_000)
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        open_tab(page, "Operate", 60_000)
        page.get_by_text("Jog", exact=True).first.wait_for()
        close_notices(page)
        open_folder(page, "Jog", page.get_by_text("Jog speed (mm/s)"))  # folded by default
        open_folder(page, "Readout", page.locator('[data-testid="tip-readout"]'))
        yield page, app
    finally:
        context.close()
        app.stop()


def _box(page: Any, handle: Any) -> dict[str, float]:
    box = page.locator(f'[id="{handle._impl.uuid}"]').bounding_box()
    assert box is not None
    return box


def _rows_sit_on_their_sliders(page: Any, app: ConsoleApp, artifacts_dir: Path) -> None:
    jog = app.panel(JogPanel)
    page.locator(f'[id="{jog.rows[-1].plus._impl.uuid}"]').wait_for()
    rows = []
    for row in jog.rows:
        track, minus, plus = (_box(page, h) for h in (row.slider, row.minus, row.plus))
        # Same row: the buttons overlap the slider's track vertically, to its right, − first.
        for b in (minus, plus):
            assert b["y"] <= track["y"] + track["height"] and b["y"] + b["height"] >= track["y"]
        assert track["x"] + track["width"] < minus["x"] < plus["x"]
        assert track["width"] > 50, f"{row.coord.label}: track too short to use"
        rows.append(minus["y"])
    assert rows == sorted(rows) and len(set(np.round(rows))) == len(rows)  # one row each
    top = _box(page, jog.rows[0].slider)["y"]
    bottom = _box(page, jog.straighten)["y"] + _box(page, jog.straighten)["height"]
    assert bottom - top < 450, "the Jog rows should fit well inside one 1000 px screen"
    page.mouse.move(5, 5)
    page.screenshot(path=str(artifacts_dir / f"browser_jog_{app.robot.kind}.png"))


def _take_control(app: ConsoleApp) -> None:
    """This browser takes control (no token): a software-rendered tab on a loaded machine can
    go silent for 2 s while drawing and lose it, so wait until it answers the lease probe."""
    (client_id,) = app.server.get_clients()
    app.access.take(client_id, None, "tester")
    # (a still console probes the tab until it first answers, then only while motion needs it)
    wait_until("the tab answering the lease probe", lambda: app.access.status().answered, 30)


def _hold_jogs_until_released(page: Any, app: ConsoleApp, key: str) -> None:
    """Hold the row ``key``'s + with the mouse: it jogs that coordinate; letting go ends it."""
    jog = app.panel(JogPanel)
    row = next(r for r in jog.rows if r.coord.key == key)
    before = float(np.asarray(app.store.command.q)[row.coord.index])
    plus = _box(page, row.plus)
    page.mouse.move(plus["x"] + plus["width"] / 2, plus["y"] + plus["height"] / 2)
    stops = app.core.stop_log  # (shown if the hold never ran)
    page.mouse.down()
    seen = set()
    deadline = time.monotonic() + 10.0
    while HOLD_SOURCE not in seen and time.monotonic() < deadline:
        seen.add(app.store.command.source)
        time.sleep(0.01)
    time.sleep(0.5)
    page.mouse.up()
    assert HOLD_SOURCE in seen, (seen, stops)
    wait_until("the held jog to end", lambda: not app.hold.active, 10)
    last = app.store.command
    assert float(np.asarray(last.q)[row.coord.index]) > before
    time.sleep(0.3)
    assert app.store.command.seq == last.seq and not app.hold.active


def _soft_arm_slider_jogs_follow_the_kinematics(page: Any, app: ConsoleApp,
                                                artifacts_dir: Path) -> None:
    robot = app.robot
    straight = pk.forward_kinematics(np.zeros(6), robot.lengths, robot.base_pose)[-1]
    wait_for_readout(page, {"tip-0": straight[0] * 1e3, "tip-1": straight[1] * 1e3,
                            "tip-2": wrap_deg(straight[2])})
    before = canvas_png(page)
    # Click 3/4 along the κ₂ track (a mouse jog), then type -8 into κ₄'s number box.
    # (Not arrow keys: viser 1.1.1 also orbits the camera on arrow keys over a slider.)
    thumb, _, track = slider(page, "κ₂")
    track.scroll_into_view_if_needed()
    box = track.bounding_box()
    assert box is not None
    page.mouse.click(box["x"] + 0.75 * box["width"], box["y"] + box["height"] / 2)
    type_value(page, "κ₄", -8.0)
    kappa2 = float(thumb.get_attribute("aria-valuenow"))
    # 3/4 of [-16.7, 16.7] is +8.35; allow for the thumb's width and the 0.1 step.
    assert 7.0 < kappa2 < 9.5
    kappa = np.array([0.0, kappa2, 0.0, -8.0, 0.0, 0.0])
    tip = pk.forward_kinematics(kappa, robot.lengths, robot.base_pose)[-1]
    c, s = math.cos(tip[2]), math.sin(tip[2])
    a, n = robot.gripper.w_off_along, robot.gripper.g_off  # palm offset: along, left
    palm = (tip[0] + a * c - n * s, tip[1] + a * s + n * c)
    wait_for_readout(page, {"tip-0": tip[0] * 1e3, "tip-1": tip[1] * 1e3,
                            "tip-2": wrap_deg(tip[2]),
                            "palm-0": palm[0] * 1e3, "palm-1": palm[1] * 1e3})
    wait_until("the 3D view redrawn after the jog", lambda: canvas_png(page) != before, 10)
    page.mouse.move(5, 5)  # park the pointer so no tooltip covers the panel
    page.screenshot(path=str(artifacts_dir / "browser_soft-arm_jogged.png"))


def _extensible_typed_jogs_follow_the_kinematics_and_clamp(page: Any, app: ConsoleApp,
                                                          artifacts_dir: Path) -> None:
    robot = app.robot
    start = ExtensibleModel(robot).initial()  # straight, every rack at mid-range
    assert np.all(start[:, :2] == 0.0)
    # The extensible arm jogs at 20 mm/s by default (a class can follow it); these moves are
    # hundreds of mm: the operator types the fastest jog speed into its field first.
    speed = page.locator("label", has_text="Jog speed (mm/s)").first.get_attribute("for")
    box = page.locator(f'[id="{speed}"]')
    box.fill("100")
    box.press("Tab")
    wait_until("the jog speed taken", lambda: app.core.hold.jog_speed == pytest.approx(0.1), 10)
    app.store.request(start, "test")
    wait_for_readout(page, {"tip-0": 0.0, "tip-1": 0.0,
                            "tip-2": dk.tip_position(robot, start)[2] * 1e3})
    assert page.locator('[data-near-limit="true"]').count() == 0
    before = canvas_png(page)
    q = np.array([[0.04, 0.0, 0.15], [0.0, -0.04, 0.10]])
    for label, value in (("δL₁", 0.15), ("Δx₁", 0.04), ("δL₂", 0.10), ("Δy₂", -0.04)):
        type_value(page, label, value * 1e3)  # the Δ sliders are in mm
    assert _feasible(robot, q)
    tip = dk.tip_position(robot, q)
    racks = _racks(robot, q)
    expected = {"tip-0": tip[0] * 1e3, "tip-1": tip[1] * 1e3, "tip-2": tip[2] * 1e3}
    expected |= {f"rack-{i + 1}-{j + 1}": racks[i, j] * 1e3 for i in range(2) for j in range(3)}
    wait_for_readout(page, expected)
    assert page.locator('[data-near-limit="true"]').count() == 0
    wait_until("the 3D view redrawn after the jog", lambda: canvas_png(page) != before, 10)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_jogged.png"))

    # Ask for more bending than allowed: the field stops at the largest feasible dx, here at the
    # bending limit (theta_max; the racks would allow 210 mm). The browser clamps the typed
    # number to the slider's range (to its 0.1 mm step) on blur; the server refuses the raw one.
    boundary = _boundary(robot, q, (0, 0), 0.04, 0.24)
    assert boundary < 0.05
    type_value(page, "Δx₁", 240.0)
    wait_until("the field clamped on blur",
               lambda: float(slider(page, "Δx₁")[1].input_value()) != 40.0, 5)
    q[0, 0] = float(slider(page, "Δx₁")[1].input_value()) / 1e3
    assert q[0, 0] == pytest.approx(boundary, abs=1e-3) and _feasible(robot, q)
    tip = dk.tip_position(robot, q)
    racks = _racks(robot, q)
    wait_for_readout(page, {"tip-0": tip[0] * 1e3, "tip-2": tip[2] * 1e3,
                            "rack-1-1": racks[0, 0] * 1e3})
    assert page.get_by_text("bending limit").count() >= 1
    # Retract segment 1 below what that bend needs: the racks stop it, flagged at their limit.
    q[0, 2] = _boundary(robot, q, (0, 2), 0.15, 0.0)  # smallest feasible dL at that bend
    type_value(page, "δL₁", 0.0)  # mm
    tip = dk.tip_position(robot, q)
    racks = _racks(robot, q)
    wait_for_readout(page, {"tip-0": tip[0] * 1e3, "tip-2": tip[2] * 1e3,
                            "rack-1-2": racks[0, 1] * 1e3})
    assert page.get_by_text("clamped").count() >= 1
    assert page.locator('[data-testid="rack-1-2"]').get_attribute("data-near-limit") == "true"
    page.screenshot(path=str(artifacts_dir / "browser_extensible_clamped.png"))


def _held_bend_of_a_retracted_arm_is_refused_with_a_note(page: Any, app: ConsoleApp,
                                                        artifacts_dir: Path) -> None:
    jog = app.panel(JogPanel)
    retracted = np.zeros((app.robot.n_segments, 3))  # every rack at rack_min: no bend possible
    app.store.request(retracted, "test")
    row = next(r for r in jog.rows if r.coord.key == "dx1")
    minus = _box(page, row.minus)
    note = page.get_by_text("clamped to +0 mm")
    for _ in range(3):  # a loaded box can lose the lease for a moment ("Not allowed"): again
        page.mouse.move(minus["x"] + minus["width"] / 2, minus["y"] + minus["height"] / 2)
        page.mouse.down()
        time.sleep(0.5)
        page.mouse.up()
        try:
            wait_until("the clamp note", lambda: note.count() > 0, 5)
            break
        except AssertionError:
            continue
    text = page.locator("body").inner_text()
    assert "clamped to +0 mm" in text and "extend δL₁ first" in text, text[-600:]
    assert not NEGATIVE_ZERO.findall(text), [ln for ln in text.splitlines()
                                             if NEGATIVE_ZERO.search(ln)]
    np.testing.assert_array_equal(np.asarray(app.store.command.q), retracted)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_clamp.png"))


def test_jog_rows_sliders_held_buttons_and_readout_in_a_real_browser(
        jog_page, artifacts_dir: Path) -> None:
    page, app = jog_page
    _rows_sit_on_their_sliders(page, app, artifacts_dir)
    _take_control(app)
    if not isinstance(app.model, ExtensibleModel):  # the soft arm
        _soft_arm_slider_jogs_follow_the_kinematics(page, app, artifacts_dir)
        _hold_jogs_until_released(page, app, "kappa1")
    else:
        _extensible_typed_jogs_follow_the_kinematics_and_clamp(page, app, artifacts_dir)
        _hold_jogs_until_released(page, app, "dL1")
        _held_bend_of_a_retracted_arm_is_refused_with_a_note(page, app, artifacts_dir)
