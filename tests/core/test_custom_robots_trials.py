"""A lab's own soft arm (tests/data/robots/, see test_custom_robots.py) grasps an object and puts
it in the bin in a headless trial through the simulated arm. The trial runs on simulated time
(its time limit is the loop's clock, not the wall's), so unlike the device tests of
test_custom_robots.py (marked `timing`) it runs in the suite's parallel part.
"""

from __future__ import annotations

import pytest
from test_custom_robots import DATA, SOFT, load, reachable_object

from core.control.trials import run_trials


@pytest.mark.parametrize("name", SOFT)
def test_soft_arm_trial_grasps_and_places_through_the_simulated_arm(name):
    x, y, r = reachable_object(load(name))
    (result,) = run_trials(str(DATA / f"{name}.toml"), [("mid", (x, y, r))], 1, seed=3,
                           time_limit_s=120.0)
    assert result.success, result.failure
    assert result.approach_s > 0 and result.return_s > 0
