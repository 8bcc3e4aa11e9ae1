"""Control panel (soft arm): the 100 Hz closed loop on the simulated arm, grasp-and-place, STOP.

:class:`~hw_bridge.soft_arm_process.ControlProcess` runs the seeded simulated arm, the
control stack, the planner process and the real-time :class:`hw_bridge.loop.LoopRunner` thread
in a child process (the console's own threads would delay a loop thread here); ``serve.py``
starts it and hands it over as ``app.services.soft_control``. The panel only sends commands
(applied by the loop at its next tick) and reads the newest published view, never locks.

Widgets: Arm / Disarm, what Execute acts on, *Execute grasp-and-place*, *Click to grasp*,
*Clear table into bin* (every object to the placed bin, :mod:`console.panels.soft_arm.control_row`), the
state machine's state and reason, a hardware fault in bold (every browser is told once; nothing
re-arms until the operator does), one line of link health (device, lifecycle state, armed, round
trip p99, lost demands), measured vs target kappa per segment in numbers, and the live plots of
:mod:`console.panels.soft_arm.control_plots` (tracking error per segment, loop timing); the last
four sit in the folder *Loop diagnostics*, collapsed, so Arm and Execute sit right below the
Grasp planner's *Plan grasp* at the top of Operate. STOP is the
header's (any client; it runs the console core's ``stop_motion``, which freezes the arm whether or
not this panel exists).

What Execute and *Click to grasp* act on (the Objects panel's selected object, the Grasp
planner's plan for it) is :mod:`console.panels.soft_arm.control_execute`. While armed the 3D view shows
the measured arm; jog commands reach the loop as moves through the console core (when no task
runs: ``console.core.arm_supervisor.SoftArmSupervisor``), not through this panel. The render thread only runs on new arm states (none while disarmed), so the pump refreshes the text
itself when ``on_state`` has been quiet.
"""

from __future__ import annotations

import html
import threading
import time
from typing import Any

import numpy as np
import viser

from console.recording.lab_feed import ControlFeed
from console.core.arm_status import loop_trouble
from console.panels.common.base import Panel, operator_only
from console.panels.common.loop_header import LoopSource, news_of
from console.panels.common.steady_figures import RTT_BAND, SteadyFigure
from console.panels.soft_arm.control_execute import ExecuteControls
from console.panels.soft_arm.control_plots import ControlPlots
from console.panels.soft_arm.control_progress import ProgressControls
from console.panels.soft_arm.control_row import RowControls
from console.core.run_state import RunView, run_of
from core.control.run_estimate import LegTimer
from console.panels.soft_arm.control_text import (
    IDLE_PHASES,
    fault_markdown,
    header_link,
    header_phase,
    kappa_html,
    link_line,
    loop_line,
    state_html,
    table_point,
)
from console.core.state import ArmState
from console.panels.common.events import client_of
from hw_bridge.link_supervisor import DISCONNECTED
from hw_bridge.soft_arm_process import ControlProcess, ControlView

OBJECT_COLOR = (60, 170, 90)
FINGER_COLOR = (235, 130, 30)
PUMP_HZ = 30.0  # the control process publishes at 30 Hz: what the 3D arm can draw per second
PUMP_POLL_S = 0.004  # how often the pump looks for a new view
PLOT_HZ = 4.0
TABLE_HZ = 2.0  # the kappa table follows the drawn arm at most at this rate
LOOP_BAND = (0.5, 0.1)  # the loop line's p99s follow the measured ones past 50 % and 0.1 ms
HISTORY_S = 10.0
STATS_TICKS = 1000


__all__ = ["ControlPanel", "control_for", "fault_markdown", "header_link", "header_phase",
           "kappa_html", "link_line", "state_html", "table_point"]


def kappa_html_key(c: Any) -> tuple[Any, ...]:
    """What of a telemetry sample the κ table shows at once: the targets (as printed; none
    while disarmed) and whether a measurement exists."""
    targets = tuple(f"{v:+.2f}" for v in c.kappa_ref) if c.armed else None
    return (targets, c.kappa_meas is None)


def control_for(app: Any) -> ControlProcess:
    """``app.services.soft_control``, the soft arm's control process (serve.py starts it)."""
    ctl = app.services.soft_control
    if ctl is None:
        raise ValueError("the Control panel needs the soft arm's control process: build the "
                         "console with services=ConsoleServices(soft_control=ControlProcess(...))"
                         " (serve.py does)")
    return ctl


