"""Tip-target panel: drag a gizmo (or type x, y, z and press Go) and the extensible arm's tip
follows by IK.

Typed x, y, z are applied together, by **Go** (issue 31: a move per typed field sent the arm
through targets nobody asked for). Typing only changes the *pending* target: a dimmed ball in the
view and a status line that says it is not applied yet; nothing moves. Go reads the three fields
at once and moves to exactly that target (one move: one IK solve, one set-point, or one route
past the boxes); a field that is not a finite number gets a clear message and moves nothing.
"Target ← current tip" or a drag of the gizmo discards a pending target.

A transform control in the 3D view holds the tip target. While the operator drags it, a worker
thread (``console.panels.extensible.target_worker``) has the tip IK
(``core.kinematics.delta_ik.solve_tip_ik``) solved, warm-started from the posture being moved to,
without restarts, at most ``LIVE_HZ`` times a second on the newest target only; on release (and
on Go) it solves once more with restarts. The solve itself runs in a ``spawn``-ed
worker process (started on the first solve), never in the console's process: there a CPU-bound
solve holds the GIL the extensible runner's 100 Hz loop needs (measured: an IK thread next to the
runner tripped the serial link's write timeout within seconds). The solution
is a set-point for ``app.core.hold`` (``console.core.hold_to_run``: speed-capped, stops on STOP or a lost
lease), like the jog sliders; on arrival the panel re-commands it as ``"target"`` so the Δ jog
sliders show it. With the hardware runner started, the motors follow the command; when the
link is not armed (its health, as the Hardware panel shows it) the status says the motors will
not follow. An unreachable target moves the arm to the closest feasible configuration; the
panel names that tip, how far it is from the target, and a red line in the view joins them.
A target released or sent by Go is answered at once ("Solving the IK for (x, y, z) mm…"), then by
the result or by why nothing moves (IK error, no answer within ``IK_TIMEOUT_S``, a running
path, control lost, motors not armed): never silence. Only the operator may move the target
(``operator_only``).

viser runs field callbacks in its thread pool (two typed fields' callbacks and Go's may run at
once) and the render thread answers new commands meanwhile: reading the typed fields, setting the
pending target, saying "Solving…" and submitting the target happen under one lock, as do the
render thread's tip reset and every echo into the fields (none while a target is pending: the
fields then hold it), so a target submitted later was read later and no echo lands between a
read and its answer (a loaded machine lost a typed field so).

Box obstacles (the Obstacles panel, ``console.panels.extensible.obstacles_boxes``): with boxes placed, the
worker process solves the IK with them (the arm's body surface keeps the clearance from every
box) and a route there whose straight rack-space legs -- what the hold-to-run set-point and the
runner follow -- stay clear too (``core.planning.box_routes.reach_clear``: direct, or through
straightened / retracted postures, moved through leg by leg). When the boxes leave no
collision-free posture or route, nothing moves and the status says why: which box, how close
("blocked").
"""

from __future__ import annotations

import concurrent.futures as cf
import html
import threading
from typing import Any

import numpy as np
import numpy.typing as npt
import viser

from console.panels.common.base import Panel, operator_only
from console.panels.extensible.status import extensible_arm, link_summary
from console.panels.extensible.obstacles_boxes import box_scene_of
from console.panels.extensible.target_worker import TargetIKWorker
from console.panels.extensible.worker_pool import WorkerPool
from console.panels.common.typed_fields import TypedFields
from console.core.console_core import MotionStopped
from console.core.state import ArmState
from console.panels.common.disarmed import disarmed_note
from core.kinematics import delta as dk
from core.kinematics.delta_ik import TipIKResult, solve_tip_ik
from core.planning.box_routes import ClearReach, reach_clear
from core.planning.box_scene import BoxScene
from core.robot_sections import IKSettings
from core.units import fmt_deg, fmt_mm, mm_value, mm_xyz

