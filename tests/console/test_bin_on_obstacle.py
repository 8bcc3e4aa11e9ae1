"""A bin is not placed on an obstacle: seen in a walk through the console, a click with "Table
click places: Bin" on an obstacle put the bin's box around it without a word (the arm could
hold an object over the point, which was all that was checked). Refused with the reason, and no
bin is placed; with the obstacle gone the same click places it."""

from __future__ import annotations

import time

import pytest
from test_row_console import BIN_XY, SOFT, rig, wait_for  # noqa: F401

from console.core.table_bin import bin_overlap, locate_bin
from core.planning.obstacles import Obstacle
from fakes import click_at, user

HALF = SOFT.bin.drop_radius_m


def test_bin_overlap_is_the_box_against_the_disk() -> None:
    disk = Obstacle("Obstacle 1", 0.0, 0.0, 0.02)
    assert bin_overlap(0.0, 0.0, HALF, [disk]) is not None  # centred on it
    assert bin_overlap(HALF + 0.019, 0.0, HALF, [disk]) is not None  # a wall 1 mm into it
    assert bin_overlap(HALF + 0.021, 0.0, HALF, [disk]) is None  # 1 mm clear of a wall
    d = 0.02 / 2 ** 0.5  # corner: clear when the corner is just outside the disk
    assert bin_overlap(HALF + d + 0.001, HALF + d + 0.001, HALF, [disk]) is None
    assert bin_overlap(HALF + d - 0.001, HALF + d - 0.001, HALF, [disk]) is not None
    why = bin_overlap(0.01, 0.0, HALF, [disk])
    assert "would stand on Obstacle 1" in why and "move Obstacle 1" in why


def test_a_click_on_an_obstacle_places_no_bin(rig) -> None:
    app, objects_panel, _, _, operator, _ = rig
    s = app.grasp_session
    locate_bin(SOFT, *BIN_XY)  # the arm could hold an object there: only the obstacle is wrong
    s.place_obstacle(BIN_XY[0] + 0.01, BIN_XY[1], 0.02)
    user(objects_panel.click_place, operator, "Bin")
    click_at(objects_panel, operator, *BIN_XY)
    wait_for(lambda: any(t == "Bin" for t, _ in operator.notes))
    assert any("Not placed: the bin's box (100 mm wide) at (150, 250) mm would stand on "
               "Obstacle 1" in b for _, b in operator.notes), operator.notes
    time.sleep(0.3)
    assert s.view().bin is None
    s.remove_obstacle("Obstacle 1")  # gone: the same click places the bin
    click_at(objects_panel, operator, *BIN_XY)
    placed = wait_for(lambda: s.view().bin)
    assert (placed.x, placed.y) == pytest.approx(BIN_XY)
