"""The grasp session: the table objects, planner settings, newest plan and waypoint inspection that
the Objects, Grasp planner and Waypoints panels share (one per console, ``session_for(app)``).

The table also holds obstacles (``core.planning.obstacles.Obstacle``): every plan keeps the arm
and gripper ``clearance`` (m) from them (drawn by :class:`console.scene.obstacle_view.ObstacleLayer`).

Callbacks only call :class:`GraspSession` methods, which take a lock, record the request and
wake one worker thread. The worker plans the newest request with
:class:`core.planning.sides.SidedPlanner` (while an object is dragged at most ``LIVE_HZ`` plans a
second, on the newest position only; a final plan with obstacles and a bin also gets its carry
to the bin, :mod:`console.scene.carry_view`; from 0.5 s on the panels show "Planning… (n s)",
:mod:`console.core.planning_clock`), steps waypoint playback, redraws the grasp layer
(:class:`console.scene.plan_view.PlanScene`, of which it is the only writer) and then tells the panels,
which refresh their widgets. Who may change it is decided by the panels (operator-only
callbacks); the session itself trusts its callers.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import viser

from console.core.grasp_obstacles import DEFAULT_CLEARANCE, ObstacleEdits
from console.core.grasp_inspection import WaypointInspection
from console.recording.lab_feed import feed_grasp
from console.scene.carry_view import CarryLayer, plan_carry
from console.scene.obstacle_view import ObstacleLayer
from console.scene.plan_view import LIVE_HZ, Outcome, PlanScene, SessionView
from console.core.planning_clock import PlanningClock
from console.core.reach_job import (REACH_STEP, SHIPPED_CACHE, ReachCache, ReachOutcome, ReachRequest,
                               start_reach_map)
from console.core.table_bin import BinView, TableBin
from console.core.table_scene import TableObject, disk_overlap, validate_object
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import Obstacle
from core.planning.reachability import ReachMap
from core.planning.sides import SidedPlanner

if TYPE_CHECKING:
    from console.core.state import StateStore

log = logging.getLogger(__name__)


class GraspHost(Protocol):
    """What the grasp session uses of the console (the app satisfies it)."""

    robot: Any
    server: viser.ViserServer
    store: StateStore
    recorder: Any  # console.recording.recorder.Recorder
    grasp_session: GraspSession | None


class GraspSession(ObstacleEdits, WaypointInspection):
    """Shared grasp state of one console; see the module docstring for the threading rules."""

    compute_reach = True    # tests switch the (CPU-heavy) reachability map off
    reach_step = REACH_STEP  # cell size of the map (tests use a coarse one)

    def __init__(self, app) -> None:
        self.app = app
        robot = app.robot
        self.robot = robot
        self.planner = SidedPlanner(robot)  # the side the object lies on (core.planning.sides)
        self.scene = PlanScene(app.server, robot)
        self.carry_layer = CarryLayer(app.server, robot)  # a final plan's carry to the bin
        self.bin_view = BinView(app.server.scene)
        self._bin: TableBin | None = None  # where "Clear table into bin" takes the objects
        self.obstacle_layer = ObstacleLayer(app.server)
        self.default_radius = robot.capture.nominal_object_radius
        self._cond = threading.Condition()
        self._objects = [TableObject("Object 1", -0.20, 0.20, self.default_radius)]
        self._selected: str | None = "Object 1"
        self._count = 1
        self._obstacles: list[Obstacle] = []
        self._obstacle_selected: str | None = None
        self._obstacle_count = 0
        self.clearance = DEFAULT_CLEARANCE
        self.delta_d = float(robot.delta_d)
        self.weights = tuple(self.planner.config.weights)
        self.live = True
        self.show_reach = True
        self._request: bool | None = False      # pending plan: True = live, False = final
        self._outcome: Outcome | None = None
        self._index, self._playing, self._speed, self._trail = 0, False, 2.0, True
        self._trail_from = 0    # "Clear trails": no trail before this waypoint (until re-planned)
        self._dirty = {"objects", "obstacles", "reach"}
        self._reach: ReachMap | str | None = "computing"
        self._reach_note = ""
        self.table_extent = _table_extent(app)
        self._listeners: list[Callable[[SessionView], None]] = []
        self._stop = False
        self._next_tick = 0.0
        self.gizmo_handler: Callable[[str, viser.TransformControlsEvent], None] | None = None
        if not self.compute_reach:
            self._reach = "off"
        self.clock = PlanningClock(self._tell_planning)  # "Planning… (n s)" from 0.5 s on
        self._thread = threading.Thread(target=self._run, name="grasp-session", daemon=True)
        self._thread.start()
        if self.compute_reach:
            self._start_reach()

    # -- thread-safe requests (GUI callbacks) ------------------------------------------------
    def view(self) -> SessionView:
        with self._cond:
            return SessionView(tuple(self._objects), self._selected, self._outcome, self._index,
                               self._playing, self._speed, self._trail, self._reach,
                               self._reach_note, self._trail_from, self._bin,
                               tuple(self._obstacles), self._obstacle_selected,
                               self.clearance)

    def add_listener(self, fn: Callable[[SessionView], None]) -> None:
        with self._cond:
            self._listeners.append(fn)

    def _changed(self, *parts: str, plan: bool | None = None) -> None:
        """Mark parts dirty and optionally request a plan (True = live); caller holds the lock."""
        self._dirty.update(parts)
        if plan is not None and (self._request is None or self._request):
            self._request = plan
        self._cond.notify_all()

    def place(self, x: float, y: float, r: float | None = None) -> str:
        """Select the object under (x, y), or add a new one there (ValueError for a bad one, or
        one that would overlap an obstacle: nothing changes then); returns its name."""
        with self._cond:
            for o in self._objects:
                if np.hypot(o.x - x, o.y - y) <= o.r + 0.005:
                    self._selected = o.name
                    self._changed("objects", plan=False)
                    return o.name
            while f"Object {self._count}" in {o.name for o in self._objects}:
                self._count += 1
            obj = validate_object(TableObject(f"Object {self._count}", float(x), float(y),
                                              float(r or self.default_radius)), self.robot)
            why = disk_overlap(obj.name, obj.x, obj.y, obj.r, self._obstacles)
            if why is not None:  # hidden inside the obstacle; the planner would refuse it
                raise ValueError(why)
            self._objects.append(obj)
            self._selected = obj.name
            self._changed("objects", plan=False)
            return obj.name

    def update(self, name: str, *, x: float | None = None, y: float | None = None,
               r: float | None = None, live: bool = False) -> None:
        """Change an object (ValueError for bad values or an overlap with an obstacle: nothing
        changes then; a dragged object stops at an obstacle)."""
        with self._cond:
            i = self._find(name)
            old = self._objects[i]
            new = validate_object(dataclasses.replace(
                old, x=old.x if x is None else float(x), y=old.y if y is None else float(y),
                r=old.r if r is None else float(r)), self.robot)
            why = disk_overlap(name, new.x, new.y, new.r, self._obstacles)
            if why is not None:
                raise ValueError(why.replace("Not placed", "Not moved", 1))
            self._objects[i] = new
            replan = (not live or self.live) and name == self._selected
            self._changed("objects", plan=live if replan else None)

    def remove(self, name: str) -> None:
        with self._cond:
            self._objects.pop(self._find(name))
            if self._selected == name:
                self._selected = self._objects[-1].name if self._objects else None
            self._changed("objects", plan=False)

    def select(self, name: str | None) -> None:
        with self._cond:
            if name is not None:
                self._find(name)
            self._selected = name
            self._changed("objects", plan=False)

    def set_objects(self, objects: list[TableObject]) -> None:
        with self._cond:
            self._objects = list(objects)
            self._selected = objects[0].name if objects else None
            self._changed("objects", plan=False)

    def set_bin(self, table_bin: TableBin | None) -> None:
        """Place the bin (``console.core.table_bin.locate_bin`` found its pose) or take it away."""
        with self._cond:
            self._bin = table_bin
            self._changed("objects", "bin")

    def request_plan(self) -> None:
        with self._cond:
            self._request = False
            self._cond.notify_all()

    def configure(self, *, delta_d: float | None = None, weights: tuple | None = None,
                  live: bool | None = None, show_reach: bool | None = None) -> None:
        with self._cond:
            if delta_d is not None:
                self.delta_d = float(delta_d)
            if weights is not None:
                self.weights = tuple(float(w) for w in weights)
            if live is not None:
                self.live = bool(live)
            if show_reach is not None:
                self.show_reach = bool(show_reach)
                self._changed("reach")

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self.clock.close()

    def _find(self, name: str) -> int:
        for i, o in enumerate(self._objects):
            if o.name == name:
                return i
        raise ValueError(f"no object named {name!r}")

    def _n(self) -> int:
        plan = self._outcome.plan if self._outcome else None
        return 0 if plan is None else plan.n

    def _start_reach(self) -> None:
        """Ask for the map over the table (cache, else a child process with progress)."""
        x0, x1, y0, y1 = self.table_extent
        request = ReachRequest(self.robot.source, self.default_radius, (x0, x1), (y0, y1),
                               self.reach_step)
        data_root = getattr(self.app, "data_root", None)
        folders = ([Path(data_root) / "cache"] if data_root is not None else []) + [
            SHIPPED_CACHE]
        start_reach_map(request, ReachCache(*folders), self._on_reach, self._on_reach_progress)

    def _on_reach_progress(self, fraction: float) -> None:
        with self._cond:
            if not isinstance(self._reach, ReachMap):
                self._reach = f"{100 * fraction:.0f} %"
                self._changed("reach")

    def _on_reach(self, result: ReachOutcome) -> None:
        if result.reach is not None:
            log.info("reachability map %s", result.note())
        else:
            log.warning("reachability map %s", result.note())
        with self._cond:
            self._reach = result.reach if result.reach is not None else result.note()
            self._reach_note = result.note()
            self._changed("reach")

    def on_gizmo(self, name: str, event: viser.TransformControlsEvent) -> None:
        """An object's gizmo moved: the Objects panel's operator-only ``gizmo_handler`` acts on
        it; without one, a browser's drag is put back."""
        handler = self.gizmo_handler
        if handler is not None:
            handler(name, event)
        elif event.client is not None:
            self.redraw_objects()

    def drag(self, name: str, x: float, y: float, *, live: bool) -> None:
        """``name`` dragged to (x, y): selected, re-planned live while dragging and finally on
        release; a position the object may not have snaps back."""
        with self._cond:
            if name != self._selected:
                self._selected = name
        try:
            self.update(name, x=x, y=y, live=live)
        except ValueError:
            self.redraw_objects()

    def redraw_objects(self) -> None:
        """Redraw the objects where the session has them (undoes a refused gizmo drag)."""
        with self._cond:
            self._changed("objects")

    # -- worker ------------------------------------------------------------------------------
    def _run(self) -> None:
        last_live = 0.0
        while True:
            with self._cond:
                while True:
                    if self._stop:
                        return
                    now = time.perf_counter()
                    tick = self._playing and now >= self._next_tick
                    wait_live = (self._request is True and now - last_live < 1.0 / LIVE_HZ)
                    if (self._request is not None and not wait_live) or self._dirty or tick:
                        break
                    timeout = 0.5
                    if self._playing:
                        timeout = min(timeout, self._next_tick - now)
                    if wait_live:
                        timeout = min(timeout, last_live + 1.0 / LIVE_HZ - now)
                    self._cond.wait(max(timeout, 0.0))
                request = None if wait_live else self._request
                if request is not None:
                    self._request = None
                dirty, self._dirty = self._dirty, set()
                if tick:
                    last = max(self._n() - 1, 0)
                    self._index = min(self._index + 1, last)
                    self._next_tick = now + 1.0 / self._speed
                    self._playing = self._index < last
                    dirty.add("inspect")
                objects, selected = list(self._objects), self._selected
                settings = (self.delta_d, self.weights, tuple(self._obstacles), self.clearance,
                            None if request else self._bin)  # live plans skip the carry
            if request is not None:
                if dirty:   # what changed on the table is drawn before the plan for it runs
                    self._draw(dirty)
                    dirty = set()
                if request:
                    last_live = time.perf_counter()
                self.clock.start()
                try:
                    outcome = self._plan(objects, selected, settings)
                finally:
                    self.clock.stop()
                with self._cond:
                    self._outcome = outcome
                    n = self._n()
                    self._index = min(self._index, max(n - 1, 0)) if request else 0
                    self._trail_from = min(self._trail_from, self._index)
                    if not request:
                        self._playing = False
                dirty.add("plan")
            self._draw(dirty)

    def _plan(self, objects, selected, settings) -> Outcome:
        seq = (self._outcome.seq + 1) if self._outcome else 1
        obj = next((o for o in objects if o.name == selected), None)
        if obj is None:
            return Outcome(None, None, "No object selected: click on the table to place one.",
                           seq)
        kappa = np.asarray(self.app.store.display.q, dtype=float)
        try:
            plan = self.planner.plan(kappa, (obj.x, obj.y), obj.r, delta_d=settings[0],
                                     weights=settings[1], obstacles=settings[2],
                                     clearance=settings[3])
            plan, note = plan_carry(self.robot, plan, obj, settings[4], settings[2],
                                    settings[3])
        except GraspRefused as exc:
            return Outcome(obj, None, str(exc), seq)
        except Exception as exc:  # a planner bug must not kill the worker
            log.exception("grasp planning failed")
            return Outcome(obj, None, f"The planner failed unexpectedly ({exc}).", seq)
        return Outcome(obj, plan, None, seq, note)

    def _tell_planning(self, seconds: float) -> None:
        """The planning clock's thread: the panels show that a plan has run ``seconds``."""
        view = dataclasses.replace(self.view(), planning_s=seconds)
        with self._cond:
            listeners = list(self._listeners)
        for fn in listeners:
            fn(view)

    def _draw(self, dirty: set[str]) -> None:
        view = self.view()
        try:
            with self.app.server.atomic():
                if "bin" in dirty:
                    self.bin_view.draw(view.bin)
                if "objects" in dirty:
                    self.scene.sync_objects(list(view.objects), view.selected, self.on_gizmo)
                if "obstacles" in dirty:
                    self.obstacle_layer.sync(view.obstacles, view.obstacle_selected,
                                             view.clearance)
                if dirty & {"plan", "inspect"}:
                    plan = view.outcome.plan if view.outcome else None
                    self.scene.draw_plan(plan, view.index, view.trail, view.trail_from)
                    if "plan" in dirty:
                        self.carry_layer.draw(plan)
                if "reach" in dirty and isinstance(view.reach, ReachMap):
                    self.scene.draw_reach(view.reach, self.show_reach, self.table_extent)
        except Exception:  # a drawing error must not kill the worker
            log.exception("grasp scene update failed")
        with self._cond:
            listeners = list(self._listeners)
        for fn in listeners:
            try:
                fn(view)
            except Exception:
                log.exception("grasp panel refresh failed")
        # objects and plans into recordings and the live bridge
        feed_grasp(self.app.recorder, view, dirty)


def _table_extent(app) -> tuple[float, float, float, float]:
    """The table rectangle (x0, x1, y0, y1) the console draws (``ConsoleApp._table_extent``),
    which the reachability map covers and its shading is clipped to."""
    extent = getattr(app, "_table_extent", None)
    if callable(extent):
        return tuple(float(v) for v in extent())  # type: ignore[return-value]
    return (-0.5, 0.5, -0.26, 0.5)


def session_for(app: GraspHost) -> GraspSession:
    """The app's grasp session (``app.grasp_session``), created by the first grasp panel that
    asks for it: it belongs to the console's GUI (scene, store), so it is not a service."""
    if app.grasp_session is None:
        app.grasp_session = GraspSession(app)
    return app.grasp_session
