"""What the soft arm's 3D view must show besides the arm's reach, so a far object's plan is not
cut off: the table's objects, the bin, and the approach circles and waypoints of the operator's
plan and of the plan the arm runs.

:func:`plan_points` turns a grasp session's snapshot (:class:`console.core.grasp_state.SessionView`)
into world points (m); ``console.scene.camera.presets`` widens a view that would leave one of
them out, and ``console.scene.window_fit`` re-frames each browser's camera when they change (a
new plan, an object or the bin placed or removed). Pure numpy: no viser here.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from console.core.grasp_state import SessionView
from console.scene.plan_geometry import Z_PLAN
from console.scene.run_view import Z_RUN, run_circle_radii

Array = npt.NDArray[np.float64]
# The grasp session's parts (console.core.grasp_state) whose change re-frames the cameras.
FRAMED_PARTS = frozenset({"objects", "bin", "plan", "run"})
RIM_POINTS = 16           # points per circle (a polygon around it: see _rim)
OBJECT_HEIGHT = 0.04      # m, the drawn object cylinders' height (plan_geometry.object_mesh)


def _rim(x: float, y: float, radii: npt.ArrayLike, z: float) -> Array:
    """Points around circles of ``radii`` about (x, y) at height ``z``: the corners of a
    polygon circumscribing each circle, so the circle is inside what frames the points."""
    a = np.linspace(0.0, 2 * math.pi, RIM_POINTS, endpoint=False)
    r = np.asarray(radii, float).reshape(-1, 1) / math.cos(math.pi / RIM_POINTS)
    pts = np.stack([x + r * np.cos(a), y + r * np.sin(a), np.full_like(r * a, z)], -1)
    return pts.reshape(-1, 3)


def plan_points(view: SessionView) -> Array:
    """World points (k, 3), m, of what the operator has on the table and plans: each object's
    cylinder (its rim, bottom and top), the placed bin's box, the newest plan's approach circles
    and waypoints (palm points) and, while the arm runs a task, the circles and waypoints of
    the plan it executes. (0, 3) for an empty table with no plan."""
    parts: list[Array] = [np.zeros((0, 3))]
    for o in view.objects:
        parts += [_rim(o.x, o.y, [o.r], 0.0), _rim(o.x, o.y, [o.r], OBJECT_HEIGHT)]
    if view.bin is not None:
        parts.append(_rim(view.bin.x, view.bin.y, [view.bin.drop_radius * math.sqrt(2)], 0.0))
    plan = view.outcome.plan if view.outcome is not None else None
    if plan is not None:
        cx, cy = (float(v) for v in np.asarray(plan.center, float)[:2])
        parts.append(_rim(cx, cy, plan.radii, Z_PLAN))
        palms = np.asarray(plan.palm_poses, float)[:, :2]
        parts.append(np.c_[palms, np.full(len(palms), Z_PLAN)])
    run = view.run
    if run is not None and run.plan is not None:
        cx, cy = (float(v) for v in run.plan.center)
        parts.append(_rim(cx, cy, run_circle_radii(run), Z_RUN))
        parts.append(np.c_[run.plan.palms[:, :2], np.full(run.plan.n, Z_RUN)])
    return np.concatenate(parts)
