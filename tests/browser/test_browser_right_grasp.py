"""Browser test: the Control panel grasps an object on the right of the arm (issue #17.2).

Chromium types an object at the paper's spot E mirrored across the arm's base line (80, 330) mm
into the Objects panel, arms and presses *Execute grasp-and-place* on the simulated arm
(serve.py --hardware mock, two-finger gripper). The state line must go through the grasp to
"released" -- which the state machine says only after it saw the object held where the right
finger's pocket is and carried to the bin -- and during the grasp the palm readout is at the
object, on the right of the arm (x > 0).

The arm is a test copy of the soft arm that moves three times faster with shorter waits
(tests/robot_files.py QUICK_MOTION): the test is about which side the gripper takes, not the
shipped timing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from robot_files import QUICK_MOTION, robot_copy
from test_browser_control import open_control, start_grasp, state_text, wait_phase

from core.control.trials import paper_locations

# alone: the palm readout follows the drawn arm at the page's frame rate, and the check samples
# it near the object (two Chromiums on 2 cores halve the rate; conftest's SUITE_PART=alone)
pytestmark = [pytest.mark.browser, pytest.mark.alone]


def palm_mm(page: Any) -> tuple[float, float]:
    return tuple(float(page.locator(f'[data-testid="palm-{i}"]').inner_text().replace("⚠", ""))
                 for i in range(2))  # type: ignore[return-value]


def test_execute_grasps_a_right_side_object_and_releases_it(
        page, console_server: Callable[..., str], tmp_path: Path, artifacts_dir: Path) -> None:
    x, y = paper_locations()["E"]
    spot = (-x, y)  # right of the arm
    page.set_viewport_size({"width": 1024, "height": 760})
    try:
        open_control(page, console_server(str(robot_copy("soft-arm", tmp_path, QUICK_MOTION)),
                                          "--no-token"))
        start_grasp(page, *spot, until=("grasp", "move_to_bin"), timeout=90.0)
        palm = palm_mm(page)
        page.screenshot(path=str(artifacts_dir / "browser_right_grasp.png"))
        # The palm point is g_off + r = 26.5 mm beside the object's centre: on its right side.
        assert palm[0] > 0 and math.hypot(palm[0] - spot[0] * 1e3, palm[1] - spot[1] * 1e3) < 55.0, \
            (palm, state_text(page))
        wait_phase(page, ("released",), timeout=90.0, avoid=("stopped", "idle"))
        time.sleep(0.2)
        assert "released" in state_text(page)
    except BaseException:
        page.screenshot(path=str(artifacts_dir / "browser_right_grasp_failure.png"))
        raise
