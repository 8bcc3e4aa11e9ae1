"""Path panel: pick a Fig. 9 path, preview its tip trace and ghost arms, execute it on the motors.

The path (linear / diagonal traverse, four corners; size, plane, tip speed <= the robot's
``tip_speed``) is centred on the arm's current tip and planned from the commanded posture by
``core.planning.paths.plan_path`` in a worker *process* (planning takes seconds of CPU; in this
process it would hold the GIL against the 100 Hz loop). The preview draws the planned tip trace
and a few translucent ghost arms (``console.panels.extensible.path_scene``). Execute streams the path
through the :class:`~hw_bridge.extensible_process.ExtensibleProcess` (``app.services.extensible_runner``,
started on first use; it first joins the path from where the motors are). While it runs the
panel shows the progress, the measured tip trace and a plot of the commanded and the measured
tip's distance to the path target (mm). Preview, Execute and Reconnect are operator-only; Stop is the
header's STOP (any client; the console core's one STOP), which makes the runner hold position, as
does a lost lease. An Execute that waits for its plan is the core's expected motion
(:data:`EXECUTE_ONCE_PLANNED`): any STOP meanwhile cancels it.

Preview answers at once: the requested tip path is drawn while the worker plans, the status
counts the seconds, and a plan that has not come back within ``PLAN_TIMEOUT_S`` is reported as
such (the worker is replaced); a failed plan or drawing says why. The worker processes (this
planner and the tip target's IK) start when a browser opens, not on the first request. The
"Hardware:" line and the tip target's warnings read the link supervisor's health (the same
source as the Hardware panel and the header's Link field); this panel pushes the header's Phase
field for the extensible arm: idle, moving to target, running path t/T s, holding after STOP,
fault. With box obstacles (the Obstacles panel) the plan keeps the arm's whole body their
clearance away along the whole motion, or says why it cannot ("blocked", naming the box).
"""

from __future__ import annotations

import html
import threading
import time
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np
import numpy.typing as npt
import viser
import viser.uplot as uplot

from console.panels.common.header import Tone
from console.recording.lab_feed import path_plan_record
from console.panels.common.base import Panel
from console.panels.extensible.status import (extensible_arm, extensible_runner, hardware_html,
                                              runner_phase)
from console.panels.extensible.worker_pool import WorkerPool
from console.panels.extensible.obstacles_boxes import box_scene_of
from console.panels.extensible.path_request import PathRequest, PendingPlan
from console.panels.extensible.path_scene import PathScene, trail_tail
from console.panels.common.plot_data import thin
from console.core.state import ArmState
from core.units import fmt_mm
from core.kinematics import delta as dk
from core.planning.paths import PATH_KINDS, BlockedPath, MotionPath, build_path, plan_path
from hw_bridge.extensible_jobs import JobResult
from hw_bridge.extensible_process import ExtensibleProcess

Array = npt.NDArray[np.float64]
MAX_EXECUTE_ERROR = 0.002  # m: refuse a path whose planned tip leaves its target by more
PLOT_HZ = 5.0
PLAN_TIMEOUT_S = 30.0  # s: a Fig. 9 path plans in 2-5 s unloaded, 10-25 s on a busy 2-core box
STATUS_HZ = 2.0  # planning seconds, Hardware line and the header's Phase field
TRAIL_S = 30.0  # the measured tip trace shows at most the run's last this many seconds
EXECUTE_ONCE_PLANNED = "paths: execute once planned"  # the core's expected motion