class ControlPanel(Panel):
    """Arm, Execute, STOP, click-to-grasp, state and live plots for the soft arm."""

    title = "Control"
    order = 3.0  # right below the Grasp planner's Plan grasp: Plan, Arm, Execute together
    kinds = ("planar",)

    def build(self) -> None:
        self.ctl = control_for(self.app)  # first: without a control process, no widgets either
        gui = self.gui
        r0 = self.app.robot.capture.nominal_object_radius
        self.state_md = gui.add_markdown("**State:** –")
        self.fault_md = gui.add_markdown("", visible=False)
        # The running task's progress bar and time left, right under the state: on screen at
        # 1600 x 1000 while the arm runs (below Execute and the row's line it was not).
        self.progress = ProgressControls(gui)
        self.arm_btn = gui.add_button("Arm", color="red", icon=viser.Icon.POWER)
        self.disarm_btn = gui.add_button("Disarm", icon=viser.Icon.HAND_STOP,
                                         disabled=True)  # until a view says armed
        self.execute = ExecuteControls(self)  # what Execute acts on, Execute, Click to grasp
        self.row = RowControls(self)  # "Clear table into bin" and the row's status
        self._timer = LegTimer(self.app.robot)  # times the plan's legs (this panel's threads)
        # Diagnostics (link health, κ numbers, loop statistics, the live plots) are folded: the
        # header already shows the link and phase, and a demo needs Plan, Arm and Execute.
        self.diagnostics = gui.add_folder("Loop diagnostics", expand_by_default=False)
        with self.diagnostics:
            self.link_md = gui.add_markdown("<small>link: –</small>")
            self.kappa_md = gui.add_markdown("")
            self.loop_md = gui.add_markdown("<small>loop: –</small>")
            self.plots = ControlPlots(gui, self.app.robot.n_segments,
                                      int(HISTORY_S * PUMP_HZ))
        scene = self.app.server.scene
        self.obj_mesh = scene.add_cylinder("/control/object", radius=r0, height=0.03,
                                           color=OBJECT_COLOR, position=(0.0, 0.0, 0.015),
                                           visible=False)
        self.finger = scene.add_line_segments("/control/finger", np.zeros((1, 2, 3)),
                                              FINGER_COLOR, thickness=0.012, visible=False)

        self.arm_btn.on_click(operator_only(lambda e: self._arm(e), panel=self,
                                            action="arm the arm"))
        self.disarm_btn.on_click(operator_only(lambda e: self._disarm(e), panel=self,
                                               action="disarm the arm"))

        self._plot_at = 0.0
        self._table_at = 0.0
        self._table_key: Any = None
        # What the link and loop lines show of jittering measurements (a still console's
        # lines then stay put and cost viewers nothing):
        self._rtt_p99 = SteadyFigure(*RTT_BAND)
        self._period_p99, self._work_p99 = SteadyFigure(*LOOP_BAND), SteadyFigure(*LOOP_BAND)
        self._reported: ControlView | None = None  # the view last reported to the store
        self._last_fault: str | None = None
        self._feed = ControlFeed(  # phase, timing, faults (+ link health) -> lab data
            self.app.recorder, lambda: self.app.services.bridge_controls is not None)
        self._told_died = False
        self._draw_lock = threading.Lock()
        self._pump_stop = threading.Event()
        self._pump = threading.Thread(target=self._pump_loop, name="control-pump", daemon=True)
        self._pump.start()

    # -- callbacks (thin: enqueue to the loop) -----------------------------------------------
    def _arm(self, event: Any = None) -> None:
        # An operator action in recordings (/operator/actions): the replay's log says who armed.
        self.app.recorder.action("arm pressed", client_of(event))
        fut = self.app.core.start_motion(self.ctl.arm)  # a refusal (link down, Disconnected) is told to this operator
        fut.add_done_callback(lambda f: self.report_done(event, f))

    def _disarm(self, event: Any = None) -> None:
        self.app.recorder.action("disarm pressed", client_of(event))
        fut = self.ctl.disarm()
        fut.add_done_callback(lambda f: self.report_done(event, f))

    def refuse_action(self, event: Any, title: str, message: str) -> None:
        self.app.show_refusal(client_of(event), title, message)

    def is_disarmed(self) -> bool:
        view = self.ctl.view
        c = None if view is None else view.snapshot.control
        return c is None or not c.armed

    def report_done(self, event: Any, fut: Any) -> None:
        exc = fut.exception()
        if exc is not None:
            self.app.show_refusal(client_of(event), "Refused", str(exc))

    # -- the pump: loop snapshot -> view, history, the measured arm to the store ---------------
    def _pump_loop(self) -> None:
        # Each new view as it arrives (polled every PUMP_POLL_S: a reference check), else at
        # PUMP_HZ: pumping on a timer of its own at the publish rate, the pump and the publisher
        # drifted through each other and one view in several was never drawn.
        period = 1.0 / PUMP_HZ
        last, last_at = None, 0.0
        while not self._pump_stop.wait(PUMP_POLL_S):
            view, now = self.ctl.view, time.monotonic()
            if view is last and now - last_at < period:
                continue
            last, last_at = view, now
            try:
                self._pump_once()
            except Exception:  # never let a display hiccup end the pump
                time.sleep(0.5)

    def _died(self) -> str | None:
        """Why the control process ended on its own (None while it runs or closed cleanly)."""
        failure = getattr(self.ctl, "failure", None)
        return failure if failure and not getattr(self.ctl, "alive", True) else None

    def _pump_once(self) -> None:
        died = self._died()
        if died:
            if not self._told_died:  # once: the panel shows it from now on
                self._told_died = True
                self.app.notify_all("Control process died", f"{died}. The arm is not commanded "
                                    "(the device's watchdog stops it); the operator can press "
                                    "Restart control loop (Hardware tab).", color="red")
                self.app.recorder.action(f"control process died: {died}", None)
                self._refresh()
            return
        self._told_died = False  # running (again, after a restart): a next death is told too
        view = self.ctl.view
        c = None if view is None else view.snapshot.control
        self._feed.on_view(view)
        if view is not None:
            self._notify_fault(view.fault)
        if time.monotonic() - self._plot_at > 2.0 / PLOT_HZ:
            self._refresh()  # the render thread is idle (no new arm state): show the view anyway
        if c is None:
            return
        snap = view.snapshot
        nothing = np.full(len(c.kappa_ref), np.nan)
        meas = c.kappa_meas if c.kappa_meas is not None else nothing
        # Disarmed, the loop's reference is its measurement (so that arming starts from where
        # the arm is): no target, no tracking error, and its noise no news for viewers.
        ref = c.kappa_ref if c.armed else nothing
        self.plots.append(c.t, ref, meas, c.phase, snap.period_ms, snap.work_ms)
        store = self.app.store
        if c.armed and c.kappa_meas is not None:
            if view is not self._reported:
                # Each measurement once: a view pumped again (none newer in time) reported
                # twice reads to the 3D view as an arm that stopped exactly there, and a still
                # arm's noise got drawn.
                self._reported = view
                store.report(c.kappa_meas, "control")

    def _notify_fault(self, fault: str | None) -> None:
        """Tell every browser once when a new hardware fault appears (not the operator's
        own Disconnect); a fault that clears and comes back is told again. With the Hardware
        panel's controls (``app.services.bridge_controls``) it tells them instead: one
        notification."""
        if fault == self._last_fault:
            return
        self._last_fault = fault
        if self.app.services.bridge_controls is not None:
            return
        if fault and fault != DISCONNECTED:
            self.app.notify_all("Hardware fault",
                                f"{fault}. The arm is not commanded; the operator must re-arm.",
                                color="red")
            self.app.recorder.action(f"hardware fault: {fault}", None)

    def on_state(self, state: ArmState) -> None:
        if time.monotonic() - self._plot_at >= 1.0 / PLOT_HZ:
            self._refresh()

    def _refresh(self) -> None:
        """Show the newest view (render thread, or the pump while the render thread idles)."""
        if not self._draw_lock.acquire(blocking=False):
            return
        try:
            self._plot_at = time.monotonic()
            self._show(self.ctl.view)
        finally:
            self._draw_lock.release()

    def _trouble(self) -> str | None:
        """Why the newest view is not the arm's state now (dead, or silent for more than
        ``STALE_AFTER_S``): None while it is fresh (:func:`console.core.arm_status.loop_trouble`)."""
        if not isinstance(self.ctl, LoopSource):  # a stand-in without a process (tests)
            return None
        return loop_trouble(news_of(self.ctl))

    def _show(self, view: ControlView | None) -> None:
        died = self._died()
        trouble = self._trouble() if view is not None else None
        if died or trouble:
            self.state_md.content = (
                f"**Control process died:** {died}. The arm is not commanded; press **Restart "
                "control loop** (Hardware tab)." if died else
                f"**{trouble[:1].upper() + trouble[1:]}:** what is shown below is not the arm "
                "now.")
            # What the last view said is no longer true: never leave ARMED or active showing.
            self.link_md.content = f"<small>link: unknown ({html.escape(died or trouble)})</small>"
            self.loop_md.content = "<small>loop: not running</small>" if died else \
                f"<small>loop: {html.escape(trouble)}</small>"
            for btn in (self.arm_btn, self.disarm_btn, self.execute.execute_btn, self.row.button):
                btn.disabled = True
            self._show_run(None)  # the loop's view is not the arm now: no plan drawn as running
            return
        if view is None:
            failure = getattr(self.ctl, "failure", None)
            self.state_md.content = ("**State:** starting the control process…" if not failure
                                     else f"**Control process failed:** {failure}")
            return
        c = view.snapshot.control
        self.state_md.content = state_html(view, self.execute.target)
        target = self.execute.target
        run = self._show_run(view)
        shown = self.app.loop_header or self.app.header  # the loop header checks the view's age
        phase, tone = self.row.header(view) or header_phase(view, target)
        known = run is not None and run.row_remaining_s is not None  # else: no time to tell
        shown.show("phase", f"{phase} · {run.time_text()}" if known else phase, tone)
        self.row.show(view)
        self.execute.show(view)  # a released single grasp's object leaves the table
        shown.show("link", *header_link(view))
        if c is not None:
            busy = c.phase not in IDLE_PHASES + ("settling",)
            self.execute.execute_btn.disabled = busy
            # Arm while armed would only restart the stack; after a fault it is the way back.
            self.arm_btn.disabled = c.armed and not view.fault
            self.disarm_btn.disabled = not c.armed
        fault = fault_markdown(view.fault)
        self.fault_md.content = fault
        self.fault_md.visible = bool(fault)
        # (viser sends a text only when it changed: a steady loop's lines cost nothing)
        h = view.link
        self.link_md.content = link_line(
            view, self._rtt_p99.shown(None if h is None else h.rtt_ms_p99))
        if len(self.plots.hist) < 2:  # else the table is redrawn with the plot (_draw_plots)
            self.kappa_md.content = kappa_html(view)
        st = view.stats
        self.loop_md.content = loop_line(
            view.scheduling, st.ticks, st.overruns, STATS_TICKS / 100.0,
            self._period_p99.shown(st.period_error_ms_p99), self._work_p99.shown(st.work_ms_p99))
        self._draw_scene(view)
        self._draw_plots()

    def _show_run(self, view: ControlView | None) -> RunView | None:
        """What the arm runs, from the loop's view: to the grasp session (the 3D view and the
        Waypoints panel draw it from there) and to the progress bar and line."""
        run = None
        if view is not None:
            sent = self.row.sent_for(view.row)
            target = self.execute.target
            run = run_of(view, self.app.robot, self._timer,
                         None if sent is None else sent.names,
                         None if target is None else target.name)
        self.app.soft_arm_grasp().set_run(run)
        self.progress.show(run)
        return run

    def _draw_scene(self, view: Any) -> None:
        c = view.snapshot.control
        if view.object_xy is not None:
            self.obj_mesh.position = (view.object_xy[0], view.object_xy[1], 0.015)
            self.obj_mesh.radius = float(view.object_radius)
        self.obj_mesh.visible = view.object_xy is not None
        if view.finger is not None and c is not None and c.armed:
            line = view.finger[1:]
            pts = np.column_stack([line, np.full(len(line), self.app.robot.half_width)])
            self.finger.points = np.stack([pts[:-1], pts[1:]], axis=1)
            self.finger.visible = True
        else:
            self.finger.visible = False
        # The 3D arm's pleated gripper curls while the loop commands it closed.
        self.app.view.set_gripper_closed(c is not None and c.armed and c.gripper_closed)

    def _draw_plots(self) -> None:
        if len(self.plots.hist) < 2:
            return
        now = time.monotonic()
        view = self.ctl.view
        c = None if view is None else view.snapshot.control
        # The κ table follows the drawn arm (at most TABLE_HZ): its measured row changes when
        # the 3D view sent a new frame (a still arm's measurement noise stays inside the view's
        # dead band and costs viewers nothing) or, disarmed (the 3D arm is not the measured
        # one then), when the error plot was redrawn for a measurement that moved; its target
        # row whenever a target changes.
        self.plots.draw(now)
        follows = self.app.view.frames_sent if c is not None and c.armed else self.plots.redraws
        key = None if c is None else (kappa_html_key(c), follows)
        if now - self._table_at >= 1.0 / TABLE_HZ and key != self._table_key:
            self._table_at, self._table_key = now, key
            table = kappa_html(view) if view else ""
            if table != self.kappa_md.content:
                self.kappa_md.content = table

    def close(self) -> None:
        self._pump_stop.set()
        self.ctl.close()
        super().close()