Array = npt.NDArray[np.float64]
TARGET_COLOR = (235, 130, 30)
MISS_COLOR = (210, 40, 40)
PENDING_OPACITY = 0.35  # the typed target not yet applied: a dimmed ball
SAME_TARGET_M = 6e-5  # m: typed fields this close to the target are the target (0.1 mm steps)
IK_TIMEOUT_S = 20.0  # s: a solve takes < 1 s unloaded; past this the worker is restarted
_AXES = ("x", "y", "z")
BLOCKED = "Blocked by the boxes: "  # an error message that starts so is shown as "blocked"


class TargetPanel(Panel):
    """Gizmo and typed tip target, solved by the tip IK within the rack and bending limits."""

    title = "Tip target"
    order = 2.0  # first in Operate, then Paths
    kinds = ("delta",)
    _route_len = 1  # postures of the last route moved along (1: straight there)

    def build(self) -> None:
        self.robot = extensible_arm(self.app)
        self.settings = IKSettings.from_robot(self.robot)
        tip = self._tip(self.app.store.command.q)
        scene = self.app.server.scene
        self.gizmo = scene.add_transform_controls(
            "/target", scale=0.12, disable_rotations=True, depth_test=False, line_width=3.0,
            position=tuple(tip))
        self.ball = scene.add_icosphere("/target/ball", radius=0.012, color=TARGET_COLOR,
                                        cast_shadow=False)
        self.pending_ball = scene.add_icosphere(
            "/target_pending", radius=0.012, color=TARGET_COLOR, opacity=PENDING_OPACITY,
            cast_shadow=False, visible=False)
        self.miss = scene.add_line_segments("/target_miss", np.zeros((1, 2, 3)), MISS_COLOR,
                                            thickness=3.0, thickness_units="screen",
                                            visible=False)
        self.follow = self.gui.add_checkbox(
            "Follow while dragging", True,
            hint="Solve the IK live while the gizmo moves (else only on release).")
        self.inputs = [self.gui.add_number(
            f"Target {a} (mm)", mm_value(v), step=0.1,
            hint=f"Tip target {a} in mm; nothing moves until Go (x, y, z together).")
            for a, v in zip(_AXES, tip)]
        self.go = self.gui.add_button("Go", hint="Move the tip to the typed x, y, z (IK within "
                                                 "the rack and bending limits).")
        self.to_tip = self.gui.add_button("Target ← current tip",
                                          hint="Put the target back on the arm's tip (and "
                                               "discard a typed target not applied).")
        self.status = self.gui.add_html(self._status_html(None, None))
        self._hardware_note = ""  # why the motors will not follow, from the link's health
        self._target = tip.copy()
        self._pending: Array | None = None  # typed, not applied (Go): the fields hold it
        self._shown_pending: tuple[float, ...] | None = None
        self._typed = TypedFields(self.inputs)  # the echo of an answer skips a field just typed
        # Typed reads + their answer, the render thread's tip reset and every echo: one at a time
        # (re-entrant: writing a field calls its callback back with no client).
        self._typing = threading.RLock()
        self._dragging = False
        self._moving_to: Array | None = None  # set-point handed to core.hold, until it arrives
        self._legs: tuple[int, list[Array]] = (0, [])  # (client id, route postures still to go)
        # (n, target, result, error, info): replaced whole by the worker, shown by on_state.
        self._latest: tuple[int, Array, TipIKResult | None, str | None, str | None] = (
            0, tip, None, None, None)
        self._shown = 0
        self._synced_seq = self.app.store.command.seq
        self._pool: WorkerPool | None = None
        self._pool_lock = threading.Lock()
        self.worker = TargetIKWorker(self)
        self.gizmo.on_update(self._on_gizmo)
        for handle in self.inputs:
            handle.on_update(self._on_typed)
        self.go.on_click(self._on_go)
        self.to_tip.on_click(lambda _: self._reset_to_tip())
        self.app.server.on_client_connect(lambda _: self._warm_up())

    def _warm_up(self) -> None:
        """Start the IK worker process when a browser opens (not on the first target: a
        spawned Python with numpy takes seconds to start on a loaded machine)."""
        q = np.asarray(self.app.store.command.q, dtype=float)
        try:  # a solve where the tip already is: cheap, and imports all a solve needs
            self._ik_pool().submit(solve_tip_ik, self.app.robot, self._tip(q), q,
                                   restarts=False, settings=self.settings)
        except RuntimeError:  # shut down (console closing)
            pass

    # -- callbacks (thin) ------------------------------------------------------------------
    @operator_only(action="move the tip target")
    def _on_gizmo(self, event: viser.TransformControlsEvent) -> None:
        if event.client is None:
            return
        target = np.asarray(event.target.position, dtype=float)
        if self._pending is not None:  # the gizmo is the new target: a typed one goes
            with self._typing:
                self._pending = None
        self._target = target
        self._dragging = event.phase != "end"
        if event.phase == "end":
            self._say_solving(target)
        if event.phase == "end" or self.follow.value:
            self.worker.submit(target, event.phase == "end", event.client.client_id)

    @operator_only(action="move the tip target")
    def _on_typed(self, event: viser.GuiEvent) -> None:
        """A typed field: the pending target (all three fields as typed now); nothing moves."""
        if event.client is None:  # our own mirror of the target into the inputs
            return
        with self._typing:  # read in the same order as other fields' callbacks and Go
            target = self._read_fields()
            if target is None:
                return
            # Typed back to the target (or a field's callback late after Go): nothing pending.
            # (Within the fields' rounding: they show the target to 0.1 mm.)
            same = bool(np.allclose(target, self._target, rtol=0, atol=SAME_TARGET_M))
            self._pending = None if same else target
            self._show()
        if not same:  # the pending ball is drawn there: every view widens to show it
            self.app.keep_in_view(target)

    @operator_only(action="move the tip target")
    def _on_go(self, event: viser.GuiEvent) -> None:
        """Go: the three typed fields together, solved once and moved to."""
        if event.client is None:
            return
        with self._typing:  # read and submitted in the same order as the fields' callbacks
            target = self._read_fields()
            if target is None:
                return
            self._pending = None
            self._target = target
            self.gizmo.position = tuple(target)
            self._say_solving(target)
            self.worker.submit(target, True, event.client.client_id)
        self.app.keep_in_view(target)

    def _read_fields(self) -> Array | None:
        """Every field as typed now (m); None after saying why when one is not a finite
        number (the fields go back to the target, nothing pending, nothing moves)."""
        target = np.array(self._typed.read()) / 1e3
        if np.all(np.isfinite(target)):
            return target
        self._pending = None
        self.report_error("Not moved: the target must be three finite numbers x, y, z (mm).")
        self._typed.show([mm_value(v) for v in self._target], typed_too=True)
        return None

    def _say_solving(self, target: Array) -> None:
        """Answer a typed / released target at once: the solve may take a moment."""
        self._publish(target, None, None, f"Solving the IK for {mm_xyz(target)} mm…")
        self._show()

    def on_refused(self, event: Any) -> None:
        """A viewer moved the gizmo or an input: put them back where the target is."""
        self.gizmo.position = tuple(self._target)
        with self._typing:
            shown = self._target if self._pending is None else self._pending
            self._typed.show([mm_value(v) for v in shown], typed_too=True)

    def _reset_to_tip(self) -> None:
        with self._typing:
            tip = self._tip(self.app.store.command.q)
            self._pending = None  # a typed target not applied is discarded
            self._target = tip
            self.gizmo.position = tuple(tip)
            self._publish(tip, None, None)
            self._typed.show([mm_value(v) for v in tip], typed_too=True)
            self._show()  # nothing else changes, so no frame would show it

    def on_stopped(self) -> None:
        """Worker thread, after the console core stopped motion (STOP, a lost lease...; the
        core's hold-to-run ended the move itself): say so when that leaves a target
        unanswered or not reached."""
        pending = self._latest[4] is not None or self._moving_to is not None
        self._moving_to = None
        self._legs = (0, [])
        if pending:
            self.report_error(f"Not moved to the target: motion stopped ({self._why_stopped()}).")

    def _why_stopped(self) -> str:
        last = self.app.core.last_stop
        return "stopped" if last is None else last.reason

    # -- worker ----------------------------------------------------------------------------
    def solve(self, target: Array, final: bool, client_id: int, generation: int,
              stops: int | None = None) -> None:
        """Worker thread: IK to ``target``, then move there (unless a job runs or STOP came:
        ``stops`` is the core's stop generation when the target was taken; None: now)."""
        if stops is None:
            stops = self.app.core.stop_generation
        runner = self.app.services.extensible_runner
        if runner is not None and runner.snapshot.busy:
            self.report_error("A path is running: stop it before moving the target.")
            return
        moving = self.app.core.hold.target()
        q0 = np.asarray(self.app.store.command.q if moving is None else moving)
        scene, _ = box_scene_of(self.app)
        if scene.boxes:
            reach = self._solve_clear(target, q0, final, scene)
            if generation != self.worker.generation:
                return
            if reach.refusal or reach.route is None:
                self._publish(target, reach.result, BLOCKED + (reach.refusal or "no route"))
                self._show()
                return
            result, legs = reach.result, list(reach.route.postures)
        else:
            result = self._solve(target, q0, final)
            legs = [result.delta]
            if generation != self.worker.generation:
                return
        self._route_len = len(legs)
        # The move first (its set-point marks the commands to come as this panel's), then the
        # answer: until it is published, "Solving…" keeps the render thread from taking a new
        # command for someone else's and putting the target back on the tip.
        if self._start_leg(client_id, legs, "Not moved: you no longer hold control.", stops):
            self._publish(target, result, None)
            self._show()

    def _start_leg(self, client_id: int, legs: list[Array], refused: str,
                   stops: int | None = None) -> bool:
        """Move to the first of ``legs`` (the rest follow on arrival, :meth:`check_arrival`);
        False after reporting ``refused`` when ``client_id`` no longer holds control, or that
        motion stopped when the core stopped since its generation ``stops`` (None: now)."""
        core = self.app.core
        if stops is None:
            stops = core.stop_generation
        note = disarmed_note(self.app)
        if note is not None:  # never armed behind the operator's back
            self.report_error(f"Not moved: {note}")
            return False
        # Set before the move starts: a frame of the move ("jog") must not read as someone
        # else's command, which would put the target back on the tip and clear this status.
        self._legs = (client_id, legs[1:])
        self._moving_to = legs[0]
        try:
            if core.run_if_current(stops, lambda: core.hold.move_to(client_id, legs[0])):
                return True
        except MotionStopped:
            refused = f"Not moved to the target: motion stopped ({self._why_stopped()})."
        self._moving_to = None
        self._legs = (0, [])
        self.report_error(refused)
        return False

    def _ik_pool(self) -> WorkerPool:
        with self._pool_lock:
            if self._pool is None:
                self._pool = WorkerPool()
            return self._pool

    def _solve(self, target: Array, q0: Array, final: bool) -> TipIKResult:
        """Worker thread: the IK in the worker process (this thread waits without the GIL)."""
        return self._in_pool(solve_tip_ik, self.app.robot, target, q0, restarts=final,
                             settings=self.settings)

    def _solve_clear(self, target: Array, q0: Array, final: bool,
                     scene: BoxScene) -> ClearReach:
        """Worker thread: the IK with the boxes and a clear route there, in the worker process."""
        return self._in_pool(reach_clear, self.app.robot, target, q0, restarts=final,
                             settings=self.settings, boxes=scene.boxes,
                             clearance=scene.clearance)

    def _in_pool(self, fn: Any, *args: Any, **kwargs: Any) -> Any:
        pool = self._ik_pool()
        try:
            return pool.submit(fn, *args, **kwargs).result(timeout=IK_TIMEOUT_S)
        except cf.process.BrokenProcessPool:
            self._drop_pool(pool)
            raise RuntimeError("the IK worker process stopped; try again") from None
        except cf.TimeoutError:
            self._drop_pool(pool)
            raise RuntimeError(f"the IK gave no answer within {IK_TIMEOUT_S:.0f} s (machine "
                               "busy?); not moved; try again") from None

    def _drop_pool(self, pool: WorkerPool) -> None:
        """A broken or stuck worker: a new one next time (the old one is told to stop)."""
        with self._pool_lock:
            if self._pool is pool:
                self._pool = None
        pool.shutdown(wait=False, cancel_futures=True)

    def close(self) -> None:
        with self._pool_lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        super().close()

    def check_arrival(self) -> None:
        """Worker thread: once ``app.core.hold`` reached the set-point, command it as ``"target"``
        (the jog sliders do not mirror ``"jog"`` moves, this makes them show the posture)."""
        goal = self._moving_to
        if goal is None or self.app.core.hold.target() is not None:
            return
        command = self.app.store.command
        arrived = command.source == "jog" and np.allclose(command.q, goal, atol=1e-9)
        client_id, rest = self._legs
        if arrived and rest and not self._measured_at(goal):
            return  # the motors lag the command: the next leg starts from the corner
        if arrived and rest:  # a route past the boxes: on to its next posture
            self._start_leg(client_id, rest, "Stopped on the way: you no longer hold control.",
                            self.worker.stops)
            return
        self._legs = (0, [])
        if arrived:
            self.app.store.edit(lambda q: q, "target")
        self._moving_to = None  # after the edit: on_state must not take the arrival for a jog

    def _measured_at(self, goal: Array) -> bool:
        """Whether the arm as shown (with hardware: measured) is at ``goal``, within 0.5 mm of
        rack travel, so a route's next leg does not cut the corner behind a lagging arm."""
        if self.app.store.mirror_commands:
            return True
        robot: Any = self.app.robot
        shown = dk.robot_rack_lengths(robot, np.asarray(self.app.store.display.q))
        return bool(np.abs(shown - dk.robot_rack_lengths(robot, goal)).max() <= 5e-4)

    def report_error(self, message: str) -> None:
        """Show ``message`` now (no state change follows that would trigger a frame)."""
        self._publish(self._target, None, message)
        self._show()

    def _publish(self, target: Array, result: TipIKResult | None, message: str | None,
                 info: str | None = None) -> None:
        """Replace what the panel shows: an error ``message``, or ``info`` (a step under way),
        or the IK ``result`` (None: idle)."""
        self._latest = (self._latest[0] + 1, np.asarray(target, dtype=float), result,
                        message, info)

    # -- display (render thread) -----------------------------------------------------------
    def on_state(self, state: ArmState) -> None:
        with self._typing:  # not between a typed field's read and its "Solving…"
            command = self.app.store.command
            if command.seq != self._synced_seq:
                self._synced_seq = command.seq
                mine = command.source == "target" or (command.source == "jog"
                                                      and self._moving_to is not None)
                if not mine and not self._dragging and self._latest[4] is None:
                    # Moved by jog / path / runner / STOP: the target rides on the tip (not
                    # while a typed target is being solved: its answer comes next).
                    self._target = self._tip(command.q)
                    self.gizmo.position = tuple(self._target)
                    self._publish(self._target, None, None)
            self._show()

    def _show(self) -> None:
        with self._typing:  # the newest answer, never an older one over a field read since
            n, target, result, error, info = self._latest
            note = self._motors_note()
            pending = self._pending
            key = None if pending is None else tuple(float(v) for v in pending)
            if n == self._shown and note == self._hardware_note and key == self._shown_pending:
                return
            self._shown, self._hardware_note, self._shown_pending = n, note, key
            if pending is None:  # (while a target is pending the fields hold it)
                self._typed.show([mm_value(v) for v in target])
            else:
                self.pending_ball.position = tuple(pending)
            self.pending_ball.visible = pending is not None
            self.status.content = self._status_html(result, error, info, target, note, pending)
            if result is not None and not result.reachable and error is None:
                self.miss.points = np.stack([result.tip, target])[None]
                self.miss.visible = True
            else:
                self.miss.visible = False

    def _motors_note(self) -> str:
        """Why the motors will not follow the command, from the link supervisor's health (what
        the Hardware panel shows); "" when they follow or there is no link to manage."""
        if self.app.store.mirror_commands:  # the view shows the command (mock: no serial link)
            return ""
        controls = self.app.services.bridge_controls
        health = None if controls is None else controls.health()
        if health is not None and health.armed and not health.fault:
            return ""
        return (f"The motors do not follow ({link_summary(self.app)}): connect and arm them "
                "in the Hardware tab.")

    def _status_html(self, result: TipIKResult | None, error: str | None,
                     info: str | None = None, target: Array | None = None,
                     note: str = "", pending: Array | None = None) -> str:
        if error is not None and error.startswith(BLOCKED):
            body = (f"<b style='color:#c92a2a'>⚠ {html.escape(BLOCKED.strip())}</b> "
                    f"{html.escape(error[len(BLOCKED):])}. Not moved.")
            state = "blocked"
        elif error is not None:
            body, state = f"⚠ {html.escape(error)}", "error"
        elif info is not None:
            body, state = html.escape(info), "solving"
        elif result is None:
            body, state = ("Drag the gizmo (orange ball), or type x, y, z (mm) and press Go.",
                           "idle")
        elif result.reachable:
            body = (f"Target {mm_xyz(result.tip)} mm reachable (IK error "
                    f"{fmt_mm(result.error, 2)} mm): the tip goes there.")
            if result.nearest_box:
                body += (f" The arm keeps {fmt_mm(result.clearance, 1)} mm from box "
                         f"'{html.escape(result.nearest_box)}'"
                         + (f", moving via {self._route_len - 1} posture"
                            f"{'s' if self._route_len > 2 else ''} around the boxes."
                            if self._route_len > 1 else "."))
            state = "reachable"
        else:
            r: Any = self.app.robot
            aim = "the target" if target is None else f"{mm_xyz(target)} mm"
            body = (f"<b style='color:#c92a2a'>⚠ Unreachable:</b> {html.escape(aim)} is beyond "
                    f"the arm's reach (racks {fmt_mm(r.rack_min, 0)}–{fmt_mm(r.rack_max, 0)} mm, "
                    f"bend ≤ {fmt_deg(r.theta_max, 0)}° per segment). Moved to the closest reachable "
                    f"tip, {mm_xyz(result.tip)} mm, <b>{fmt_mm(result.error, 1)} mm</b> from the "
                    "target (red line to the target).")
            state = "unreachable"
        if pending is not None:  # typed, not applied: said first, the last answer below it
            body = (f"<b>Pending target {mm_xyz(pending)} mm, not applied</b>: press "
                    "<b>Go</b> to move the tip there (nothing moves until then; "
                    "“Target ← current tip” discards it).<br>"
                    f"<span style='opacity:.7'>{body}</span>")
            state = "pending"
        if note:
            body += f"<br><b style='color:#e67700'>⚠ {html.escape(note)}</b>"
        distance = "" if result is None else f"{fmt_mm(result.error, 3)}"
        clear = "" if result is None or not result.nearest_box else fmt_mm(result.clearance, 2)
        aimed = "" if target is None else ",".join(fmt_mm(v, 1) for v in target)  # never "-0"
        waiting = "" if pending is None else ",".join(fmt_mm(v, 1) for v in pending)
        return (f'<div data-testid="target-status" data-state="{state}" '
                f'data-target-mm="{aimed}" data-pending-mm="{waiting}" '
                f'data-motors="{"still" if note else "follow"}" '
                f'data-error-mm="{distance}" data-clearance-mm="{clear}" '
                f'data-route="{self._route_len}" style="font-size:0.85em">{body}</div>')

    def _tip(self, q: npt.ArrayLike) -> Array:
        return dk.tip_position(self.robot, np.asarray(q))
