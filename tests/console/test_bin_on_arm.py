"""A bin does not cover the arm: seen in a walk through the console, a click beside the straight
arm put the bin's 100 mm box over the arm's start pose (the arm could hold an object over the
point, which was all that was checked). Refused with the reason, and no bin is placed; a click
clear of the arm (its half width, the gripper beyond the tip) places it."""

from __future__ import annotations

import time

import pytest
from test_row_console import SOFT, rig, wait_for  # noqa: F401

from console.core.table_bin import bin_on_arm, locate_bin
from fakes import click_at, user

HALF = SOFT.bin.drop_radius_m
W, GW = SOFT.half_width, SOFT.gripper.half_width  # the body's and the gripper's half widths
TIP = sum(SOFT.lengths)  # the straight arm runs along +y from the base at the origin
END = TIP + SOFT.gripper.length


def test_bin_on_arm_is_the_box_against_the_straight_arm() -> None:
    assert SOFT.base_pose.tolist()[:2] == [0.0, 0.0]
    x_wall = HALF + W  # a box beside the body: its wall meets the body's side here
    assert bin_on_arm(SOFT, x_wall - 0.001, 0.20, HALF) is not None
    assert bin_on_arm(SOFT, x_wall + 0.001, 0.20, HALF) is None
    assert bin_on_arm(SOFT, -(x_wall - 0.001), 0.20, HALF) is not None  # either side
    y_end = END + GW + HALF  # beyond the gripper's rounded end (as the planner's clearance)
    assert bin_on_arm(SOFT, 0.0, y_end - 0.001, HALF) is not None
    assert bin_on_arm(SOFT, 0.0, y_end + 0.001, HALF) is None
    x_grip = HALF + GW  # beside the gripper (narrower than the body there)
    assert bin_on_arm(SOFT, x_grip + 0.001, (TIP + END) / 2 + HALF + 0.002, HALF) is None
    assert bin_on_arm(SOFT, x_grip - 0.001, (TIP + END) / 2, HALF) is not None
    why = bin_on_arm(SOFT, 0.05, 0.40, HALF)
    assert why == ("the bin's box (100 mm wide) at (50, 400) mm would cover the arm where it "
                   "starts, straight (by 12 mm): click farther from the arm")


def test_a_click_beside_the_arm_places_no_bin(rig) -> None:
    app, objects_panel, _, _, operator, _ = rig
    s = app.grasp_session
    locate_bin(SOFT, 0.05, 0.40)  # the arm could hold an object there: only the box is wrong
    user(objects_panel.click_place, operator, "Bin")
    click_at(objects_panel, operator, 0.05, 0.40)
    wait_for(lambda: any(t == "Bin" for t, _ in operator.notes))
    assert any("Not placed: the bin's box (100 mm wide) at (50, 400) mm would cover the arm"
               in b for _, b in operator.notes), operator.notes
    time.sleep(0.3)
    assert s.view().bin is None
    click_at(objects_panel, operator, 0.09, 0.40)  # 27.5 mm clear of the arm: placed
    placed = wait_for(lambda: s.view().bin)
    assert (placed.x, placed.y) == pytest.approx((0.09, 0.40))