class PathsPanel(Panel):
    """Path choice, preview, execute / stop, progress and tip-error plot."""

    title = "Paths"
    order = 3.0  # right below the tip target
    kinds = ("delta",)

    def build(self) -> None:
        v_max = extensible_arm(self.app).tip_speed * 1e3
        gui = self.gui
        self.kind = gui.add_dropdown(
            "Path", PATH_KINDS, initial_value="linear",
            hint="Fig. 9: linear traverse, diagonal traverse, four corners.")
        self.plane = gui.add_dropdown("Plane", ("xy", "xz", "yz"), initial_value="xy")
        self.size = gui.add_number(
            "Size (mm)", 80.0, min=5.0, max=400.0, step=1.0,
            hint="Traverse length / square side, centred on the current tip.")
        self.speed = gui.add_slider(
            "Tip speed (mm/s)", min=5.0, max=v_max, step=1.0, initial_value=min(50.0, v_max),
            hint=f"At most the tip speed limit, {v_max:.0f} mm/s (Table I).")
        self.preview_btn = gui.add_button("Preview", icon=viser.Icon.EYE)
        self.execute_btn = gui.add_button("Execute", color="green", icon=viser.Icon.PLAYER_PLAY)
        self.reconnect_btn = gui.add_button(
            "Reconnect hardware", icon=viser.Icon.PLUG_CONNECTED,
            hint="Connect (after a fault: reconnect) and arm the motors; the arm holds still.")
        self.hardware = gui.add_html(hardware_html(self.app))
        self.progress = gui.add_progress_bar(0.0, color="blue")
        self.status = gui.add_html(self._status("Preview a path, then Execute.", "idle"))
        self.plot = gui.add_uplot(
            data=(np.zeros(2), np.zeros(2), np.zeros(2)),
            series=(uplot.Series(label="t (s)"),
                    uplot.Series(label="commanded (mm)", stroke="#1c7ed6", width=2),
                    uplot.Series(label="measured (mm)", stroke="#e8590c", width=2)),
            scales={"x": uplot.Scale(time=False)},
            axes=(uplot.Axis(label="t (s)"), uplot.Axis(label="mm")),
            title="Tip distance to the path target", aspect=1.6)
        self.drawing = PathScene(self.app.server.scene)  # trace, waypoints, ghosts, measured
        self._lock = threading.Lock()
        self._pool: WorkerPool | None = None
        self._planned: tuple[PathRequest, MotionPath] | None = None
        self._planning: PendingPlan | None = None
        self._job = 0
        self._plot_at = 0.0
        self._quit = threading.Event()
        self.preview_btn.on_click(self.operator_only(
            lambda _: self._request_plan(execute=False), "preview a path"))
        self.execute_btn.on_click(self.operator_only(self._on_execute, "execute a path"))
        self.reconnect_btn.on_click(self.operator_only(lambda _: self._reconnect(),
                                                       "connect the hardware"))
        self.app.server.on_client_connect(lambda _: self._warm_up())
        threading.Thread(target=self._status_loop, daemon=True, name="paths-status").start()

    def _warm_up(self) -> None:
        """Start the planner worker when a browser opens (importing the planner takes seconds
        on a busy machine; the first Preview should not wait for it)."""
        try:
            self._plan_pool().submit(build_path, "linear", np.zeros(3), 0.01, "xy")
        except RuntimeError:  # shut down (console closing)
            pass

    @property
    def runner(self) -> ExtensibleProcess:
        """The console's runner (``app.services.extensible_runner``; serve.py builds it)."""
        return extensible_runner(self.app)

    # -- callbacks -------------------------------------------------------------------------
    def _current_request(self) -> PathRequest:
        q = np.asarray(self.app.store.command.q, dtype=float)
        return PathRequest(str(self.kind.value), str(self.plane.value),
                           float(self.size.value) / 1e3, float(self.speed.value) / 1e3,
                           tuple(np.round(q.ravel(), 9)), box_scene_of(self.app)[1])

    def _request_plan(self, execute: bool) -> None:
        try:
            req = self._current_request()
            robot: Any = self.app.robot
            q = np.array(req.start).reshape(robot.n_segments, 3)
            kind: Any = req.kind
            plane: Any = req.plane
            waypoints = build_path(kind, dk.tip_position(robot, q), req.size, plane)
        except ValueError as exc:
            self._set_status(f"⚠ {exc}", "error")
            return
        core = self.app.core
        with self._lock:
            if execute:
                core.expect_motion(EXECUTE_ONCE_PLANNED)
            else:  # a Preview replaces a pending Execute
                core.drop_expected(EXECUTE_ONCE_PLANNED)
            if self._planning is not None and self._planning.req == req:
                return  # already planning this one (its status counts the seconds)
        self.drawing.draw_requested(waypoints)
        pool = self._plan_pool()
        scene, _ = box_scene_of(self.app)
        try:
            future = pool.submit(plan_path, self.app.robot, waypoints, speed=req.speed,
                                 start_delta=q, boxes=scene.boxes, clearance=scene.clearance)
        except (RuntimeError, BrokenProcessPool) as exc:
            self._drop_pool(pool)
            self._set_status(f"⚠ Planning failed: the planner worker is gone ({exc}); "
                             "Preview again.", "error")
            return
        planning = PendingPlan(req, waypoints, future, time.perf_counter())
        with self._lock:
            self._planning = planning
        self._show_planning(planning)
        future.add_done_callback(lambda f: self._on_planned(planning))

    def _on_execute(self, event: viser.GuiEvent) -> None:
        req = self._current_request()
        self.app.recorder.action("execute path", event.client, kind=req.kind, plane=req.plane,
                                 size_m=req.size, speed_mps=req.speed)
        planned = self._planned
        if planned is not None and planned[0] == req:
            self._execute(planned[1])
        else:
            self._request_plan(execute=True)

    def _reconnect(self) -> None:
        runner = self.runner
        future = runner.connect() if runner.started else runner.start().connecting
        self.hardware.content = hardware_html(self.app, "connecting…")

        def show() -> None:
            try:
                if future is not None:  # None: another thread's start() is connecting
                    future.result(timeout=10.0)
                time.sleep(3 * runner.period_s)  # the snapshot trails by a tick
            finally:
                self.hardware.content = hardware_html(self.app)
        threading.Thread(target=show, daemon=True, name="hw-connect").start()

    # -- workers ---------------------------------------------------------------------------
    def _plan_pool(self) -> WorkerPool:
        with self._lock:
            if self._pool is None:
                self._pool = WorkerPool()
            return self._pool

    def _drop_pool(self, pool: WorkerPool) -> None:
        """A broken or stuck worker: a new one on the next request."""
        with self._lock:
            if self._pool is pool:
                self._pool = None
        pool.terminate()  # stuck in a plan: shutdown alone would leave it computing

    def _on_planned(self, planning: PendingPlan) -> None:
        """Worker callback: draw the plan and say what it is, or why there is none."""
        with self._lock:
            if self._planning is not planning:
                return  # timed out (already reported) or replaced
            self._planning = None
        execute = self.app.core.is_expected(EXECUTE_ONCE_PLANNED)  # (a STOP since: False)
        try:
            self._show_plan(planning, execute)
        except Exception as exc:  # noqa: BLE001 - a done-callback's exception would be lost
            self.app.core.drop_expected(EXECUTE_ONCE_PLANNED)
            self._set_status(f"⚠ Planning failed: {type(exc).__name__}: {exc}", "error")

    def _show_plan(self, planning: PendingPlan, execute: bool) -> None:
        req, waypoints = planning.req, planning.waypoints
        try:
            path: MotionPath = planning.future.result()
        except Exception as exc:  # noqa: BLE001 - bad input or a broken worker: say so
            pool = self._pool
            if isinstance(exc, BrokenProcessPool) and pool is not None:
                self._drop_pool(pool)
            blocked = isinstance(exc, BlockedPath)
            self.app.core.drop_expected(EXECUTE_ONCE_PLANNED)  # nothing to execute
            self._set_status(f"⚠ {'Blocked by the boxes' if blocked else 'Planning failed'}: "
                             f"{exc or type(exc).__name__}", "blocked" if blocked else "error")
            return
        self._planned = (req, path)
        self.app.recorder.log("plan", path_plan_record(req, waypoints, path))  # lab data
        self.drawing.draw_preview(path, waypoints, self.app.view)
        ok = path.max_error <= MAX_EXECUTE_ERROR
        summary = (f"{req.kind} {fmt_mm(req.size, 0)} mm in {req.plane} at "
                   f"{fmt_mm(req.speed, 0)} mm/s: {path.duration:.1f} s, {len(path.times)} samples, "
                   f"max planned tip error {fmt_mm(path.max_error, 2)} mm, {path.jumps} jumps"
                   + (f", arm ≥ {fmt_mm(path.clearance, 1)} mm from box "
                      f"'{path.nearest_box}'" if path.nearest_box else ""))
        if not ok:
            self.app.core.drop_expected(EXECUTE_ONCE_PLANNED)
            self._set_status(f"⚠ {summary}. The path leaves the reachable workspace: shrink it "
                             "or move the arm.", "infeasible")
        elif execute:
            self._execute(path, once_planned=True)
        else:
            self._set_status(f"Preview: {summary}.", "previewed")

    def _execute(self, path: MotionPath, once_planned: bool = False) -> None:
        """Run ``path`` on the runner; ``once_planned``: the Execute that waited for this plan
        (the core's expected motion: not if a STOP came meanwhile)."""
        core, jobs = self.app.core, []
        if path.max_error > MAX_EXECUTE_ERROR:
            core.drop_expected(EXECUTE_ONCE_PLANNED)
            self._set_status("⚠ This path leaves the reachable workspace; not executed.", "error")
            return
        runner = self.runner.start()
        if runner.snapshot.busy:
            core.drop_expected(EXECUTE_ONCE_PLANNED)
            self._set_status("⚠ A job is running: stop it first.", "error")
            return
        if runner.snapshot.state in ("disarmed", "disconnected"):  # never armed behind the
            core.drop_expected(EXECUTE_ONCE_PLANNED)
            self._set_status("⚠ Not executed: arm first (Hardware tab: Arm device); "  # back
                             "connecting never arms the arm.", "error")
            return
        start = lambda: jobs.append(runner.execute(path, "path"))  # noqa: E731
        if once_planned:
            if not core.run_expected(EXECUTE_ONCE_PLANNED, start):
                self._set_status("Preview: planned; not executed (stopped meanwhile).", "stopped")
                return
        else:
            core.start_motion(start)
        self._job = job = jobs[0]
        self.hardware.content = hardware_html(self.app)
        self._set_status(f"Executing ({path.duration:.1f} s)…", "running")
        # Frames come while the arm moves; this shows the end even if nothing is redrawn then.
        threading.Thread(target=self._watch, args=(runner, job), daemon=True,
                         name="path-watch").start()

    # -- display ---------------------------------------------------------------------------
    def _show_planning(self, planning: PendingPlan) -> None:
        """Planning status with its seconds; past ``PLAN_TIMEOUT_S`` say so and give up."""
        waited = time.perf_counter() - planning.started
        if waited >= PLAN_TIMEOUT_S:
            with self._lock:
                if self._planning is not planning:
                    return
                self._planning = None
                pool = self._pool
            self.app.core.drop_expected(EXECUTE_ONCE_PLANNED)
            if pool is not None:
                self._drop_pool(pool)
            self._set_status(f"⚠ Planning gave no answer within {PLAN_TIMEOUT_S:.0f} s (the "
                             "planner worker is busy or stuck; it was restarted). The drawn "
                             "line is only the requested path: Preview again.", "error")
            return
        self._set_status(f"Planning… {waited:.0f} s (the requested tip path is drawn; the "
                         "arm's motion follows when planned)", "planning", drawn="requested")

    def clear_trails(self) -> None:
        """Hide the measured tip trace of the last run (the View panel's "Clear trails")."""
        self.drawing.clear_trails()

    def _set_status(self, text: str, state: str, drawn: str = "") -> None:
        self.status.content = self._status(text, state, drawn)

    @staticmethod
    def _status(text: str, state: str, drawn: str = "") -> str:
        mark = f' data-drawn="{drawn}"' if drawn else ""
        return (f'<div data-testid="path-status" data-state="{state}"{mark} '
                f'style="font-size:0.85em">{html.escape(text)}</div>')

    def phase(self) -> tuple[str, Tone]:
        """The header's Phase field for the extensible arm (what the runner is doing)."""
        runner = self.app.services.extensible_runner
        snap = runner.snapshot if runner is not None and runner.started else None
        moving = self.app.core.hold.target() is not None
        period = runner.period_s if runner is not None else 0.01
        return runner_phase(snap, period, self._job, moving, self.app.core.holding_after_stop)

    def show_phase(self) -> None:
        """Push :meth:`phase` to the header (it sends only changes)."""
        if not self.app.stopped:  # (the loop header checks the view's age)
            (self.app.loop_header or self.app.header).show("phase", *self.phase())

    def _status_loop(self) -> None:
        """Worker: planning seconds (and timeout), the Hardware line and the Phase field,
        also while no frame is drawn (an idle arm draws none)."""
        shown = ""
        while not self._quit.wait(1.0 / STATUS_HZ) and not self.app.stopped:
            try:
                planning = self._planning
                if planning is not None:
                    self._show_planning(planning)
                self.show_phase()
                page = hardware_html(self.app)
                if page != shown:
                    shown = self.hardware.content = page
            except Exception:  # noqa: BLE001 - a display hiccup must not end the thread
                time.sleep(1.0)

    def close(self) -> None:
        self._quit.set()
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        super().close()

    def on_state(self, state: ArmState) -> None:
        self.show_phase()
        runner = self.app.services.extensible_runner
        if runner is not None and runner.started:  # (the mock's connects on the first Execute)
            self._show_job(runner)

    def _show_job(self, runner: ExtensibleProcess, result: JobResult | None = None) -> None:
        """Progress, plot and measured trace of the panel's job; its outcome once ``result``."""
        job = self._job
        if job == 0:
            return
        snap = runner.snapshot
        n, trace = snap.trace_count, snap.trace
        now = time.perf_counter()
        if snap.job_id == job:
            self.progress.value = round(100.0 * snap.progress, 1)
            if trace is not None and n >= 2 and (now - self._plot_at >= 1.0 / PLOT_HZ or result):
                self._plot_at = now
                target = trace.targets[:n]
                self.plot.data = thin((trace.times[:n],
                                       np.linalg.norm(trace.commanded[:n] - target, axis=1) * 1e3,
                                       np.linalg.norm(trace.measured[:n] - target, axis=1) * 1e3))
                m = trail_tail(trace.times[:n], trace.measured[:n], TRAIL_S)
                if len(m) >= 2:
                    self.drawing.draw_measured(m)
        if result is None:
            return
        self._job = 0
        self.hardware.content = hardware_html(self.app)
        self.show_phase()
        if result.ok:
            self._set_status(f"Done: final tip {fmt_mm(result.error or 0.0, 2)} mm from the "
                             "path's end.", "done")
        elif snap.fault:
            self._set_status(f"⚠ Hardware fault: {snap.fault}. Commanding stopped.", "fault")
        else:
            self._set_status(f"⚠ {result.message}.", "stopped")

    def _watch(self, runner: ExtensibleProcess, job: int) -> None:
        """Worker: wait for the job's end, then show it (no frame may follow it)."""
        result = runner.wait(job)
        deadline = time.perf_counter() + 1.0
        while runner.snapshot.busy and time.perf_counter() < deadline:
            time.sleep(runner.period_s)  # the snapshot trails the result by a tick
        if result is not None:
            self._show_job(runner, result)
