"""No object hidden inside an obstacle, no obstacle dropped onto an object: seen in a walk
through the console, a click (or Add) put an object inside an obstacle's cylinder, where it was
hidden and the planner refused it later ("The object overlaps Obstacle 1"). Like a bin on an
obstacle (test_bin_on_obstacle), refused at once with the reason, and nothing changes; clear of
each other both are placed."""

from __future__ import annotations

import pytest
from test_row_console import rig  # noqa: F401

from console.core.table_scene import TableObject, disk_overlap
from core.planning.obstacles import Obstacle
from fakes import click_at, user
from tests.ws_client import wait_for

OBSTACLE_XY = (0.05, 0.30)


def test_disk_overlap_is_the_gap_between_the_circles() -> None:
    disk = Obstacle("Obstacle 1", 0.0, 0.0, 0.02)
    assert disk_overlap("Object 2", 0.0, 0.0, 0.01, [disk]) is not None  # inside it
    assert disk_overlap("Object 2", 0.029, 0.0, 0.01, [disk]) is not None  # 1 mm into it
    assert disk_overlap("Object 2", 0.031, 0.0, 0.01, [disk]) is None  # 1 mm clear
    assert disk_overlap("Object 2", 0.0, -0.031, 0.01, [disk]) is None
    why = disk_overlap("Object 2", 0.02, 0.0, 0.01, [disk])
    assert why == ("Not placed: Object 2 (r 10.0 mm) at (20, 0) mm would overlap Obstacle 1 "
                   "(by 10 mm): place it farther from Obstacle 1, or move Obstacle 1")
    obj = TableObject("Object 1", 0.0, 0.0, 0.0165)  # and an obstacle against the objects
    assert "would overlap Object 1" in disk_overlap("Obstacle 2", 0.03, 0.0, 0.02, [obj])


def test_a_click_or_add_on_an_obstacle_places_no_object(rig) -> None:
    app, objects_panel, _, _, operator, _ = rig
    s = app.grasp_session
    s.place_obstacle(*OBSTACLE_XY, 0.02)
    click_at(objects_panel, operator, OBSTACLE_XY[0] + 0.0104, OBSTACLE_XY[1])
    assert [o.name for o in s.view().objects] == ["Object 1"]
    title, body = operator.notes[-1]
    assert title == "Objects" and body.startswith("Not placed: Object 2 (r 16.5 mm) at (60, 300) "
                                                  "mm would overlap Obstacle 1 (by 26 mm)")
    user(objects_panel.x, operator, 50.0)  # Object 1 typed to (50, 200) mm: moved;
    # (the session's echo of the move is shown from its own thread: once it is, the fields
    # hold what the operator types next; a late echo wrote y back to 200 before Add below)
    wait_for(lambda: "at (50, 200) mm" in objects_panel.info.content, what="the move shown")
    user(objects_panel.y, operator, 330.0)  # then to (50, 330) mm, on the obstacle: not moved
    assert operator.notes[-1][1].startswith("Not moved: Object 1 (r 16.5 mm) at (50, 330) mm "
                                            "would overlap Obstacle 1")
    assert [(o.x, o.y) for o in s.view().objects] == [pytest.approx((0.05, 0.20))]
    user(objects_panel.add_button, operator)  # Add at the typed spot, on the obstacle: refused
    assert [o.name for o in s.view().objects] == ["Object 1"]
    assert operator.notes[-1][1].startswith("Not placed: Object 2 (r 16.5 mm) at (50, 330) mm "
                                            "would overlap Obstacle 1")
    s.drag("Object 1", *OBSTACLE_XY, live=False)  # dragged onto it: stays where it was
    assert [(o.x, o.y) for o in s.view().objects] == [pytest.approx((0.05, 0.20))]
    s.remove_obstacle("Obstacle 1")  # gone: the same click places the object
    click_at(objects_panel, operator, OBSTACLE_XY[0] + 0.0104, OBSTACLE_XY[1])
    assert [(o.x, o.y) for o in s.view().objects][-1] == pytest.approx(
        (OBSTACLE_XY[0] + 0.0104, OBSTACLE_XY[1]))


def test_a_click_on_an_object_places_no_obstacle(rig) -> None:
    app, objects_panel, _, _, operator, _ = rig
    s = app.grasp_session
    obj = s.view().objects[0]
    user(objects_panel.click_place, operator, "Obstacle")
    click_at(objects_panel, operator, obj.x + 0.02, obj.y)
    assert s.view().obstacles == ()
    assert operator.notes[-1][1].startswith("Not placed: Obstacle 1 (r 20.0 mm) at (-180, 200) "
                                            "mm would overlap Object 1")
    click_at(objects_panel, operator, obj.x + 0.05, obj.y)  # 13.5 mm clear of it: placed
    assert [o.name for o in s.view().obstacles] == ["Obstacle 1"]
    with pytest.raises(ValueError, match="Not changed: Obstacle 1 .* would overlap Object 1"):
        s.update_obstacle("Obstacle 1", x=obj.x + 0.03)  # typed onto the object
    assert s.view().obstacles[0].x == pytest.approx(obj.x + 0.05)
