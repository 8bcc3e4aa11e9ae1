"""Control panel (soft arm): the 100 Hz closed loop on the simulated arm, grasp-and-place, STOP.

:class:`~hw_bridge.soft_arm_process.ControlProcess` runs the seeded simulated arm, the
control stack, the planner process and the real-time :class:`hw_bridge.loop.LoopRunner` thread
in a child process (the console's own threads would delay a loop thread here); ``serve.py``
starts it and hands it over as ``app.services.soft_control``. The panel only sends commands
(applied by the loop at its next tick) and reads the newest published view, never locks.

Widgets: Arm / Disarm, object x, y, r and *Place object*, *Execute* (the full grasp-and-place
for the placed object: settle, plan in the planner process, approach, grasp, carry, release),
*Click to grasp* (one click on the table places the object there and runs it all), STOP (any
client, also the Session panel's hotkey: it runs ``app.stop_motion``, whose hook freezes the
arm), the state machine's state and reason, a hardware fault in bold (every browser is told
once; nothing re-arms until the operator does), one line of link health (device, lifecycle
state, armed, round trip p99, lost demands), measured vs target kappa per segment in numbers,
and live uPlots of kappa target vs measured and of the loop's period and tick time. While armed
the 3D view shows the measured arm; jog commands from other panels are forwarded as moves when
no task runs. The render thread only runs on new arm states (none while disarmed), so the pump
refreshes the text itself when ``on_state`` has been quiet.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from typing import Any

import numpy as np
import viser
from viser import uplot

from console.lab_feed import ControlFeed
from console.panels.base import Panel, operator_only
from console.panels.control_text import (IDLE_PHASES, fault_markdown, header_link, header_phase,
                                         kappa_html, link_line, state_html, table_point)
from console.panels.plot_data import thin
from console.plan_view import TableObject, validate_object
from hw_bridge.link_supervisor import DISCONNECTED
from hw_bridge.soft_arm_process import ControlProcess, ControlView
from console.state import ArmState

SEGMENT_COLORS = ("#1c7ed6", "#e8590c", "#2f9e44", "#ae3ec9", "#f08c00", "#0c8599")
OBJECT_COLOR = (60, 170, 90)
FINGER_COLOR = (235, 130, 30)
PUMP_HZ = 20.0
PLOT_HZ = 4.0
# The curvature plot has 13 series, which viser sends as float64: 60 points, at most 2 Hz,
# cost ~12 KB/s per viewer while the arm moves.
KAPPA_PLOT_POINTS = 60
KAPPA_PLOT_HZ = 2.0
PLOT_BAND = 0.05  # 1/m: the curvature plot is redrawn when a target moved more than this,
MEAS_BAND = 1.0  # 1/m: ... a measured curvature more than this (the sim's noise: <= 0.35 rms),
STILL_PLOT_S = 10.0  # s: ... or this long after the last redraw
COUNTERS_HZ = 1.0  # link and loop lines (their counters change on every refresh)
LOOP_PLOT_HZ = 0.2  # loop timing is noise on a still arm too: every 5 s is enough
HISTORY_S = 10.0
STATS_TICKS = 1000
FORWARD_PHASES = ("idle", "released")  # jog commands become moves only then


__all__ = ["ControlPanel", "control_for", "fault_markdown", "header_link", "header_phase",
           "kappa_html", "link_line", "state_html", "table_point"]


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
    order = 15.0
    kinds = ("planar",)

    def build(self) -> None:
        self.ctl = control_for(self.app)  # first: without a control process, no widgets either
        gui = self.gui
        r0 = self.app.robot.capture.nominal_object_radius
        self.state_md = gui.add_markdown("**State:** –")
        self.fault_md = gui.add_markdown("", visible=False)
        self.link_md = gui.add_markdown("<small>link: –</small>")
        self.arm_btn = gui.add_button("Arm", color="red", icon=viser.Icon.POWER)
        self.disarm_btn = gui.add_button("Disarm", icon=viser.Icon.HAND_STOP)
        self.obj_x = gui.add_number("Object x (m)", -0.16, step=0.005)
        self.obj_y = gui.add_number("Object y (m)", 0.28, step=0.005)
        self.obj_r = gui.add_number("Object r (m)", r0, min=0.005, max=0.05, step=0.0005)
        self.place_btn = gui.add_button("Place object", icon=viser.Icon.CIRCLE_PLUS)
        self.execute_btn = gui.add_button("Execute grasp-and-place", icon=viser.Icon.PLAYER_PLAY)
        self.plan_btn = gui.add_button("Execute current plan", icon=viser.Icon.ROUTE,
                                       hint="the Grasp planner panel's plan for its object")
        self.click_mode = gui.add_checkbox("Click to grasp", False,
                                           hint="one click on the table places the object there "
                                                "and runs the whole grasp-and-place")
        self.kappa_md = gui.add_markdown("")
        self.loop_md = gui.add_markdown("<small>loop: –</small>")
        n = self.app.robot.n_segments
        series = [uplot.Series(label="t (s)")]
        for i in range(n):
            c = SEGMENT_COLORS[i % len(SEGMENT_COLORS)]
            series.append(uplot.Series(label=f"κ{i + 1} target", stroke=c, width=1, dash=(6, 4)))
            series.append(uplot.Series(label=f"κ{i + 1} measured", stroke=c, width=2))
        self.kappa_plot = gui.add_uplot(
            data=tuple(np.zeros(2) for _ in range(1 + 2 * n)), series=tuple(series),
            scales={"x": uplot.Scale(time=False)},
            axes=(uplot.Axis(label="t (s)"), uplot.Axis(label="1/m")),
            title="Curvature: target (dashed) vs measured", aspect=1.4)
        self.loop_plot = gui.add_uplot(
            data=(np.zeros(2), np.zeros(2), np.zeros(2)),
            series=(uplot.Series(label="t (s)"),
                    uplot.Series(label="period (ms)", stroke="#1c7ed6", width=2),
                    uplot.Series(label="tick work (ms)", stroke="#e8590c", width=2)),
            scales={"x": uplot.Scale(time=False)},
            axes=(uplot.Axis(label="t (s)"), uplot.Axis(label="ms")),
            title="Control loop (100 Hz)", aspect=2.0)
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
        self.place_btn.on_click(operator_only(lambda e: self._place(e), panel=self,
                                              action="place the object"))
        self.execute_btn.on_click(operator_only(lambda e: self._execute(e), panel=self,
                                                action="run grasp-and-place"))
        self.plan_btn.on_click(operator_only(lambda e: self._execute_plan(e), panel=self,
                                             action="execute the plan"))
        scene.on_click()(self._on_scene_click)
        self.app.add_stop_hook(self._stop_hook)

        self._hist: collections.deque = collections.deque(maxlen=int(HISTORY_S * PUMP_HZ))
        self._plot_at = 0.0
        self._plotted: tuple[np.ndarray, np.ndarray] | None = None
        self._plotted_at = 0.0
        self._table_at = 0.0
        self._loop_plot_at = 0.0
        self._counters_at = 0.0
        self._link_key: Any = None
        self._fwd_seq = self.app.store.command.seq
        self._stopped = False
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
        self._fwd_seq = self.app.store.command.seq  # forward only later jog commands
        self._stopped = False
        fut = self.ctl.arm()  # a refusal (link down, Disconnected) is told to this operator
        fut.add_done_callback(lambda f: self._report(event, f))

    def _disarm(self, event: Any = None) -> None:
        fut = self.ctl.disarm()
        fut.add_done_callback(lambda f: self._report(event, f))

    def _object(self, event: Any, x: float, y: float) -> tuple[float, float, float] | None:
        """(x, y, r) of the object to grasp, or None after telling the user why (nothing is
        sent: a radius of 1e308 must not arm the arm)."""
        r = float(self.obj_r.value)
        lo, hi = float(self.obj_r.min or 0.0), float(self.obj_r.max or 0.2)
        try:
            if not all(math.isfinite(v) for v in (x, y, r)):
                raise ValueError("object position and radius must be finite numbers")
            if not lo <= r <= hi:
                raise ValueError(f"object radius must be between {lo * 1e3:g} and {hi * 1e3:g} "
                                 f"mm, got {r * 1e3:.4g} mm")
            validate_object(TableObject("object", x, y, r), self.app.robot)
        except ValueError as exc:
            client = getattr(event, "client", None)
            if client is not None:
                client.add_notification("Refused", str(exc), color="red",
                                        auto_close_seconds=8.0)
            return None
        return x, y, r

    def _place(self, event: Any = None) -> None:
        obj = self._object(event, float(self.obj_x.value), float(self.obj_y.value))
        if obj is not None:
            self.ctl.place_object(*obj)

    def _execute(self, event: Any) -> None:
        obj = self._object(event, float(self.obj_x.value), float(self.obj_y.value))
        if obj is None:
            return
        self._stopped = False
        fut = self.ctl.grasp_at(*obj)
        fut.add_done_callback(lambda f: self._report(event, f))

    def _execute_plan(self, event: Any) -> None:
        from console.panels.planner import session_for
        out = session_for(self.app).view().outcome
        client = getattr(event, "client", None)
        if out is None or out.plan is None or out.obj is None or len(out.plan.kappas) == 0:
            if client is not None:
                client.add_notification("No plan", "Plan a grasp in the Grasp planner panel first.",
                                        color="orange", auto_close_seconds=6.0)
            return
        self._stopped = False
        fut = self.ctl.execute(out.plan, out.obj.x, out.obj.y, out.obj.r)
        fut.add_done_callback(lambda f: self._report(event, f))

    def _stop_hook(self, reason: str) -> None:
        self._stopped = True  # no forwarded jog may undo a STOP (race with the view)
        self.ctl.stop_arm(reason)

    def _on_scene_click(self, event: Any) -> None:
        if not self.click_mode.value:
            return
        try:
            self.app.access.check(event.client, "click to grasp")
        except Exception as exc:  # NotOperator: tell this viewer only
            self.app.refuse(event.client, str(exc), "click to grasp")
            return
        p = table_point(event.ray_origin, event.ray_direction)
        if p is None:
            return
        obj = self._object(event, float(p[0]), float(p[1]))
        if obj is None:
            return
        self.obj_x.value, self.obj_y.value = round(p[0], 4), round(p[1], 4)
        self._stopped = False
        fut = self.ctl.grasp_at(*obj)
        fut.add_done_callback(lambda f: self._report(event, f))

    @staticmethod
    def _report(event: Any, fut: Any) -> None:
        exc = fut.exception()
        client = getattr(event, "client", None)
        if exc is not None and client is not None:
            client.add_notification("Refused", str(exc), color="red", auto_close_seconds=8.0)

    # -- the pump: loop snapshot -> view, history, forwarded jog commands ----------------------
    def _pump_loop(self) -> None:
        period = 1.0 / PUMP_HZ
        while not self._pump_stop.wait(period):
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
                                    "(the device's watchdog stops it); restart the console.",
                                    color="red")
                self.app.recorder.action(f"control process died: {died}", None)
                self._refresh()
            return
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
        meas = c.kappa_meas if c.kappa_meas is not None else np.full(len(c.kappa_ref), np.nan)
        self._hist.append((c.t, c.kappa_ref.copy(), meas, snap.period_ms, snap.work_ms))
        store = self.app.store
        if c.armed and c.kappa_meas is not None:
            cmd = store.command
            if cmd.seq != self._fwd_seq and cmd.source != "control":
                self._fwd_seq = cmd.seq
                # Never after STOP: only Arm / Execute clear a stop (jogging does not).
                if c.phase in FORWARD_PHASES and not self._stopped:
                    self.ctl.goto(np.asarray(cmd.q))
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

    def _show(self, view: ControlView | None) -> None:
        died = self._died()
        if died:
            self.state_md.content = (f"**Control process died:** {died}. The arm is not "
                                     "commanded; restart the console.")
            for btn in (self.arm_btn, self.disarm_btn, self.execute_btn, self.plan_btn):
                btn.disabled = True
            return
        if view is None:
            failure = getattr(self.ctl, "failure", None)
            self.state_md.content = ("**State:** starting the control process…" if not failure
                                     else f"**Control process failed:** {failure}")
            return
        c = view.snapshot.control
        self.state_md.content = state_html(view)
        self.app.header.show("phase", *header_phase(view))
        self.app.header.show("link", *header_link(view))
        if c is not None:
            busy = c.phase not in IDLE_PHASES + ("settling",)
            self.execute_btn.disabled = self.plan_btn.disabled = busy
            # Arm while armed would only restart the stack; after a fault it is the way back.
            self.arm_btn.disabled = c.armed and not view.fault
            self.disarm_btn.disabled = not c.armed
        fault = fault_markdown(view.fault)
        self.fault_md.content = fault
        self.fault_md.visible = bool(fault)
        now = time.monotonic()
        # Counters (ticks, round trips) change on every refresh: once a second is readable;
        # a change of the link's state, arming or losses is shown at once.
        h = view.link
        link_key = (view.device, None if h is None else (h.state, h.armed, h.lost))
        counters = now - self._counters_at >= 1.0 / COUNTERS_HZ
        if counters or link_key != self._link_key:
            self._link_key = link_key
            self.link_md.content = link_line(view)
        if len(self._hist) < 2:  # else the table is redrawn with the plot (_draw_plots)
            self.kappa_md.content = kappa_html(view)
        if counters:
            self._counters_at = now
            st = view.stats
            self.loop_md.content = (f"<small>loop (own process, {view.scheduling}): {st.ticks} "
                                    f"ticks · overruns {st.overruns} · last "
                                    f"{STATS_TICKS // 100} s: period error p99 "
                                    f"{st.period_error_ms_p99:.3f} ms · tick work p99 "
                                    f"{st.work_ms_p99:.3f} ms</small>")
        self._draw_scene(view)
        self._draw_plots()

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

    def _draw_plots(self) -> None:
        hist = list(self._hist)
        if len(hist) < 2:
            return
        t = np.array([h[0] for h in hist])
        ref = np.array([h[1] for h in hist])
        meas = np.array([h[2] for h in hist])
        now = time.monotonic()
        if now - self._table_at >= 1.0 / KAPPA_PLOT_HZ:
            # The κ table is a few hundred bytes: it follows the measurement at 2 Hz (only the
            # plot waits for a move beyond the noise), so what it shows is never seconds old.
            self._table_at = now
            table = kappa_html(self.ctl.view) if self.ctl.view else ""
            if table != self.kappa_md.content:
                self.kappa_md.content = table
        if now - self._plotted_at >= 1.0 / KAPPA_PLOT_HZ and self._plot_moved(
                ref[-1], meas[-1], now):
            cols: list[np.ndarray] = [t]
            for i in range(ref.shape[1]):
                cols += [ref[:, i], np.where(np.isfinite(meas[:, i]), meas[:, i], math.nan)]
            self.kappa_plot.data = thin(cols, KAPPA_PLOT_POINTS)
        if now - self._loop_plot_at >= 1.0 / LOOP_PLOT_HZ:
            self._loop_plot_at = now
            self.loop_plot.data = thin((t, np.array([h[3] for h in hist]),
                                        np.array([h[4] for h in hist])))

    def _plot_moved(self, ref: np.ndarray, meas: np.ndarray, now: float) -> bool:
        """Whether the curvatures moved enough to redraw the plot: a target moved
        by PLOT_BAND, a measurement by MEAS_BAND (beyond mocap noise), or STILL_PLOT_S passed.
        A still arm's noise then costs a redraw every STILL_PLOT_S, not PLOT_HZ of them."""
        last = self._plotted
        moved = (last is None or last[0].shape != ref.shape
                 or now - self._plotted_at >= STILL_PLOT_S
                 or not np.allclose(ref, last[0], rtol=0.0, atol=PLOT_BAND)
                 or not np.allclose(meas, last[1], rtol=0.0, atol=MEAS_BAND, equal_nan=True))
        if moved:
            self._plotted, self._plotted_at = (ref.copy(), meas.copy()), now
        return moved

    def close(self) -> None:
        self._pump_stop.set()
        self.ctl.close()
        self.app.remove_stop_hook(self._stop_hook)
        super().close()
