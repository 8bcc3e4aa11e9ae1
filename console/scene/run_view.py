"""The plan the ARM is executing, in the 3D view, so the scene never shows another plan than the
one running (issue 31.1).

:class:`RunScene` draws a :class:`console.core.run_state.RunView` (from the loop's published
view): the approach circles through the plan's palm points around the object it was made for,
numbered palm points, the ghost arm of the waypoint the arm goes to now (bold, with its palm
point marked) and one label at the object ("Arm: Object 2 (object 2 of 3) · waypoint 3 of 9").
It hides everything when the arm runs no task. Drawn by the grasp layers on the grasp
session's worker thread (the only thread drawing them), next to the operator's own plan, which
is then drawn dimmed (:meth:`console.scene.plan_view.PlanScene.draw_plan` ``dim``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from console.core.run_state import RunView
from console.scene.plan_geometry import LABEL_GAP, Z_PLAN, circle_segments, ghost_segments

RUN_CIRCLE_COLOR = (40, 170, 70)
RUN_GHOST_COLOR = (245, 120, 20)
RUN_PALM_COLOR = (200, 40, 60)
Z_RUN = Z_PLAN + 0.004  # over the operator's (dimmed) plan


def run_circle_radii(run: RunView) -> Any:
    """Each waypoint's approach circle: its palm point's distance from the object's centre."""
    p = run.plan
    assert p is not None
    return np.hypot(p.palms[:, 0] - p.center[0], p.palms[:, 1] - p.center[1])


def run_label(run: RunView) -> str:
    """The label at the object: whose plan the arm runs and where it is in it."""
    what = run.object_text()
    return f"Arm: {what + ' · ' if what else ''}{run.waypoint_text()}"


class RunScene:
    """Scene nodes of the plan the arm executes (see the module docstring)."""

    def __init__(self, server: Any, robot: Any) -> None:
        self.server, self.robot = server, robot
        scene = server.scene
        empty = np.zeros((1, 2, 3))
        self.circles = scene.add_line_segments("/grasp/run/circles", empty, RUN_CIRCLE_COLOR,
                                               thickness=0.003, visible=False)
        self.ghost = scene.add_line_segments("/grasp/run/ghost", empty, RUN_GHOST_COLOR,
                                             thickness=0.009, visible=False)
        self.palms = scene.add_point_cloud("/grasp/run/palms", np.zeros((1, 3)),
                                           RUN_PALM_COLOR, point_size=0.012,
                                           point_shape="circle", visible=False)
        self.palm_now = scene.add_icosphere("/grasp/run/palm_now", radius=0.01,
                                            color=RUN_GHOST_COLOR, visible=False,
                                            cast_shadow=False)
        self.label = scene.add_label("/grasp/run/label", "", position=(0.0, 0.0, Z_RUN),
                                     visible=False)
        self.numbers: list[Any] = []
        self.shown: RunView | None = None  # what is drawn (None: nothing)

    def draw(self, run: RunView | None) -> None:
        """Show ``run`` (None, or a run without a plan yet, hides the plan; the label stays
        while a task runs)."""
        plan = None if run is None else run.plan
        if plan is None:
            for h in (self.circles, self.ghost, self.palms, self.palm_now, *self.numbers):
                h.visible = False
            self.label.visible = False
            self.shown = run
            return
        c = np.asarray(plan.center, float)
        self.circles.points = circle_segments(c, run_circle_radii(run), Z_RUN)
        palms = np.c_[plan.palms[:, :2], np.full(plan.n, Z_RUN)]
        self.palms.points = palms
        self.circles.visible = self.palms.visible = True
        k = run.waypoint if run.waypoint is not None else plan.n - 1
        self.ghost.points = ghost_segments(self.robot, plan.kappas[k:k + 1], Z_RUN)[0]
        self.ghost.visible = True
        self.palm_now.position = tuple(palms[k])
        self.palm_now.visible = run.waypoint is not None
        self._draw_numbers(palms, c)
        self.label.text = run_label(run)
        self.label.position = (float(c[0]), float(c[1]) - 0.05, Z_RUN)
        self.label.visible = True
        self.shown = run  # last: a reader that sees it sees it drawn

    def _draw_numbers(self, palms: Any, center: Any) -> None:
        """Each palm point's number just outside it (away from the object)."""
        scene = self.server.scene
        for i, p in enumerate(palms):
            out = p[:2] - center
            n = np.linalg.norm(out)
            out = out / n if n > 1e-9 else np.array([0.0, 1.0])
            pos = (float(p[0] + LABEL_GAP * out[0]), float(p[1] + LABEL_GAP * out[1]), Z_RUN)
            if i == len(self.numbers):
                self.numbers.append(scene.add_label(f"/grasp/run/numbers/{i}", f"{i + 1}",
                                                    position=pos, anchor="center-center"))
                continue
            h = self.numbers[i]
            h.position = pos
            h.visible = True
        for h in self.numbers[len(palms):]:
            h.visible = False
