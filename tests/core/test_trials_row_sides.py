"""``python -m core.control.trials --objects-in-a-row N --side right|both``: a row drawn on the
right finger's side (or alternating) is taken to the bin, released counted per side; a robot
whose gripper has no finger for that side is refused with the reason.

Independent expectations: the soft arm's base is at the origin heading +y, so the right side is
x > 0; at the robot file's straight bin the object held by the right finger lies in the right
pocket, by hand ``(2 g_off + r, N L + w_along)``, the left one's at ``-x`` (as in
test_row_sides). The positions checked are the simulated object's right after each release
(the JSON's ``final_object``), not the printed status.
"""

import json

import numpy as np
import pytest
from robot_files import QUICK_MOTION, robot_copy

from core import robots
from core.control.trials.__main__ import main as trials_main

ARM = robots.load("soft-arm")
G = ARM.gripper
R = ARM.capture.nominal_object_radius


@pytest.fixture(scope="module")
def two_fingers(tmp_path_factory):
    return str(robot_copy("soft-arm", tmp_path_factory.mktemp("robots"),
                          {**QUICK_MOTION, "gripper.fingers": "both"}, name="soft-two"))


@pytest.fixture(scope="module")
def one_finger(tmp_path_factory):
    return str(robot_copy("soft-arm", tmp_path_factory.mktemp("robots"),
                          {**QUICK_MOTION, "gripper.fingers": "left"}, name="soft-one"))


def pocket(side):
    normal, along = 2 * G.g_off + R, ARM.n_segments * ARM.segment_length + G.w_off_along
    return np.array([normal if side == "right" else -normal, along])


def run_row(capsys, robot, side, *extra):
    assert trials_main(["--objects-in-a-row", "3", "--side", side, "--robot", robot,
                        "--time-limit", "60", "--seed", "0", *extra]) == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("side, want", [("right", ["right"] * 3),
                                        ("both", ["left", "right", "left"])])
def test_a_row_on_a_side_is_released_into_the_bin(capsys, two_fingers, side, want):
    np.testing.assert_allclose(ARM.base_pose, [0.0, 0.0, np.pi / 2])  # heading +y: right is +x
    out = json.loads(run_row(capsys, two_fingers, side, "--json"))
    row = out["row"]
    assert [o["side"] for o in row] == want
    for o, s in zip(row, want):
        x, y, r = o["object"]
        assert (x > 0) == (s == "right") and y > 0 and r == R
        assert o["status"] == "released", o
        assert o["finger"] == s  # the finger that closes toward it held it
        assert np.hypot(*(np.array(o["final_object"]) - pocket(s))) < ARM.bin.drop_radius_m
    counts = {s: {"released": want.count(s), "objects": want.count(s)} for s in ("left", "right")
              if s in want}
    assert out["sides"] == counts and out["released"] == 3


def test_the_table_reports_released_per_side(capsys, two_fingers):
    lines = run_row(capsys, two_fingers, "both").splitlines()
    assert "side" in lines[0]
    assert [line.split()[8] for line in lines[1:4]] == ["left", "right", "left"]
    assert lines[4] == "3/3 released" and lines[5] == "per side: left 2/2 released, right 1/1 released"


@pytest.mark.parametrize("side", ["right", "both"])
def test_a_side_without_its_finger_is_refused(capsys, one_finger, side):
    with pytest.raises(SystemExit) as exc:
        trials_main(["--objects-in-a-row", "3", "--side", side, "--robot", one_finger])
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert ("robot 'soft-one' has no finger closing to the right ([gripper] fingers = \"left\")"
            in err), err


def test_side_with_given_objects_is_refused(capsys):
    with pytest.raises(SystemExit) as exc:
        trials_main(["--objects-in-a-row", "1", "--side", "right",
                     "--object", "0.13", "0.17", str(R)])
    assert exc.value.code == 2 and "with --object each object is grasped on the side" in \
        capsys.readouterr().err
