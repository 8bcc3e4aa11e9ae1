"""Browser test of the extensible arm's box obstacles: the operator places a shelf board in the
Obstacles panel, types a tip target over it, and the arm reaches it with its whole body (the
robot file's ``body_radius`` around the backbone) clear of the shelf.

serve.py runs in a subprocess (conftest's ``console_server``, mock hardware). What the server
holds is read from the page: the Obstacles panel's info (``data-count``, ``data-names``), the
tip target's status (``data-state``, ``data-clearance-mm``), the tip readout and the Δ jog
sliders (the commanded posture). The posture's clearance is checked here independently, by
sampling the backbone every 0.5 mm with ``delta.forward_kinematics`` and measuring each point's
distance to the box by clipping, minus the body radius. Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from browser_tabs import open_console, wait_until
from test_browser_extensible import jog_posture, readout_tip

from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load

pytestmark = pytest.mark.browser
ROBOT = load("extensible")
SHELF_CENTRE_MM, SHELF_SIZE_MM = (200.0, 0.0, 250.0), (200.0, 300.0, 20.0)
TARGET_MM = np.array([200.0, 0.0, 380.0])  # 120 mm above the board: room for the 45 mm body
CLEARANCE_MM = 20.0                          # the panel's default


def field(page, label: str):
    uid = page.locator("label", has_text=label).first.get_attribute("for")
    assert uid, f"no input labelled {label!r}"
    return page.locator(f'[id="{uid}"]')


def fill(page, label: str, value: str) -> None:
    """Type ``value`` into the input labelled ``label`` (generous timeouts: on a loaded 2-core
    box the page can take a minute to make its inputs editable)."""
    box = field(page, label)
    box.fill(value, timeout=120_000)
    box.press("Tab", timeout=60_000)


def surface_distance_mm(delta: np.ndarray) -> float:
    """Smallest distance (mm) from the arm's body at ``delta`` to the shelf: the backbone's,
    sampled every 0.5 mm (an arc fraction s of segment i is segment i with (s dx, s dy, s L)),
    minus the body radius."""
    lo = (np.array(SHELF_CENTRE_MM) - np.array(SHELF_SIZE_MM) / 2) / 1e3
    hi = (np.array(SHELF_CENTRE_MM) + np.array(SHELF_SIZE_MM) / 2) / 1e3
    frames = dk.forward_kinematics(delta, ROBOT.L0, ROBOT.d)
    pts = [np.zeros((1, 3))]
    for i, (dx, dy, dl) in enumerate(delta):
        length = ROBOT.L0 + dl
        s = np.linspace(0.0, 1.0, int(math.ceil(length / 5e-4)) + 1)[1:]
        part = np.stack([s * dx, s * dy, s * length - ROBOT.L0], axis=-1)
        pts.append((frames[i] @ dk.segment_transform(part, ROBOT.L0, ROBOT.d))[:, :3, 3])
    p = np.vstack(pts)
    outside = np.linalg.norm(p - np.clip(p, lo, hi), axis=-1)
    inside = np.minimum(p - lo, hi - p).min(axis=-1)
    return float((np.where(outside > 0, outside, -inside).min() - ROBOT.body_radius) * 1e3)


def test_shelf_box_and_a_target_over_its_edge_reached_clear_of_it(
        page, console_server: Callable[..., str], artifacts_dir: Path) -> None:
    open_console(page, console_server("extensible"), "Obstacles (boxes)",
                 '[data-testid="tip-readout"]', timeout_ms=180_000)  # (a loaded box)
    # Without the shelf the plain IK's arc would pass through it (so this is a real detour).
    plain = solve_tip_ik(ROBOT, TARGET_MM / 1e3)
    assert plain.reachable and surface_distance_mm(plain.delta) < 0

    info = page.locator('[data-testid="boxes-info"]')
    for axis, c, s in zip("xyz", SHELF_CENTRE_MM, SHELF_SIZE_MM):
        fill(page, f"Centre {axis} (mm)", f"{c:g}")
        fill(page, f"Size {axis} (mm)", f"{s:g}")
    page.get_by_role("button", name="Add box").click(timeout=120_000)
    wait_until("the shelf in the server's scene", lambda: info.get_attribute("data-count") == "1",
               timeout=30, show=info.inner_text)
    assert info.get_attribute("data-names") == "Shelf"
    assert float(info.get_attribute("data-clearance-mm")) == CLEARANCE_MM

    for axis, value in zip("xyz", TARGET_MM):
        fill(page, f"Target {axis} (mm)", f"{value:g}")
    status = page.locator('[data-testid="target-status"]')
    aimed = ",".join(f"{v:.1f}" for v in TARGET_MM)   # not a partly typed target's answer
    wait_until("the target solved with the shelf",
               lambda: status.get_attribute("data-target-mm") == aimed
               and status.get_attribute("data-state") in ("reachable", "blocked", "error"),
               timeout=60, show=status.inner_text)
    assert status.get_attribute("data-state") == "reachable", status.inner_text()
    assert float(status.get_attribute("data-clearance-mm")) >= CLEARANCE_MM
    assert "Shelf" in status.inner_text()
    wait_until("the tip readout at the target",
               lambda: np.abs(readout_tip(page) - TARGET_MM).max() <= 1.0, timeout=60,
               show=lambda: str(readout_tip(page)))
    wait_until("the jog sliders at the reached posture", lambda: np.linalg.norm(
        dk.tip_position(ROBOT, jog_posture(page)) * 1e3 - TARGET_MM) <= 1.0, timeout=30)
    posture = jog_posture(page)
    # The sliders show 1e-6 mm; 0.5 mm sampling leaves at most 0.25 mm between samples.
    assert surface_distance_mm(posture) >= CLEARANCE_MM - 0.3
    page.get_by_text("Obstacles (boxes)", exact=True).scroll_into_view_if_needed()
    time.sleep(0.5)
    page.screenshot(path=str(artifacts_dir / "browser_boxes_shelf_reached.png"))
