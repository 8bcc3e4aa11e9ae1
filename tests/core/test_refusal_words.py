"""The planner's refusals in the screen's words: distances in mm (never cm), figures that never
read as equal when the object lies just past the reach, and the noun of what was asked about
(the bin refuses as "the bin", not "the object")."""

import re

import numpy as np
import pytest

from core import robots
from core.control.row import bin_at
from core.planning.arm_model import ArmModel
from core.planning.feasibility import GraspRefused, check_request

R = 0.0165


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def _reach(arm) -> float:
    """The cheap reach bound, from the robot file independently of the planner: the arm's length
    plus the palm-to-object offset of an object of radius R (the paper's final approach)."""
    g = arm.gripper
    return float(np.sum(arm.lengths)) + float(np.hypot(g.w_off_along, 2 * g.g_off + R))


def _refusal(arm, dist: float) -> GraspRefused:
    model = ArmModel.from_robot(arm)
    centre = model.base + dist * 1j  # straight ahead of the base (up the table)
    with pytest.raises(GraspRefused) as info:
        check_request(arm, model, np.zeros(model.n), centre, R, 0.0)
    return info.value


def test_out_of_reach_is_told_in_mm(arm):
    exc = _refusal(arm, _reach(arm) + 0.0376)
    text = str(exc)
    assert exc.reason == "out_of_reach" and " cm" not in text
    figures = [float(v) for v in re.findall(r"(\d+\.\d) mm", text)]
    assert figures[0] == pytest.approx((_reach(arm) + 0.0376) * 1e3, abs=0.05)
    assert figures[1] == pytest.approx(37.6, abs=0.05)      # how far beyond
    assert figures[2] == pytest.approx(_reach(arm) * 1e3, abs=0.05)


def test_just_past_the_reach_never_reads_as_equal(arm):
    text = str(_refusal(arm, _reach(arm) + 1e-5))  # 0.01 mm past: both round to the same mm
    assert "less than 0.1 mm beyond" in text, text


def test_the_bin_refuses_as_the_bin(arm):
    with pytest.raises(ValueError) as info:
        bin_at(arm, 0.6, 0.1)
    text = str(info.value)
    assert text.startswith("The bin at (600, 100) mm is out of reach"), text
    assert "The object" not in text and " cm" not in text
