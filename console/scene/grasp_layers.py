"""The grasp layers of the 3D view, so the headless grasp session is drawn: they render what the
session tells them changed, and turn a browser's gizmo drag into a plain session call.

:class:`GraspSceneView` subscribes to a :class:`console.core.grasp_session.GraspSession` (first,
so every other listener sees a scene already drawn) and, on the session's worker thread (the
only thread that draws into these layers), redraws from the parts that changed
(:mod:`console.core.grasp_state`): the bin (:class:`console.scene.bin_view.BinView`), the
objects with their drag gizmos and the plan with its inspected waypoint and the reachability
shading (:class:`console.scene.plan_view.PlanScene`), the obstacles
(:class:`console.scene.obstacle_view.ObstacleLayer`) and a final plan's carry to the bin
(:class:`console.scene.carry_view.CarryLayer`), all in one ``server.atomic()`` change. While
the arm runs a task the plan it executes is drawn by :class:`console.scene.run_view.RunScene`
(from the loop's view, at once on the Control panel's display thread: the session's run
listener) and the operator's own plan, when it is another, dimmed (part ``run``, worker).

A gizmo event goes to :attr:`GraspSceneView.gizmo_handler` (the Objects panel's operator-only
handler, which calls ``session.drag(name, x, y, live=...)``); without one a browser's drag is
put back (the session redraws the objects where it has them).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import viser

from console.core.grasp_session import GraspSession
from console.core.grasp_state import SessionView
from console.core.run_state import RunView
from console.scene.bin_view import BinView
from console.scene.carry_view import CarryLayer
from console.scene.obstacle_view import ObstacleLayer
from console.scene.plan_view import PlanScene
from console.scene.run_view import RunScene
from core.planning.reachability import ReachMap
from core.robots import SoftArm

log = logging.getLogger(__name__)

GizmoHandler = Callable[[str, viser.TransformControlsEvent], None]


class GraspSceneView:
    """The grasp session's 3D layers (see the module docstring).

    Args:
        server: The viser server to draw into.
        robot: The soft arm (ghost arms, capture region, carry).
        session: The session to render; the view subscribes to it at once.
    """

    def __init__(self, server: viser.ViserServer, robot: SoftArm,
                 session: GraspSession) -> None:
        self.server = server
        self.session = session
        self.plan_scene = PlanScene(server, robot)
        self.carry_layer = CarryLayer(server, robot)  # a final plan's carry to the bin
        self.bin_view = BinView(server.scene, robot)
        self.obstacle_layer = ObstacleLayer(server)
        self.run_scene = RunScene(server, robot)  # the plan the arm executes (the loop's)
        self.gizmo_handler: GizmoHandler | None = None
        session.add_listener(self.on_change)
        session.add_run_listener(self.on_run)  # the only thread drawing the run layer

    def on_change(self, view: SessionView, changed: frozenset[str]) -> None:
        """The session's worker: redraw the layers whose parts changed."""
        try:
            with self.server.atomic():
                self._draw(view, changed)
        except Exception:  # a drawing error must not stop the panels from being told
            log.exception("grasp scene update failed")

    def _draw(self, view: SessionView, changed: frozenset[str]) -> None:
        if "bin" in changed:
            self.bin_view.draw(view.bin)
        if "objects" in changed:
            self.plan_scene.sync_objects(list(view.objects), view.selected, self.on_gizmo)
        if "obstacles" in changed:
            self.obstacle_layer.sync(view.obstacles, view.obstacle_selected, view.clearance)
        if changed & {"plan", "inspect", "run"}:
            plan = view.outcome.plan if view.outcome else None
            run = view.run
            if run is not None and run.plan is not None and not view.running_other_plan():
                plan = None  # the arm runs this very plan: drawn once, by the run layer
            self.plan_scene.draw_plan(plan, view.index, view.trail, view.trail_from,
                                      dim=run is not None)
            if changed & {"plan", "run"}:
                self.carry_layer.draw(plan if run is None else None)
        if "reach" in changed and isinstance(view.reach, ReachMap):
            self.plan_scene.draw_reach(view.reach, view.show_reach, self.session.table_extent)

    def on_run(self, run: RunView | None) -> None:
        """What the arm runs changed (the Control panel's display thread): draw it at once."""
        try:
            with self.server.atomic():
                self.run_scene.draw(run)
        except Exception:
            log.exception("run layer update failed")

    def on_gizmo(self, name: str, event: viser.TransformControlsEvent) -> None:
        """An object's gizmo moved: :attr:`gizmo_handler` acts on it; without one, a browser's
        drag is put back."""
        handler = self.gizmo_handler
        if handler is not None:
            handler(name, event)
        elif event.client is not None:
            self.session.redraw_objects()
