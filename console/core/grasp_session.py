"""The grasp session: the table (objects, obstacles, bin), the planner settings, the newest plan and
its waypoint inspection, kept headless so the console's core owns them and views only render them.

One per soft-arm console (``ConsoleApp.grasp_session``, made with the console whatever panels it
has); it knows no viser and no app: it is built from the robot, the table rectangle
(:func:`console.core.table_area.table_extent`), where the arm is now (``kappa``, for the start
of a plan), an optional ``feed`` (recordings: :func:`console.recording.lab_feed.feed_grasp`) and
a clock. Plans keep the arm and gripper ``clearance`` (m) from the obstacles
(``core.planning.obstacles.Obstacle``) and from every other object on the table (an obstacle
of its radius: :meth:`console.core.grasp_state.SessionView.plan_obstacles`).

Threading: callers (GUI callbacks, tests) only call :class:`GraspSession` methods, which take a
lock, record the request and wake one worker thread (started by :meth:`GraspSession.start`). The
worker plans the newest request with :class:`core.planning.sides.SidedPlanner` (while an object
is dragged at most ``LIVE_HZ`` plans a second, on the newest position only; a final plan with
obstacles and a bin also gets its carry to the bin, :mod:`console.core.grasp_carry`; from 0.5 s
on listeners are told "planning for n s", :mod:`console.core.planning_clock`), steps waypoint
playback, and then tells every listener (:meth:`GraspSession.add_listener`) the new snapshot and
which parts changed (:mod:`console.core.grasp_state`): the 3D layers
(:class:`console.scene.grasp_layers.GraspSceneView`, subscribed first) redraw, the panels
refresh their widgets, then ``feed`` records. Who may change it is decided by the panels
(operator-only callbacks); the session itself trusts its callers.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from console.core.grasp_carry import plan_carry
from console.core.grasp_inspection import WaypointInspection
from console.core.grasp_obstacles import DEFAULT_CLEARANCE, ObstacleEdits
from console.core.run_state import RunView
from console.core.grasp_state import LIVE_HZ, PARTS, GraspListener, Outcome, SessionView
from console.core.planning_clock import PlanningClock
from console.core.reach_job import (REACH_STEP, SHIPPED_CACHE, ReachCache, ReachOutcome,
                                    ReachRequest, start_reach_map)
from console.core.table_area import Extent
from console.core.table_bin import TableBin
from console.core.table_scene import TableObject, disk_overlap, validate_object
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import Obstacle, with_other_objects
from core.planning.reachability import ReachMap
from core.planning.sides import SidedPlanner
from core.robots import SoftArm

log = logging.getLogger(__name__)

PLANNING = frozenset({"planning"})  # what a planning-clock report changes

GraspFeed = Callable[[SessionView, frozenset[str]], None]


class GraspSession(ObstacleEdits, WaypointInspection):
    """Shared grasp state of one soft-arm console; see the module docstring for the threads.

    Args:
        robot: The soft arm.
        table_extent: The table rectangle (x0, x1, y0, y1), m: the reachability map covers it.
        kappa: Where the arm is now (its curvatures): the start of every plan.
        feed: Called after the listeners with the snapshot and the parts that changed (the
            recorder's :func:`console.recording.lab_feed.feed_grasp`); None records nothing.
        cache_dirs: Folders for reachability maps, searched before the shipped cache (the first
            is where a computed map is saved).
        clock: Monotonic seconds, for live re-plan pacing and waypoint playback.
        compute_reach: Whether to get the reachability map (None: :attr:`compute_reach`).
    """

    compute_reach = True    # tests switch the (CPU-heavy) reachability map off
    reach_step = REACH_STEP  # cell size of the map (tests use a coarse one)

    def __init__(self, robot: SoftArm, table_extent: Extent, *,
                 kappa: Callable[[], npt.ArrayLike],
                 feed: GraspFeed | None = None, cache_dirs: Sequence[Path | str] = (),
                 clock: Callable[[], float] = time.perf_counter,
                 compute_reach: bool | None = None) -> None:
        self.robot = robot
        self.planner = SidedPlanner(robot)  # the side the object lies on (core.planning.sides)
        x0, x1, y0, y1 = (float(v) for v in table_extent)
        self.table_extent: Extent = (x0, x1, y0, y1)
        self._kappa = kappa
        self._feed = feed
        self._cache_dirs = tuple(Path(d) for d in cache_dirs)
        self._clock = clock
        self._with_reach = self.compute_reach if compute_reach is None else bool(compute_reach)
        self.default_radius = robot.capture.nominal_object_radius
        self._cond = threading.Condition()
        self._bin: TableBin | None = None  # where "Clear table into bin" takes the objects
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
        self._reach: ReachMap | str | None = "computing" if self._with_reach else "off"
        self._reach_note = ""
        self._listeners: list[GraspListener] = []
        self._welcome: list[GraspListener] = []  # added since the worker last ran
        self._stop = False
        self._next_tick = 0.0
        self.planning_clock: PlanningClock | None = None   # "planning for n s" from 0.5 s on
        self._thread: threading.Thread | None = None
        self._run_view: RunView | None = None  # what the arm runs (the loop's view)
        self._run_listeners: list[Callable[[RunView | None], None]] = []
        # Held while a listener (run listener) is called: its remover waits for the call in
        # progress, so a closed panel is never written to after it removed itself. Re-entrant:
        # a listener may remove itself (or another) from inside its call.
        self._calling = threading.RLock()
        self._calling_run = threading.RLock()

    def start(self) -> GraspSession:
        """Start the worker (it plans the first object at once) and ask for the reachability
        map; subscribe the views first so they are told from the first change on."""
        with self._cond:
            if self._thread is not None:
                return self
            self.planning_clock = PlanningClock(self._tell_planning)
            self._thread = threading.Thread(target=self._run, name="grasp-session", daemon=True)
        self._thread.start()
        if self._with_reach:
            self._start_reach()
        return self

    # -- thread-safe requests (GUI callbacks) ------------------------------------------------
    def view(self) -> SessionView:
        with self._cond:
            return SessionView(tuple(self._objects), self._selected, self._outcome, self._index,
                               self._playing, self._speed, self._trail, self._reach,
                               self._reach_note, self._trail_from, self._bin,
                               tuple(self._obstacles), self._obstacle_selected,
                               self.clearance, show_reach=self.show_reach,
                               run=self._run_view)

    def add_listener(self, fn: GraspListener) -> Callable[[], None]:
        """Call ``fn(view, changed)`` on the worker thread after every change (the snapshot
        and the parts that changed, :mod:`console.core.grasp_state`), in the order added. A
        listener added after the session started is first told everything (``PARTS``) once, so
        it never waits for the next change to show the table. Returns what removes it (a
        closed panel's: its widgets are gone)."""
        with self._cond:
            self._listeners.append(fn)
            self._welcome.append(fn)
            self._cond.notify_all()

        def remove() -> None:
            with self._cond:
                for registry in (self._listeners, self._welcome):
                    if fn in registry:
                        registry.remove(fn)
            self._wait_for_call(self._calling, fn)
        return remove

    @staticmethod
    def _wait_for_call(calling: Any, fn: Any, timeout_s: float = 5.0) -> None:
        """Wait (at most ``timeout_s``) for a listener call in progress on another thread to
        end: after a remover returns, ``fn`` is not running and will not be called again."""
        if calling.acquire(timeout=timeout_s):
            calling.release()
        else:
            log.warning("listener %r removed while its call has run for over %.0f s", fn,
                        timeout_s)

    def _call(self, calling: Any, registry: list[Any], fn: Any, *args: Any) -> None:
        """Call ``fn(*args)`` holding ``calling``, unless it was removed from ``registry``
        since the caller copied the list; an error is logged, the others are still told."""
        with calling:
            with self._cond:
                if fn not in registry:
                    return
            try:
                fn(*args)
            except Exception:  # a view's error must not kill the worker
                log.exception("grasp session listener %r failed", fn)

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
            self._count += 1  # a removed (or cleared) object's name is not given again
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
            # the selected object is re-planned (live while dragged); another one is one of its
            # obstacles, so its plan is re-made once it is put down
            replan = (not live or self.live) if name == self._selected else not live
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

    def set_run(self, run: RunView | None) -> None:
        """What the arm runs now, from the loop's published view
        (:func:`console.core.run_state.run_of`); run listeners at once and listeners (part
        ``run``) are told when its plan, waypoint or object changed or it began or ended, not
        for its times alone."""
        with self._cond:
            old = self._run_view
            self._run_view = run
            changed = (old is None) != (run is None) or (
                run is not None and old is not None and old.key() != run.key())
            if changed:
                self._changed("run")
            listeners = list(self._run_listeners) if changed else []
        for fn in listeners:  # at once, on the caller's thread: never behind a running plan
            self._call(self._calling_run, self._run_listeners, fn, run)

    def add_run_listener(self, fn: Callable[[RunView | None], None]) -> Callable[[], None]:
        """Call ``fn(run)`` on :meth:`set_run`'s thread (the Control panel's display thread,
        one thread) whenever what the arm runs changed, so the plan being run is drawn at once
        even while the worker plans the operator's next one (the ``run`` part follows when it
        is free). Returns what removes it."""
        with self._cond:
            self._run_listeners.append(fn)

        def remove() -> None:
            with self._cond:
                if fn in self._run_listeners:
                    self._run_listeners.remove(fn)
            self._wait_for_call(self._calling_run, fn)
        return remove

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
        """End the worker (it tells nobody anything after its current step); idempotent."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
            planning = self.planning_clock
        if planning is not None:
            planning.close()

    def join(self, timeout: float | None = None) -> None:
        """Wait for the worker to end after :meth:`close` (no drawing after this)."""
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)

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
        folders = [*self._cache_dirs, SHIPPED_CACHE]
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

    def drag(self, name: str, x: float, y: float, *, live: bool) -> None:
        """``name`` dragged to (x, y): selected, re-planned live while dragging and finally on
        release; a position the object may not have snaps back (views are told ``objects``)."""
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
        planning = self.planning_clock
        assert planning is not None  # made by start() before this thread
        last_live = -float("inf")
        while True:
            with self._cond:
                while True:
                    if self._stop:
                        return
                    now = self._clock()
                    tick = self._playing and now >= self._next_tick
                    wait_live = (self._request is True and now - last_live < 1.0 / LIVE_HZ)
                    if ((self._request is not None and not wait_live) or self._dirty or tick
                            or self._welcome):
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
                welcome, self._welcome = self._welcome, []
                if tick:
                    last = max(self._n() - 1, 0)
                    self._index = min(self._index + 1, last)
                    self._next_tick = now + 1.0 / self._speed
                    self._playing = self._index < last
                    dirty.add("inspect")
                objects, selected = list(self._objects), self._selected
                settings = (self.delta_d, self.weights, tuple(self._obstacles), self.clearance,
                            None if request else self._bin)  # live plans skip the carry
            self._greet(welcome)
            if request is not None:
                if dirty:   # what changed on the table is drawn before the plan for it runs
                    self._publish(dirty)
                    dirty = set()
                if request:
                    last_live = self._clock()
                planning.start()
                try:
                    # an empty table (a row cleared it, the last object removed) is nothing to
                    # refuse: the summary goes back to "Place an object and press Plan grasp."
                    outcome = self._plan(objects, selected, settings) if objects else None
                finally:
                    planning.stop()
                with self._cond:
                    self._outcome = outcome
                    n = self._n()
                    self._index = min(self._index, max(n - 1, 0)) if request else 0
                    self._trail_from = min(self._trail_from, self._index)
                    if not request:
                        self._playing = False
                dirty.add("plan")
            if dirty:
                self._publish(dirty)

    def _plan(self, objects: list[TableObject], selected: str | None,
              settings: tuple) -> Outcome:
        seq = (self._outcome.seq + 1) if self._outcome else 1
        obj = next((o for o in objects if o.name == selected), None)
        if obj is None:
            return Outcome(None, None, "No object selected: click on the table to place one.",
                           seq)
        kappa = np.asarray(self._kappa(), dtype=float)
        others = [o for o in objects if o.name != obj.name]  # obstacles too: never swept through
        obstacles = with_other_objects(settings[2], others)
        names = tuple(o.name for o in obstacles[len(settings[2]):])
        try:
            plan = self.planner.plan(kappa, (obj.x, obj.y), obj.r, delta_d=settings[0],
                                     weights=settings[1], obstacles=obstacles,
                                     clearance=settings[3])
            plan, note = plan_carry(self.robot, plan, obj, settings[4], obstacles, settings[3])
        except GraspRefused as exc:
            return Outcome(obj, None, str(exc), seq, others=names)
        except Exception as exc:  # a planner bug must not kill the worker
            log.exception("grasp planning failed")
            return Outcome(obj, None, f"The planner failed unexpectedly ({exc}).", seq)
        return Outcome(obj, plan, None, seq, note, others=names)

    def _tell_planning(self, seconds: float) -> None:
        """The planning clock's thread: listeners show that a plan has run ``seconds``."""
        view = dataclasses.replace(self.view(), planning_s=seconds)
        with self._cond:
            listeners = list(self._listeners)
        for fn in listeners:
            self._call(self._calling, self._listeners, fn, view, PLANNING)

    def _greet(self, listeners: list[GraspListener]) -> None:
        """Tell listeners added since the last run the whole state (the feed is not told: it
        recorded every change already)."""
        if not listeners:
            return
        view = self.view()
        for fn in listeners:
            self._call(self._calling, self._listeners, fn, view, PARTS)

    def _publish(self, dirty: set[str]) -> None:
        """Tell every listener (views first: they subscribed first) and then ``feed`` what
        changed; one that raises is logged and the others are still told."""
        view, changed = self.view(), frozenset(dirty)
        with self._cond:
            listeners = list(self._listeners)
        for fn in listeners:
            self._call(self._calling, self._listeners, fn, view, changed)
        if self._feed is not None:
            try:
                self._feed(view, changed)   # objects and plans into recordings and the bridge
            except Exception:
                log.exception("grasp session feed failed")
