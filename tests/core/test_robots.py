"""Robot descriptions load from data files and bad files name the bad field."""

import math

import pytest

from core import robots


def test_soft_arm_matches_the_paper():
    arm = robots.load("soft-arm")
    assert arm.n_segments == 6 and arm.segment_length == pytest.approx(0.0627)
    assert arm.kappa_max == pytest.approx(16.7)
    assert math.degrees(arm.kappa_max * arm.segment_length) == pytest.approx(60, abs=0.1)
    assert arm.gripper.length == pytest.approx(0.106)
    assert arm.drive_cylinders == 13
    assert tuple(arm.base_pose) == (0.0, 0.0, pytest.approx(math.pi / 2))


def test_extensible_defaults():
    arm = robots.load("extensible")
    assert arm.n_segments == 2 and arm.d == pytest.approx(0.03)
    assert (arm.rack_min, arm.rack_max) == (0.05, 0.41)
    assert arm.phi == pytest.approx(math.pi) and arm.tip_speed == pytest.approx(0.10)
    assert arm.n_segments * arm.rack_max == pytest.approx(0.82)


def _write(tmp_path, name, old, new):
    text = (robots.ROBOTS_DIR / f"{name}.toml").read_text()
    assert old in text
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize("old,new,field", [
    ("length = 0.0627", "length = -1", "segments.length"),
    ("kappa_max = 16.7", "kappa_max = \"high\"", "segments.kappa_max"),
    ("count = 6 ", "count = 0 ", "segments.count"),
    ("count = 6 ", "count = 100000 ", r"segments.count: must be an integer in \[1, 15\]"),
    ("pose = [0.0, 0.0, 1.5707963267948966]", "pose = [0.0, 0.0]", "base.pose"),
    ("g_off = 0.010", "", "gripper.g_off"),
])
def test_bad_soft_arm_file_names_the_field(tmp_path, old, new, field):
    with pytest.raises(robots.RobotFileError, match=field.replace(".", r"\.")):
        robots.load(_write(tmp_path, "soft-arm", old, new))


@pytest.mark.parametrize("old,new,field", [
    ("rack_max = 0.41", "rack_max = 0.01", "segments.rack_max"),
    ("counts_per_metre = 76000.0", "count = 5\ncounts_per_metre = 76000.0", "motors.count"),
    ("rack_radius = 0.03", "rack_radius = 0", "segments.rack_radius"),
])
def test_bad_extensible_file_names_the_field(tmp_path, old, new, field):
    with pytest.raises(robots.RobotFileError, match=field.replace(".", r"\.")):
        robots.load(_write(tmp_path, "extensible", old, new))


def test_unknown_robot_lists_the_shipped_ones():
    with pytest.raises(robots.RobotFileError, match="soft-arm"):
        robots.load("no-such-arm")


def test_not_toml_is_reported(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("this is = = not toml")
    with pytest.raises(robots.RobotFileError, match="not valid TOML"):
        robots.load(p)


def test_extensible_bending_and_motor_limits():
    arm = robots.load("extensible")
    assert arm.theta_max == pytest.approx(math.pi / 2)
    assert arm.bend_max == pytest.approx(arm.d * math.pi / 2)
    assert arm.motor_speed == pytest.approx(0.05)
    assert arm.motor_speed_counts == pytest.approx(0.05 * arm.counts_per_metre)
    # The emulated motors are a bit faster than the planner's motor limit.
    emu = arm.emulator.motor_speed_counts
    assert arm.motor_speed_counts < emu <= 1.5 * arm.motor_speed_counts


@pytest.mark.parametrize("old,new,field", [
    ("theta_max = 1.5707963267948966", "theta_max = 0", "segments.theta_max"),
    ("theta_max = 1.5707963267948966", "theta_max = 7.0", "segments.theta_max"),
    ("theta_max = 1.5707963267948966", "", "segments.theta_max"),
    ("motor_speed = 0.05 ", "motor_speed = -0.05 ", "limits.motor_speed"),
    ("motor_speed = 0.05 ", "motor_speed = \"fast\" ", "limits.motor_speed"),
    ("motor_speed = 0.05 ", "", "limits.motor_speed"),
    ("motor_speed_counts = 4560.0", "motor_speed_counts = 3000.0", "emulator.motor_speed_counts"),
])
def test_bad_extensible_limits_name_the_field(tmp_path, old, new, field):
    with pytest.raises(robots.RobotFileError, match=field.replace(".", r"\.")) as err:
        robots.load(_write(tmp_path, "extensible", old, new))
    if "emulator" in field:
        assert "3800 counts/s" in str(err.value)
