"""Paths panel: what a path looks like in the 3D scene, so the panel itself only plans and runs.

The requested tip path (drawn at once on Preview: its waypoints and the line through them), the
planned tip trace with a few translucent ghost arms along the motion, and the measured tip trace
of the run (its last ``TRAIL_S`` seconds, :func:`trail_tail`). The View panel's legend names
these colours and its "Clear trails" hides the measured trace (:meth:`PathScene.clear_trails`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import viser

from console.core.model import ArmModel
from console.scene.arm_view import ArmView
from core.planning.paths import MotionPath

Array = npt.NDArray[np.float64]
N_GHOSTS = 5
TRACE_COLOR = (150, 60, 200)
WAYPOINT_COLOR = (150, 60, 200)
MEASURED_COLOR = (235, 130, 30)
GHOST_COLOR = (90, 140, 220)


def trail_tail(times: Array, points: Array, seconds: float) -> Array:
    """The points of a trace sampled no more than ``seconds`` before its newest sample."""
    if len(times) == 0:
        return points[:0]
    return points[np.asarray(times) >= times[-1] - seconds]


class PathScene:
    """The Paths panel's scene nodes: requested / planned trace, waypoints, ghosts, measured.

    Args:
        scene: The console's viser scene (``app.server.scene``).
    """

    def __init__(self, scene: viser.SceneApi) -> None:
        self.scene = scene
        self.trace = scene.add_line_segments("/path/trace", np.zeros((1, 2, 3)), TRACE_COLOR,
                                             thickness=5.0, thickness_units="screen", visible=False)
        self.measured = scene.add_line_segments("/path/measured", np.zeros((1, 2, 3)),
                                                MEASURED_COLOR, thickness=3.0,
                                                thickness_units="screen", visible=False)
        self.waypoints = scene.add_point_cloud("/path/waypoints", np.zeros((1, 3)), WAYPOINT_COLOR,
                                               point_size=0.014, point_shape="circle",
                                               precision="float32", visible=False)
        self.ghosts: list[viser.MeshHandle] = []

    def draw_requested(self, waypoints: Array) -> None:
        """At once on Preview: the requested tip path (the plan replaces it), no ghost arms."""
        w = np.asarray(waypoints, dtype=float)
        self.waypoints.points = w.astype(np.float32)
        self.waypoints.visible = True
        self.trace.points = np.stack([w[:-1], w[1:]], axis=1) if len(w) > 1 \
            else np.stack([w, w], axis=1)
        self.trace.visible = True
        self.measured.visible = False
        for ghost in self.ghosts:
            ghost.visible = False

    def draw_preview(self, path: MotionPath, waypoints: Array,
                     view: ArmView[ArmModel]) -> None:
        """The planned tip trace and ghost arms along it, drawn by the arm's ``view``."""
        self.waypoints.points = np.asarray(waypoints, dtype=np.float32)
        self.waypoints.visible = True
        tips = path.tips
        self.trace.points = np.stack([tips[:-1], tips[1:]], axis=1) if len(tips) > 1 \
            else np.stack([tips, tips], axis=1)
        self.trace.visible = True
        self.measured.visible = False
        picks = np.linspace(0, len(path.times) - 1, N_GHOSTS).round().astype(int)
        for i, k in enumerate(picks):
            verts, faces = view.ghost_mesh(path.deltas[k])
            if i < len(self.ghosts):
                self.ghosts[i].vertices = verts
                self.ghosts[i].visible = True
            else:
                self.ghosts.append(self.scene.add_mesh_simple(
                    f"/path/ghost_{i}", verts, faces, color=GHOST_COLOR, opacity=0.22,
                    cast_shadow=False, receive_shadow=False))

    def draw_measured(self, points: Array) -> None:
        """The measured tip trace (at least two points)."""
        self.measured.points = np.stack([points[:-1], points[1:]], axis=1)
        self.measured.visible = True

    def clear_trails(self) -> None:
        """Hide the measured tip trace of the last run (the View panel's "Clear trails")."""
        self.measured.visible = False
