"""The table's rectangle around the arm, as pure geometry: the stage draws it, the grasp session's
reachability map covers it, and neither needs the other (nor a viser server) to know it."""

from __future__ import annotations

from typing import Any

Extent = tuple[float, float, float, float]  # (x0, x1, y0, y1) in m, on the table plane z = 0


def arm_span(robot: Any, kind: str) -> float:
    """Largest distance of any arm point from the base (straight, fully extended).

    Args:
        robot: The arm's description (``core.robots``).
        kind: ``"planar"`` for the soft arm, anything else for the extensible arm.

    Returns:
        The span in m.
    """
    if kind == "planar":
        return robot.n_segments * robot.segment_length + robot.gripper.length
    return robot.n_segments * robot.rack_max


def table_extent(robot: Any, kind: str) -> Extent:
    """Table rectangle (x0, x1, y0, y1) around the arm's workspace, in m.

    Args:
        robot: The arm's description (``core.robots``).
        kind: ``"planar"`` for the soft arm, anything else for the extensible arm.

    Returns:
        The rectangle the console draws as the table.
    """
    span = arm_span(robot, kind)
    if kind == "planar":
        return -1.0 * span, 1.0 * span, -0.4 * span, 1.15 * span
    return -0.75 * span, 0.75 * span, -0.75 * span, 0.75 * span
