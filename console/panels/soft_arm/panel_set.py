"""The soft arm's grasp panels as one set, so a console composes them in one line and none of the
three needs to know the others (the set imports them; they never import it).

``grasp_panels()`` lists them in display order (Objects, Grasp planner, Waypoints) for
``ConsoleApp`` (e.g. ``DEFAULT_PANELS + tuple(grasp_panels())``); they work on the console's grasp
session (``ConsoleApp.grasp_session``), which exists on a soft arm whatever panels are built.
"""

from __future__ import annotations

from console.panels.common.base import Panel
from console.panels.soft_arm.objects import ObjectsPanel
from console.panels.soft_arm.planner import PlannerPanel
from console.panels.soft_arm.waypoints import WaypointsPanel


def grasp_panels() -> list[type[Panel]]:
    """The grasp panels in display order (Objects, Grasp planner, Waypoints)."""
    return [ObjectsPanel, PlannerPanel, WaypointsPanel]
