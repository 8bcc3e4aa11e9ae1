"""Browser tests: serve.py in a subprocess, Chromium jogs the arm, the readout follows the FK.

Each test drives the real viser client (Mantine sliders: keyboard on the slider thumb and typing
into the companion number box), then reads the tip readout the operator sees and compares it
with the pose computed here from ``core.kinematics`` (and closed-form rack lengths), checks the
3D canvas changed, and saves screenshots to ``artifacts/``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from browser_tabs import open_console, wait_until

from console.core.model import ExtensibleModel
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.robots import load

pytestmark = pytest.mark.browser
READOUT_TOL = 0.051  # the readout shows one decimal (mm, degrees)


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


def wait_for_readout(page, expected: dict[str, float], timeout: float = 5.0) -> None:
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


def test_soft_arm_jog_moves_tip_as_forward_kinematics(
        page, console_server: Callable[..., str], artifacts_dir: Path) -> None:
    robot = load("soft-arm")
    open_console(page, console_server("soft-arm"), "Readout", '[data-testid="tip-readout"]')
    straight = pk.forward_kinematics(np.zeros(6), robot.lengths, robot.base_pose)[-1]
    wait_for_readout(page, {"tip-0": straight[0] * 1e3, "tip-1": straight[1] * 1e3,
                            "tip-2": wrap_deg(straight[2])})
    page.screenshot(path=str(artifacts_dir / "browser_soft-arm_default.png"))
    before = canvas_png(page)

    # Click 3/4 along the κ₂ track (a mouse jog), then type -8 into κ₄'s number box.
    # (Not arrow keys: viser 1.1.1 also orbits the camera on arrow keys over a slider.)
    thumb, _, track = slider(page, "κ₂")
    track.scroll_into_view_if_needed()  # the Jog panel sits below others in the Operate tab
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
    time.sleep(0.3)  # let the client draw the mesh update
    assert canvas_png(page) != before, "3D view did not change after jogging"
    page.mouse.move(5, 5)  # park the pointer so no tooltip covers the panel
    page.screenshot(path=str(artifacts_dir / "browser_soft-arm_jogged.png"))


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


def test_extensible_jog_moves_tip_and_clamps_at_rack_limits(
        page, console_server: Callable[..., str], artifacts_dir: Path) -> None:
    robot = load("extensible")
    open_console(page, console_server("extensible"), "Readout", '[data-testid="tip-readout"]')
    # It starts straight with every rack at mid-range (issue 19.5: room to bend both ways).
    start = ExtensibleModel(robot).initial()
    assert np.all(start[:, :2] == 0.0)
    wait_for_readout(page, {"tip-0": 0.0, "tip-1": 0.0,
                            "tip-2": dk.tip_position(robot, start)[2] * 1e3})
    assert page.locator('[data-near-limit="true"]').count() == 0
    page.screenshot(path=str(artifacts_dir / "browser_extensible_default.png"))
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
    time.sleep(0.3)  # let the client draw the mesh update
    assert canvas_png(page) != before, "3D view did not change after jogging"
    page.screenshot(path=str(artifacts_dir / "browser_extensible_jogged.png"))

    # Ask for more bending than allowed: the field stops at the largest feasible dx, here at the
    # bending limit (theta_max; the racks would allow 210 mm). The browser clamps the typed
    # number to the slider's range (to its 0.1 mm step) on blur; the server refuses the raw one.
    boundary = _boundary(robot, q, (0, 0), 0.04, 0.24)
    assert boundary < 0.05
    type_value(page, "Δx₁", 240.0)
    deadline = time.monotonic() + 5.0
    while float(slider(page, "Δx₁")[1].input_value()) == 40.0 and time.monotonic() < deadline:
        time.sleep(0.1)  # the field clamped on blur
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
