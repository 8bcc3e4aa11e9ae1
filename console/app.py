"""The operator console: one viser server, one arm, composable panels and a single render thread.

``ConsoleApp(robot, server)`` sets up the stage (``console.scene.stage``: the theme from
``static/theme.toml`` with the share tunnel closed, the table, lights), the arm view and the
camera, then composes its panels. ``start()`` launches the render thread; ``stop()`` ends it
(the app is also a context manager).

Data flow (see ``console.core.state``)::

    GUI callback --store.request/edit--> command --(mirror, or hardware bridge)--> display
    render thread: newest display state -> ArmView.update -> panel.on_state  (<= render_hz)

Adding a panel (other engineers): write ``class MyPanel(console.panels.common.base.Panel)`` in
``console/panels/my_panel.py`` with ``title``, ``order``, optional ``kinds = ("planar",)``,
``build()`` creating widgets with thin callbacks that call ``self.app.store.request(q, "me")``,
and ``on_state(state)`` for display updates. Then add it to
:data:`console.panel_sets.DEFAULT_PANELS` (``kinds`` keeps it off the other robot), pass
``panels=`` to the constructor, or call ``app.add_panel(MyPanel)``; find it again with
``app.panel(MyPanel)``. Panels see the app as a :class:`console.panels.common.host.PanelHost`.

Plugging in hardware: build the app with ``mirror_commands=False``; the bridge's control thread
reads ``app.store.wait_command(seq, timeout)`` and reports measurements with
``app.store.report(q, "hardware")``; the view then draws what the robot measured. The loops and
links the panels use come in one typed :class:`console.core.services.ConsoleServices`
(``services=``, built by ``serve.py``; a loop that needs the console's store before the app
exists gets it from ``store=``); panels read ``app.services.<name>``.

Motion and safety live in ``app.core`` (:class:`console.core.console_core.ConsoleCore`, headless):
its ``stop_motion(reason, who)`` is THE STOP (the header's button and Esc, a lost lease, release
or take-over, hold-to-run expiry, link loss, a dead loop), the same for both arms whatever panels
exist; it owns hold-to-run (``app.core.hold``) and forwards commanded states to the arm's loop.
Panels never wire safety: they render state and call the core.

Sharing the console (issue 6): ``app.access`` is the operator lock (``console.core.access``): gate
every callback that moves the arm with ``console.panels.common.base.operator_only`` (or
``app.access.check(event.client, "jog")``). ``app.recorder.log(kind, payload, client)`` adds to
a running recording (``console.recording.recorder``); files live under ``app.data``
(``console.core.datadir``).
A process builds a console only after ``console.web.install()`` (``serve.py`` calls it; the
constructor raises RuntimeError otherwise). ``app.guard`` (``console.web.client_guard``) checks
every message a browser sends before viser stores or broadcasts it: only valid values, shared
inputs for the operator only unless a panel calls ``allow_viewers(handle)``, per-client rate and
size limits.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable, Sequence, TypeVar

import numpy as np
import numpy.typing as npt
import viser

from console import web
from console.core.access import AccessControl, NotOperator, Operator
from console.core.console_core import ConsoleCore, StopRecord
from console.scene.arm_view import ArmView
from console.scene.arm_view_factory import make_arm_view
from console.core.datadir import DataDir
from console.core.design_study import DesignStudies
from console.core.grasp_session import GraspSession
from console.panels.common.header import ConsoleHeader, ViewerLine
from console.core.hold_to_run import HoldToRun
from console.lease import LeaseMonitor
from console.panels.common.loop_header import LoopHeader, LoopSource
from console.core.model import ArmModel, model_for
from console.panel_sets import DEFAULT_PANELS
from console.panels.common.base import Panel
from console.recording.lab_feed import feed_grasp
from console.recording.recorder import Recorder
from console.core.services import ConsoleServices
from console.scene.grasp_layers import GraspSceneView
from console.scene.study_ghost import StudyGhostView
from console.scene.camera import presets_for_window, volume_top
from console.scene.plan_frame import FRAMED_PARTS, plan_points
from console.scene.window_fit import WindowFit
from console.scene.stage import add_lights, add_table, arm_span, setup_camera, setup_theme, table_extent
from console.core.state import ArmState, StateStore
from console.panels.common.tabs import ConsoleTabs
from core.kinematics import delta as dk
from core.labdata.channels import robot_description
from core.robots import Robot, SoftArm
from console.web.client_guard import ClientGuard
from console.web.connection_gate import ConnectionGate, ConnectionLimits, is_loopback

log = logging.getLogger(__name__)

P = TypeVar("P", bound=Panel)
# The extensible arm's tip this close (m) to the top its views were framed for: re-framed.
FOLLOW_MARGIN_M = 0.02
# The display this long (s) without a new state: the state the arm view's dead band held back is
# drawn (its source went quiet). Not sooner: an armed soft arm's view pauses 0.2-0.3 s about 4
# times a minute while it keeps reporting its noise, and each such flush drew one noisy frame.
FLUSH_IDLE_S = 1.0


class ConsoleApp:
    """Viser operator console for one robot.

    Args:
        robot: A loaded description (``core.robots.load``).
        server: The viser server to draw into (the app does not own its lifetime).
        panels: Panel classes to compose, in addition order (default :data:`DEFAULT_PANELS`);
            those whose ``supports(robot)`` is false are skipped.
        mirror_commands: True to display commands at once (no hardware); False when a hardware
            bridge reports the measured state.
        render_hz: Upper bound on redraws per second; only the newest state is drawn.
        status: One line shown at the top of the control panel (e.g. the hardware mode).
        initial: Initial configuration (default: straight / retracted).
        access: The operator lock (default: no token, every browser starts as a viewer).
        data_dir: The only folder the console reads or writes files in (default ``./runs``,
            created when first used).
        services: The loops, links and helpers the panels use (``serve.py`` builds them; the
            default has none, and panels that need one say so).
        store: The console's state store, when a service built before the app needs it (it
            then carries ``initial`` and ``mirror_commands`` itself).
        connection_limits: Websocket connections served per address and in all (default
            :class:`~console.web.connection_gate.ConnectionLimits`: 20 and 200); loopback and
            the operator's address are never refused.
        clock: Monotonic time source of the core, its hold-to-run, the panels' rate limits and
            the coalescing of refusals and notifications (tests pass a simulated one).
    """

    def __init__(self, robot: Robot, server: viser.ViserServer, *,
                 panels: Sequence[type[Panel]] | None = None,
                 mirror_commands: bool = True, render_hz: float = 30.0,
                 status: str = "Kinematic simulation (no hardware connected)",
                 initial: npt.ArrayLike | None = None, access: AccessControl | None = None,
                 data_dir: str | Path | None = None, services: ConsoleServices | None = None,
                 store: StateStore | None = None,
                 connection_limits: ConnectionLimits | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not web.installed():  # fail closed: no console on an unguarded, unfixed viser
            raise RuntimeError("call console.web.install() first: viser's patches (the client "
                               "guard, shared sends) are not installed")
        if render_hz <= 0:
            raise ValueError(f"render_hz must be > 0, got {render_hz}")
        self.robot = robot
        self.server = server
        self.model: ArmModel = model_for(robot)
        if store is not None and (initial is not None or store.model.kind != self.model.kind):
            raise ValueError("give either store= (for this robot) or initial=, not both")
        self.store = store if store is not None else StateStore(self.model, initial,
                                                                 mirror_commands=mirror_commands)
        self.services = services if services is not None else ConsoleServices()
        self.grasp_session: GraspSession | None = None  # the soft arm's table and plan
        self.grasp_scene: GraspSceneView | None = None  # and its 3D layers
        self.render_period = 1.0 / render_hz
        self.frames_drawn = 0
        self.last_drawn_seq = -1
        self.refusals = 0
        self._refused_at: dict[tuple[Any, str], float] = {}
        self._notified_at: dict[tuple[str, str], float] = {}
        self._panels: list[Panel] = []
        self._panel_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._notice_lock = threading.Lock()
        self._refusal_notes: dict[Any, Any] = {}  # client id -> its refusal's notification

        self.data_root = Path("runs" if data_dir is None else data_dir)
        self._data: DataDir | None = None
        self.access = access if access is not None else AccessControl()
        self.guard = ClientGuard(server, is_operator=self.access.is_operator, refuse=self.refuse,
                                 refusal=self.access.refusal)
        self.connections = ConnectionGate(server, connection_limits,
                                          privileged=self._privileged_address)
        self.connections.closed.append(self.guard.forget)
        self.recorder = Recorder(lambda: self.data, self.model, self.access.name_of)
        self.recorder.log("robot", robot_description(robot))  # latched: recordings start with it
        for loop_process in (self.services.soft_control, self.services.extensible_runner):
            listeners = getattr(loop_process, "tick_listeners", None)
            if listeners is not None:  # every loop tick into recordings (100 Hz)
                listeners.append(self.recorder.on_ticks)
        self.core = ConsoleCore(self.store, self.services, self.access, self.recorder,
                                clock=clock)
        self.lease = LeaseMonitor(server, self.access, busy=lambda: self.core.hold.active,
                                  needed=self._motion_needs_lease)
        # Each viewer's page: one line atop saying who operates and how to get control.
        self.viewer_line = ViewerLine(server, self.access, stopped=lambda: self.stopped)
        self.access.add_listener(self._on_control_change)  # after the core's: it stops first
        server.on_client_connect(self.access.grant_if_free)

        self.theme = setup_theme(server, robot.name)  # (console.scene.stage) no share tunnel either
        self.status = server.gui.add_markdown(f"<small>{status}</small>", order=0.3)
        self.header = ConsoleHeader(  # STOP, control, phase, link: above every tab
            server.gui, self.core, allow_viewers=self.guard.allow_viewers,
            notify_all=self.notify_all, stopped=lambda: self.stopped)
        # Phase and Link: the arm's loop process's view with its age (console.panels.common.loop_header);
        # panels word a fresh view through it: (app.loop_header or app.header).show(...)
        loop = self.services.soft_control or self.services.extensible_runner
        self.loop_header: LoopHeader | None = (LoopHeader(self.header, loop)
                                               if isinstance(loop, LoopSource) else None)
        self.tabs = ConsoleTabs(self.server.gui, order=1.0)  # panels build into their tab
        self.table, self.grid = add_table(server.scene, self.theme, self.table_rectangle())
        add_lights(server.scene, self.theme)
        self.view: ArmView[ArmModel] = make_arm_view(server.scene, self.model)
        if isinstance(robot, SoftArm):  # the table, its objects and plans
            self.grasp_session = GraspSession(
                robot, self.table_rectangle(), kappa=lambda: self.store.display.q,
                feed=lambda view, changed: feed_grasp(self.recorder, view, changed),
                cache_dirs=(self.data_root / "cache",))
            self.grasp_scene = GraspSceneView(server, robot, self.grasp_session)
            self.grasp_session.start()
            # A recording starts with the table and plan as they are: the recorder keeps the
            # newest objects and plan records (Recorder.latched), logged by the feed on change.
        # Design studies (Experiments tab): the open study and a variant drawn beside the arm.
        self.design_study = DesignStudies(self.data_root)
        self.study_ghost = StudyGhostView(server, self.design_study, robot)
        self.camera_presets = setup_camera(server, robot, self.model.kind)
        kind, span, table = self.model.kind, self.arm_reach(), self.table_rectangle()
        # Each browser's camera framed for its own window (a tablet's, a phone's) and for what
        # is planned (a far object's approach circles: console.scene.plan_frame); the
        # extensible arm's for the arm as tall as it is (re-framed when it grows: follow_arm).
        self._framed_top = span  # the lowest top (m) an extensible arm's view was framed for
        self._kept_in_view: np.ndarray | None = None  # a typed tip target (keep_in_view)
        self.window_fit = WindowFit(
            server, self.camera_presets[0],
            lambda w, h: presets_for_window(kind, span, table, w, h, self.framed_points()),
            stopped=lambda: self.stopped)
        if self.grasp_session is not None:
            self.grasp_session.add_listener(
                lambda view, changed: self.window_fit.refit() if changed & FRAMED_PARTS else None)
        for panel_cls in DEFAULT_PANELS if panels is None else panels:
            self.add_panel(panel_cls)

    # -- composition -------------------------------------------------------------------------

    def add_panel(self, panel_cls: type[P]) -> P | None:
        """Construct ``panel_cls(self)`` if it supports this robot; returns it (or None)."""
        if not panel_cls.supports(self.robot):
            return None
        panel = panel_cls(self)
        with self._panel_lock:
            self._panels.append(panel)
        return panel

    def panel(self, panel_cls: type[P]) -> P:
        """The composed panel of class ``panel_cls`` (KeyError if absent)."""
        with self._panel_lock:
            for p in self._panels:
                if isinstance(p, panel_cls):
                    return p
        raise KeyError(f"no {panel_cls.__name__} in this console")

    def soft_arm_grasp(self) -> GraspSession:
        """The grasp session, for panels that exist on the soft arm only (RuntimeError on an
        arm without one)."""
        if self.grasp_session is None:
            raise RuntimeError(f"{self.robot.name} is not a soft arm: it has no grasp session")
        return self.grasp_session

    def soft_arm_grasp_scene(self) -> GraspSceneView:
        """The grasp session's 3D layers (RuntimeError on an arm without a grasp session)."""
        if self.grasp_scene is None:
            raise RuntimeError(f"{self.robot.name} is not a soft arm: it has no grasp layers")
        return self.grasp_scene

    @property
    def panels(self) -> tuple[Panel, ...]:
        """Composed panels in addition order."""
        with self._panel_lock:
            return tuple(self._panels)

    # -- sharing: data folder, STOP, who may act ----------------------------------------------

    @property
    def data(self) -> DataDir:
        """The console's data folder (created on first use)."""
        if self._data is None:
            self._data = DataDir(self.data_root)
        return self._data

    @property
    def hold(self) -> HoldToRun:
        """The core's hold-to-run (every jog motion)."""
        return self.core.hold

    def _motion_needs_lease(self) -> bool:
        """Whether the operator's tab must answer lease probes now: a jog held, the arm moving
        (the loop's view), or the demo motion running; a still console keeps the lease without
        them (see ``console.lease.LeaseMonitor``)."""
        demo = self.services.demo
        return (self.core.hold.active or self.core.arm.moving()
                or (demo is not None and demo.running))

    def stop_motion(self, reason: str, client: Any = None) -> None:
        """STOP: the core's one safety route (:meth:`ConsoleCore.stop_motion`)."""
        self.core.stop_motion(reason, client)

    @property
    def stops(self) -> int:
        """How many times motion was stopped (the core's count)."""
        return self.core.stops

    @property
    def last_stop(self) -> StopRecord | None:
        """The latest stop: when, why, who (the core's)."""
        return self.core.last_stop

    def refuse(self, client: Any, exc: NotOperator | str, action: str = "") -> None:
        """Tell ``client`` why it may not act (a notification only it sees); logs the refusal."""
        reason = exc.reason if isinstance(exc, NotOperator) else str(exc)
        key = (getattr(client, "client_id", client), action or reason)
        now = self.core.clock()
        with self._notice_lock:  # a held button refuses 20 times a second: tell them once
            if now - self._refused_at.get(key, -1e9) < 2.0:
                return
            self._refused_at[key] = now
            if len(self._refused_at) > 1000:
                self._refused_at.clear()
        self.refusals += 1
        self.recorder.action(f"refused: {action or reason}", client)
        self.show_refusal(client, "Not allowed", reason)

    def show_refusal(self, client: Any, title: str, message: str) -> None:
        """Tell ``client`` (only) why something was refused, until its next action: the
        notification does not close by itself (a refusal read 8 s later must still be there);
        the client's next refusal replaces it and its next action (:meth:`clear_refusal`,
        called by ``operator_only``) removes it."""
        if client is None or not hasattr(client, "add_notification"):
            return
        self.clear_refusal(client)
        try:
            note = client.add_notification(title, message, color="red", auto_close_seconds=None)
        except Exception:  # a client that just left
            log.debug("refusal to client %s failed", getattr(client, "client_id", client))
            return
        with self._notice_lock:
            self._refusal_notes[getattr(client, "client_id", id(client))] = note

    def clear_refusal(self, client: Any) -> None:
        """Remove ``client``'s standing refusal (its next action is under way)."""
        if client is None:
            return
        with self._notice_lock:
            note = self._refusal_notes.pop(getattr(client, "client_id", id(client)), None)
        if note is not None and hasattr(note, "remove"):
            try:
                note.remove()
            except Exception:  # a client that just left
                log.debug("removing a refusal failed")

    def notify_all(self, title: str, body: str, color: str = "blue",
                   coalesce_s: float = 0.0) -> None:
        """A notification on every connected browser; with ``coalesce_s``, the same title and
        body again within that many seconds is not repeated (a burst of STOP clicks shows one).
        """
        if coalesce_s > 0:
            now = self.core.clock()
            with self._notice_lock:
                if now - self._notified_at.get((title, body), -1e9) < coalesce_s:
                    return
                self._notified_at[(title, body)] = now
                if len(self._notified_at) > 1000:
                    self._notified_at.clear()
        for client in self.server.get_clients().values():
            try:
                client.add_notification(title, body, color=color, auto_close_seconds=8.0)
            except Exception:  # a client that just left
                log.debug("notification to client %s failed", client.client_id)

    def _on_control_change(self, new: Operator | None, previous: Operator | None,
                           reason: str) -> None:
        """Tell every browser that nobody holds control (the core has stopped the arm); show each
        browser its role's controls (viewers: operator-only ones disabled) and viewer line."""
        if not self.stopped:
            self.guard.viewer_props.resend()
            self.viewer_line.refresh()
        if previous is not None:
            if new is None:
                self.notify_all("Control released", f"{reason}. The arm was stopped; nobody "
                                "holds control.", color="orange", coalesce_s=3.0)

    # -- lifecycle ---------------------------------------------------------------------------

    def start(self) -> ConsoleApp:
        """Start the render, jog and lease threads (idempotent)."""
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._render_loop, name="console-render",
                                            daemon=True)
            self._thread.start()
        self.core.start()
        self.lease.start()
        if self.loop_header is not None:
            self.loop_header.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the threads (and any recording); the viser server keeps running."""
        self._stop.set()
        if self.loop_header is not None:
            self.loop_header.stop(timeout)
        self.lease.stop(timeout)
        self.core.stop(timeout)
        self.recorder.stop()
        for loop_process in (self.services.soft_control, self.services.extensible_runner):
            listeners = getattr(loop_process, "tick_listeners", None)
            if listeners is not None and self.recorder.on_ticks in listeners:
                listeners.remove(self.recorder.on_ticks)
        if self.grasp_session is not None:
            self.grasp_session.close()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def _privileged_address(self, address: str | None) -> bool:
        """Whether connections from ``address`` are never refused: this machine's, and the one
        the operator's browser connects from (others' sockets cannot lock them out)."""
        if is_loopback(address):
            return True
        holder = self.access.holder
        return (holder is not None and address is not None
                and address == self.guard.address_of(holder.client_id))

    @property
    def stopped(self) -> bool:
        """Whether :meth:`stop` has run (panels skip GUI updates while shutting down)."""
        return self._stop.is_set()

    def __enter__(self) -> ConsoleApp:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- rendering ---------------------------------------------------------------------------

    def render(self, state: ArmState) -> None:
        """Draw ``state`` and notify panels; only the render thread should call this."""
        with self.server.atomic():
            self.view.update(np.asarray(state.q))
            for panel in self.panels:
                try:
                    panel.on_state(state)
                except Exception:  # a broken panel must not stop the arm from drawing
                    log.exception("panel %s failed in on_state", type(panel).__name__)
        self.follow_arm(np.asarray(state.q))
        self.frames_drawn += 1
        self.last_drawn_seq = state.seq
        self.recorder.on_state(state, self.store.command)

    def _idle(self, idle_s: float = FLUSH_IDLE_S) -> None:
        """The display has had no new state for ``idle_s`` seconds: from :data:`FLUSH_IDLE_S` on
        the arm view draws the state its dead band held back; panels catch up."""
        if idle_s >= FLUSH_IDLE_S:
            with self.server.atomic():
                try:
                    self.view.flush()  # the newest state, if the dead band held it back
                except Exception:
                    log.exception("arm view flush failed")
        for panel in self.panels:
            try:
                panel.on_idle()
            except Exception:
                log.exception("panel %s failed in on_idle", type(panel).__name__)

    def _render_loop(self) -> None:
        last_seq = -1
        next_frame = 0.0
        last_state_at = time.monotonic()  # (the loop waits on the wall clock, as its frames)
        while not self._stop.is_set():
            state = self.store.wait_display(last_seq, timeout=0.2)
            if state is None:
                self._idle(time.monotonic() - last_state_at)
                continue
            last_state_at = time.monotonic()
            wait = next_frame - time.perf_counter()
            if wait > 0 and self._stop.wait(wait):
                break
            state = self.store.display  # the newest after the wait: skip, never catch up
            started = time.perf_counter()
            try:
                self.render(state)
            except Exception:
                log.exception("render failed for state #%d", state.seq)
            last_seq = state.seq
            # The period counts from this frame's start: counted from its end, the time a
            # render takes (5-25 ms on a busy machine) came on top and 30 Hz became ~20 Hz.
            next_frame = started + self.render_period

    # -- the stage (console.scene.stage) ----------------------------------------------------------

    def arm_reach(self) -> float:
        """Largest distance of any arm point from the base (:func:`console.scene.stage.arm_span`)."""
        return arm_span(self.robot, self.model.kind)

    def table_rectangle(self) -> tuple[float, float, float, float]:
        """Table rectangle (x0, x1, y0, y1) around the arm's workspace
        (:func:`console.scene.stage.table_extent`)."""
        return table_extent(self.robot, self.model.kind)

    def framed_points(self) -> np.ndarray | None:
        """World points (m) the camera presets frame besides the arm's reach: the soft arm's
        plans (:meth:`planned_points`); the extensible arm's own points as drawn now, which
        size its framed working volume (``console.scene.camera.working_volume``)."""
        if self.model.kind == "planar":
            return self.planned_points()
        g = self.view.geometry(np.asarray(self.store.display.q))
        points = np.concatenate([np.asarray(g[k], float).reshape(-1, 3)
                                 for k in ("platforms", "backbone") if k in g])
        kept = self._kept_in_view
        if kept is not None:
            points = np.vstack([points, kept[None]])
        self._framed_top = min(self._framed_top, volume_top(self.arm_reach(), points))
        return points

    def keep_in_view(self, point: npt.ArrayLike | None) -> list[int]:
        """Keep ``point`` (m, world; the extensible arm's typed or dragged tip target) in every
        browser's view until another replaces it (None: none): when it lies above the top the
        views were framed for (or within :data:`FOLLOW_MARGIN_M` of it), re-frame the cameras
        still where the console put them, like :meth:`follow_arm`; the ids of the browsers
        moved. A typed target above the arm used to be drawn half off the top until Go."""
        if point is None:
            self._kept_in_view = None
            return []
        p = np.asarray(point, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)) or self.model.kind != "delta":
            return []
        self._kept_in_view = p
        return self._reframe_above(p)

    def follow_arm(self, q: np.ndarray) -> list[int]:
        """The extensible arm's tip rose within :data:`FOLLOW_MARGIN_M` of the top its views
        were framed for (:meth:`framed_points`): re-frame every browser's camera still where the
        console put it (``WindowFit.refit``), for the arm as tall as it is now; the ids of the
        browsers moved. Nothing for the soft arm (it lies on the table) or below that top."""
        if self.model.kind != "delta":
            return []
        return self._reframe_above(dk.tip_position(self.robot, q))

    def _reframe_above(self, point: npt.ArrayLike) -> list[int]:
        """Re-frame the cameras still where the console put them when ``point`` (m, world)
        rises within :data:`FOLLOW_MARGIN_M` of the top the views were framed for; the ids of
        the browsers moved (none when framed for the fully extended arm already, or when the
        point is well in view)."""
        p = np.asarray(point, dtype=float).reshape(3)
        if self._framed_top >= self.arm_reach() or p[2] + FOLLOW_MARGIN_M <= self._framed_top:
            return []
        self._framed_top = volume_top(self.arm_reach(), [p])
        return self.window_fit.refit()

    def planned_points(self) -> np.ndarray | None:
        """World points (m) the camera presets show besides the arm's reach: the soft arm's
        objects, bin and plans (:func:`console.scene.plan_frame.plan_points`); None for an arm
        without a grasp session."""
        session = self.grasp_session
        return None if session is None else plan_points(session.view())
