"""What the Control panel (soft arm) writes: the state line, header fields, fault, link line and
the curvature table, as text built from one :class:`~hw_bridge.soft_arm_process.ControlView`.

Pure functions (no widgets, no threads), so they are tested without a console.
"""

from __future__ import annotations

import dataclasses
import html
from typing import Any

import numpy as np

from console.panels.common.header import Tone
from console.core.grasp_state import SessionView
from hw_bridge.link_supervisor import DISCONNECTED
from hw_bridge.soft_arm_process import ControlView

IDLE_PHASES = ("idle", "released", "stopped")
STALE_S = 0.2  # telemetry older than this (loop time) was not refreshed by a device read
DEVICE_NAMES = {"sim": "simulated arm", "mock": "mock device", "emulator": "device emulator",
                "port": "controller"}
_CELL = "padding:0 2px;text-align:right;font-variant-numeric:tabular-nums"


def table_point(origin: Any, direction: Any) -> tuple[float, float] | None:
    """Where a click ray meets the table plane z = 0 (None if it does not)."""
    o, d = np.asarray(origin, float), np.asarray(direction, float)
    if abs(d[2]) < 1e-9:
        return None
    s = -o[2] / d[2]
    return None if s <= 0 else (float(o[0] + s * d[0]), float(o[1] + s * d[1]))


@dataclasses.dataclass(frozen=True)
class ExecuteTarget:
    """What Execute acts on: the Objects panel's selected object (metres) and, when the Grasp
    planner has a successful plan for exactly that object, that plan (else the controller
    plans the approach itself)."""

    name: str
    x: float
    y: float
    r: float
    plan: Any = None  # core.planning.grasp.GraspPlan

    def describe(self) -> str:
        """For the operator: which object, where, and whose plan."""
        where = f"{self.name} at ({self.x * 1e3:.0f}, {self.y * 1e3:.0f}) mm, r {self.r * 1e3:.1f} mm"
        if self.plan is not None:
            return f"{where}, with the Grasp planner's {self.plan.n}-waypoint plan"
        return f"{where} (no Grasp planner plan for it: the controller plans the approach)"


def _same_disks(a: Any, b: Any) -> bool:
    """Whether two lists of obstacle disks are the same (names, and centres and radii to a
    nanometre: a right-side plan's were mirrored there and back, core.planning.sides)."""
    a, b = tuple(a or ()), tuple(b or ())
    return len(a) == len(b) and all(
        p.name == q.name and max(abs(p.x - q.x), abs(p.y - q.y), abs(p.r - q.r)) < 1e-9
        for p, q in zip(a, b))


def execute_target(session_view: SessionView) -> ExecuteTarget:
    """The target of Execute from the grasp session's view (``console.scene.plan_view.SessionView``);
    ValueError (the operator's message) without a selected object."""
    obj = next((o for o in session_view.objects if o.name == session_view.selected), None)
    if obj is None:
        raise ValueError("No object selected: place or select one in the Objects panel first.")
    out = session_view.outcome
    plan = None
    if (out is not None and out.obj == obj and out.plan is not None and out.plan.success
            and out.plan.n > 0):
        plan = out.plan
    around = session_view.plan_obstacles(obj.name)  # the obstacles and the other objects
    if plan is not None and (not _same_disks(plan.obstacles, around) or (
            around and plan.obstacle_margin != session_view.clearance)):
        plan = None   # made for another table: not this one's plan
    if session_view.obstacles and plan is None:
        # Only a plan the operator saw go around them runs (the controller's re-plans then keep
        # to the same obstacles and clearance: they travel with the plan). Without obstacles
        # the controller plans, around the other objects (the same disks and clearance).
        why = (f" ({out.refusal})" if out is not None and out.obj == obj and out.refusal
               else "")
        raise ValueError(f"Obstacles are on the table: Execute needs the Grasp planner's plan "
                         f"around them for {obj.name}; press Plan grasp first{why}.")
    return ExecuteTarget(obj.name, obj.x, obj.y, obj.r, plan)


def waypoint_text(c: Any, planner_plan: bool = False) -> str:
    """Where the task is in its plan, counted as the Grasp planner and the Waypoints panel count
    (" · approach waypoint 3 of 8 (Grasp planner's plan)"); empty without a plan."""
    if not c.n_waypoints:
        return ""
    whose = (f"controller's re-plan {c.replans}" if c.replans
             else "Grasp planner's plan" if planner_plan else "controller's plan")
    if c.phase == "approach":
        return f" · approach waypoint {c.waypoint + 1} of {c.n_waypoints} ({whose})"
    s = "" if c.n_waypoints == 1 else "s"
    return f" · plan of {c.n_waypoints} waypoint{s} ({whose})"


def state_html(view: ControlView, target: ExecuteTarget | None = None) -> str:
    """The state machine's state (``data-phase``, ``data-waypoint``, ``data-waypoints`` and
    ``data-object`` for tests), the object it acts on, reason and flags."""
    c = view.snapshot.control
    if c is None:
        return '<div data-testid="control-state" data-phase=""><b>State:</b> –</div>'
    wp = waypoint_text(c, target is not None and target.plan is not None)
    stale = (f" · <b>telemetry stale</b> (last at t = {c.t:.2f} s: the device is not read)"
             if view.snapshot.t - c.t > STALE_S else "")
    why = f"<br><b>Reason:</b> {html.escape(c.reason)}" if c.reason else ""
    name = "" if target is None else html.escape(target.name, quote=True)
    obj = "" if target is None else f"<br><b>Object:</b> {html.escape(target.describe())}"
    return (f'<div data-testid="control-state" data-phase="{c.phase}" '
            f'data-waypoint="{c.waypoint + 1 if c.n_waypoints else ""}" '
            f'data-waypoints="{c.n_waypoints or ""}" data-object="{name}"><b>State:</b> '
            f'<span data-testid="control-phase">{c.phase}</span>{wp} · '
            f"{'ARMED' if c.armed else 'disarmed'} · tracking {'ok' if c.tracking_ok else 'LOST'}"
            f" · gripper {'closed' if c.gripper_closed else 'open'}{stale}{obj}{why}</div>")


