"""Browser tests of lab robots that are not the shipped ones: the runtime takes its counts from the file.

``serve.py --robot tests/data/robots/soft-4x80mm.toml`` (four 80 mm segments) runs a full
grasp-and-place from the Control panel to ``released``; ``serve.py --robot
tests/data/robots/extensible-3seg.toml`` (three tri-rack segments) moves its tip to a typed target
that the IK reaches. Expectations come from the robot files (the object position scales with the
arm; the tip target is checked with the test's own call of the IK and forward kinematics).
The four-segment arm moves as tests/robot_files.py QUICK_MOTION says (a test copy of its file):
what is tested is that the runtime takes its counts from the file, not the shipped timing.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from robot_files import QUICK_MOTION, robot_copy

from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load

pytestmark = pytest.mark.browser

DATA = Path(__file__).resolve().parents[1] / "data" / "robots"


def test_four_segment_soft_arm_grasps_and_places_from_the_browser(
        page, console_server: Callable[..., str], tmp_path: Path, artifacts_dir: Path) -> None:
    from test_browser_control import (close_notices, kappa_measured, open_control, start_grasp,
                                      wait_phase)

    robot_file = robot_copy(DATA / "soft-4x80mm.toml", tmp_path, QUICK_MOTION)
    arm = load(robot_file)
    assert arm.n_segments == 4
    total = arm.n_segments * arm.segment_length
    x, y = -0.53 * total, 0.53 * total  # up and to the left, within reach of this arm
    page.set_viewport_size({"width": 1024, "height": 760})
    try:
        open_control(page, console_server(str(robot_file), "--no-token"))
        page.locator('[data-testid="control-link"]').wait_for(timeout=60_000)
        close_notices(page)
        start_grasp(page, x, y, ("grasp", "move_to_bin"), timeout=60.0)
        assert kappa_measured(page).shape == (4,)  # one measured curvature per segment
        wait_phase(page, ("released",), timeout=60.0, avoid=("stopped", "idle"))
        page.screenshot(path=str(artifacts_dir / "browser_soft_4x80mm_released.png"))
    except BaseException:
        page.screenshot(path=str(artifacts_dir / "browser_soft_4x80mm_failure.png"))
        raise


def test_three_segment_extensible_arm_reaches_a_typed_target(
        page, console_server: Callable[..., str], artifacts_dir: Path) -> None:
    from browser_tabs import wait_until
    from test_browser_extensible import open_extensible, readout_tip, type_target

    robot_file = DATA / "extensible-3seg.toml"
    arm = load(robot_file)
    assert arm.n_segments == 3
    target = np.array([100.0, -50.0, 0.8 * arm.n_segments * arm.rack_max * 1e3])  # mm
    ik = solve_tip_ik(arm, target / 1e3)
    assert ik.reachable and np.linalg.norm(dk.tip_position(arm, ik.delta) - target / 1e3) < 1e-3
    try:
        open_extensible(page, console_server(str(robot_file)))
        type_target(page, target)
        wait_until("the tip readout at the target",
                   lambda: np.abs(readout_tip(page) - target).max() <= 1.0, timeout=20.0,
                   show=lambda: str(readout_tip(page)))
        status = page.locator('[data-testid="target-status"]')
        wait_until("the reachable status",
                   lambda: status.get_attribute("data-state") == "reachable")
        racks = page.locator('[data-testid^="rack-"][data-near-limit]').all_inner_texts()
        assert len(racks) == 3 * arm.n_segments  # a rack readout per rack of the file's arm
        time.sleep(0.3)
        page.screenshot(path=str(artifacts_dir / "browser_extensible_3seg_target.png"))
    except BaseException:
        page.screenshot(path=str(artifacts_dir / "browser_extensible_3seg_failure.png"))
        raise
