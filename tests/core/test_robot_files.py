"""tests/robot_files.py: a test copy of a robot file differs from the original in exactly the
values asked for (read back through core.robots.load), and a key it cannot find is an error."""

import dataclasses

import numpy as np
import pytest
from robot_files import QUICK_MOTION, TEST_ROBOTS, robot_copy

from core.robots import load


def test_quick_copy_changes_only_the_motion_values(tmp_path):
    shipped = load("soft-arm")
    quick = load(robot_copy("soft-arm", tmp_path, QUICK_MOTION))
    assert quick.name == "soft-arm-test" and quick.source.parent == tmp_path
    np.testing.assert_array_equal(quick.trajectory.max_velocity, [2.4] * 6)
    np.testing.assert_array_equal(quick.trajectory.max_acceleration, [4.5] * 6)
    np.testing.assert_array_equal(quick.trajectory.max_jerk, [30.0] * 6)
    assert quick.trajectory.synchronization == shipped.trajectory.synchronization
    sm = dataclasses.replace(shipped.state_machine, settle_time_s=0.5, grasp_time_s=0.8,
                             release_time_s=0.5)
    assert quick.state_machine == sm != shipped.state_machine
    for field in ("controller", "sim", "bridge", "emulator", "planner", "gripper", "capture"):
        assert getattr(quick, field) == getattr(shipped, field), field
    assert quick.lengths.tolist() == shipped.lengths.tolist()


def test_copy_of_a_test_robot_file_with_a_name(tmp_path):
    path = robot_copy(TEST_ROBOTS / "soft-4x80mm.toml", tmp_path,
                      {"bridge.watchdog_ms": 1000}, name="four-slack")
    arm = load(path)
    assert (arm.name, arm.n_segments, path.name) == ("four-slack", 4, "four-slack.toml")
    assert arm.bridge.watchdog_ms == 1000


@pytest.mark.parametrize("key", ["trajectory.no_such_key", "controller.max_velocity",
                                 "cylinder_rate"])
def test_a_key_not_once_in_its_section_is_refused(tmp_path, key):
    with pytest.raises(KeyError, match="not found exactly once"):
        robot_copy("soft-arm", tmp_path, {key: 1.0})