def header_phase(view: ControlView, target: ExecuteTarget | None = None
                 ) -> tuple[str, Tone | None]:
    """The header's phase field: the state machine's phase, waypoint and arming."""
    c = view.snapshot.control
    if c is None:
        return "–", None
    wp = ""
    if c.n_waypoints and c.phase == "approach":
        wp = f" · waypoint {c.waypoint + 1} of {c.n_waypoints}"
    what = f" · {target.name}" if target is not None and c.phase not in IDLE_PHASES else ""
    tone: Tone = "busy" if c.phase not in IDLE_PHASES + ("settling",) else "ok"
    return f"{c.phase}{what}{wp} · {'ARMED' if c.armed else 'disarmed'}", tone


def header_link(view: ControlView) -> tuple[str, Tone | None]:
    """The header's link field: device and lifecycle state, or the fault in red."""
    name = DEVICE_NAMES.get(view.device, view.device)
    if view.fault:
        return f"{name} · {view.fault}", "fault"
    h = view.link
    if view.device == "sim" and (h is None or h.port == "sim://"):
        return f"{name} (no serial link)", "ok"
    if h is None:
        return f"{name} · starting…", "busy"
    ready = h.state in ("active", "inactive")  # inactive: configured, waiting for Arm
    return f"{name} · {h.state}", "ok" if ready else "warn"


def fault_markdown(fault: str | None) -> str:
    """The hardware fault in bold, with what the operator must do (empty without one)."""
    if not fault:
        return ""
    if fault == DISCONNECTED:
        return ("**Disconnected** by the operator: the arm is not commanded. "
                "Connect (Hardware panel), then Arm.")
    return (f"**Fault: {fault}**  \nThe arm is not commanded and nothing re-arms by itself: "
            "the operator must press **Arm** again (it reconnects the link first).")


def link_line(view: ControlView, rtt_ms_p99: float | None = None) -> str:
    """One line of link health: device, lifecycle state, armed, round trip p99 (``rtt_ms_p99``
    as shown, a :class:`~console.panels.common.steady_figures.SteadyFigure`; None: the view's),
    lost."""
    name = DEVICE_NAMES.get(view.device, view.device)
    h = view.link
    if view.device == "sim" and (h is None or h.port == "sim://"):
        return f"<small>link: {name} in the loop process (no serial link)</small>"
    if h is None:
        return f"<small>link: {name} · starting…</small>"
    where = f" {h.port}" if view.device == "port" else ""
    p99 = h.rtt_ms_p99 if rtt_ms_p99 is None else rtt_ms_p99
    rtt = "–" if p99 is None else f"{p99:.2f} ms"
    return (f'<small data-testid="control-link">link: {name}{where} · {h.state} · '
            f"{'ARMED' if h.armed else 'disarmed'} · round trip p99 {rtt} · lost {h.lost}"
            "</small>")


def loop_line(scheduling: str, ticks: int, overruns: int, window_s: float,
              period_error_ms_p99: float | None, work_ms_p99: float | None) -> str:
    """One line of loop health: where it runs, for how long (whole minutes of 100 Hz ticks, so
    the line stays put while the loop runs steadily), overruns, and the last ``window_s``'s
    p99 period error and tick work (as shown)."""

    def ms(v: float | None) -> str:
        return "–" if v is None else f"{v:.2f} ms"

    return (f"<small>loop (own process, {html.escape(scheduling)}): "
            f"{ticks // 6000} min of ticks · overruns {overruns} · last {window_s:.0f} s: "
            f"period error p99 {ms(period_error_ms_p99)} · tick work p99 {ms(work_ms_p99)}"
            "</small>")


def kappa_html(view: ControlView) -> str:
    """Measured and target curvature per segment (1/m), two decimals; cells have test ids.
    Disarmed there is no target ("–")."""
    c = view.snapshot.control
    if c is None:
        return ""
    n = len(c.kappa_ref)
    meas = c.kappa_meas if c.kappa_meas is not None else [None] * n
    refs = c.kappa_ref if c.armed else [None] * n

    def row(label: str, key: str, values: Any) -> str:
        cells = "".join(f'<td style="{_CELL}" data-testid="kappa-{key}-{i}">'
                        f"{'–' if v is None else f'{v:+.2f}'}</td>" for i, v in enumerate(values))
        return f'<tr><td style="{_CELL};text-align:left">{label}</td>{cells}</tr>'

    head = "".join(f'<th style="{_CELL}">{i + 1}</th>' for i in range(n))
    return (f'<div data-testid="control-kappa" style="font-size:0.72em">'
            f'<table style="border-collapse:collapse;width:100%">'
            f'<tr><th style="{_CELL};text-align:left">κ (1/m)</th>{head}</tr>'
            f"{row('measured', 'meas', meas)}{row('target', 'ref', refs)}</table></div>")
