"""Browser tests of the extensible arm's console: typed tip target -> IK -> arm, and a path run.

serve.py runs in a subprocess (conftest's ``console_server``). Chromium types a target; the readout must show a tip
within 1 mm of it, which the test checks against its own IK (``solve_tip_ik`` /
``tip_position``), the Δ jog boxes must hold a posture whose tip is there too, and an
unreachable target must be reported with the distance the readout shows. The path test previews
and executes a linear traverse on the in-process MockHardware and checks the tip ends at the
path's end (``build_path``). Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import pytest

from core.kinematics import delta as dk
from core.planning.paths import build_path
from core.robots import load

pytestmark = pytest.mark.browser
REPO = Path(__file__).resolve().parent.parent
ROBOT = load("extensible")
READOUT_MM = 0.051  # the readout shows 0.1 mm
@pytest.fixture
def extensible_console(console_server: Callable[..., str]) -> Callable[[], str]:
    """serve.py for the extensible (it composes every panel of that robot), on the mock device."""
    return lambda: console_server("extensible")


def open_console(page, url: str) -> None:
    page.goto(url)
    page.get_by_text("Tip target", exact=True).wait_for(timeout=15_000)
    page.locator('[data-testid="tip-readout"]').wait_for(timeout=10_000)
    notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
    if notice.count():
        notice.locator("button").first.click()
        notice.wait_for(state="detached", timeout=5_000)


def field(page, label: str):
    uid = page.locator("label", has_text=label).first.get_attribute("for")
    assert uid, f"no input labelled {label!r}"
    return page.locator(f'[id="{uid}"]')


def type_target(page, xyz_mm) -> None:
    for axis, value in zip("xyz", xyz_mm):
        box = field(page, f"Target {axis} (mm)")
        box.fill(f"{value:g}")
        box.press("Tab")


def readout_tip(page) -> np.ndarray:
    return np.array([float(page.locator(f'[data-testid="tip-{k}"]').inner_text())
                     for k in range(3)])


def wait_until(what: str, fn: Callable[[], bool], timeout: float = 10.0,
               show: Callable[[], str] = lambda: "") -> None:
    deadline = time.monotonic() + timeout
    while not fn():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what} {show()}")
        time.sleep(0.1)


def jog_posture(page) -> np.ndarray:
    """The Δ jog sliders' values (m) as (n, 3), full precision (the boxes show 3 decimals)."""
    labels = [f"{c}{s} (m)" for s in "₁₂" for c in ("Δx", "Δy", "δL")]
    values = []
    for label in labels:
        uid = page.locator("label", has_text=label).first.get_attribute("for")
        thumb = page.locator(f'[id="{uid}"]').get_by_role("slider")
        values.append(float(thumb.get_attribute("aria-valuenow")))
    return np.array(values).reshape(ROBOT.n_segments, 3)


def test_typed_target_moves_the_tip_and_the_jog_sliders(
        page, extensible_console: Callable[[], str], artifacts_dir: Path) -> None:
    open_console(page, extensible_console())
    target = np.array([120.0, -60.0, 350.0])  # mm
    ik = dk.solve_tip_ik(ROBOT, target / 1e3)
    assert ik.reachable and np.linalg.norm(dk.tip_position(ROBOT, ik.delta) - target / 1e3) < 1e-3
    type_target(page, target)
    wait_until("the tip readout at the target",
               lambda: np.abs(readout_tip(page) - target).max() <= 1.0)
    status = page.locator('[data-testid="target-status"]')
    wait_until("the reachable status", lambda: status.get_attribute("data-state") == "reachable")
    # The jog sliders mirror the posture the IK chose (the panel rounds them to 1e-6 m).
    wait_until("the jog sliders in sync", lambda: np.linalg.norm(
        dk.tip_position(ROBOT, jog_posture(page)) * 1e3 - target) <= 1.0)
    time.sleep(0.3)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_target.png"))

    far = np.array([900.0, -60.0, 350.0])  # beyond the 820 mm arm
    assert not dk.solve_tip_ik(ROBOT, far / 1e3).reachable
    type_target(page, far)
    wait_until("the unreachable status",
               lambda: status.get_attribute("data-state") == "unreachable", timeout=15)
    said = float(status.get_attribute("data-error-mm"))
    wait_until("the readout at the closest feasible tip", lambda: abs(
        np.linalg.norm(readout_tip(page) - far) - said) <= 0.2)
    assert said > 1.0 and f"{said:.1f} mm" in status.inner_text()
    racks = [float(t.replace("⚠", "")) for t in
             page.locator('[data-testid^="rack-"][data-near-limit]').all_inner_texts()]
    assert min(racks) >= ROBOT.rack_min * 1e3 - 0.05 and max(racks) <= ROBOT.rack_max * 1e3 + 0.05
    time.sleep(0.3)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_unreachable.png"))


def test_path_preview_and_execute_on_mock_hardware(
        page, extensible_console: Callable[[], str], artifacts_dir: Path) -> None:
    open_console(page, extensible_console())
    start = np.array([100.0, 0.0, 300.0])
    type_target(page, start)
    wait_until("the tip at the start", lambda: np.abs(readout_tip(page) - start).max() <= 1.0)
    status = page.locator('[data-testid="path-status"]')
    page.get_by_role("button", name="Preview").click()
    wait_until("the preview", lambda: status.get_attribute("data-state") == "previewed", 60,
               show=status.inner_text)
    centre = readout_tip(page) / 1e3
    end = build_path("linear", centre, 0.08, "xy")[-1] * 1e3  # default: linear, 80 mm, xy
    page.get_by_text("Paths", exact=True).scroll_into_view_if_needed()
    page.screenshot(path=str(artifacts_dir / "browser_extensible_path_preview.png"))
    page.get_by_role("button", name="Execute").click()
    wait_until("the run to finish", lambda: status.get_attribute("data-state") == "done", 60,
               show=status.inner_text)
    wait_until("the readout at the path's end",
               lambda: np.abs(readout_tip(page) - end).max() <= 1.0)
    wait_until("the jog sliders at the path's end", lambda: np.linalg.norm(
        dk.tip_position(ROBOT, jog_posture(page)) * 1e3 - end) <= 1.0)
    time.sleep(0.3)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_path_done.png"))
