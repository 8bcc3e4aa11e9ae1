"""What the Control panel (soft arm) writes: the state line, header fields, fault, link line and
the curvature table, as text built from one :class:`~hw_bridge.soft_arm_process.ControlView`.

Pure functions (no widgets, no threads), so they are tested without a console.
"""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from console.header import Tone
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


def state_html(view: ControlView) -> str:
    """The state machine's state (``data-phase`` for tests), reason and flags."""
    c = view.snapshot.control
    if c is None:
        return '<div data-testid="control-state" data-phase=""><b>State:</b> –</div>'
    wp = f" · waypoint {c.waypoint + 1}/{c.n_waypoints}" if c.n_waypoints else ""
    stale = (f" · <b>telemetry stale</b> (last at t = {c.t:.2f} s: the device is not read)"
             if view.snapshot.t - c.t > STALE_S else "")
    why = f"<br><b>Reason:</b> {html.escape(c.reason)}" if c.reason else ""
    return (f'<div data-testid="control-state" data-phase="{c.phase}"><b>State:</b> '
            f'<span data-testid="control-phase">{c.phase}</span>{wp} · re-plans {c.replans} · '
            f"{'ARMED' if c.armed else 'disarmed'} · tracking {'ok' if c.tracking_ok else 'LOST'}"
            f" · gripper {'closed' if c.gripper_closed else 'open'}{stale}{why}</div>")


def header_phase(view: ControlView) -> tuple[str, Tone | None]:
    """The header's phase field: the state machine's phase, waypoint and arming."""
    c = view.snapshot.control
    if c is None:
        return "–", None
    wp = f" · waypoint {c.waypoint + 1}/{c.n_waypoints}" if c.n_waypoints else ""
    tone: Tone = "busy" if c.phase not in IDLE_PHASES + ("settling",) else "ok"
    return f"{c.phase}{wp} · {'ARMED' if c.armed else 'disarmed'}", tone


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
    return f"{name} · {h.state}", "ok" if h.state == "active" else "warn"


def fault_markdown(fault: str | None) -> str:
    """The hardware fault in bold, with what the operator must do (empty without one)."""
    if not fault:
        return ""
    if fault == DISCONNECTED:
        return ("**Disconnected** by the operator: the arm is not commanded. "
                "Connect (Hardware panel), then Arm.")
    return (f"**Fault: {fault}**  \nThe arm is not commanded and nothing re-arms by itself: "
            "the operator must press **Arm** again (it reconnects the link first).")


def link_line(view: ControlView) -> str:
    """One line of link health: device, lifecycle state, armed, round trip p99, lost."""
    name = DEVICE_NAMES.get(view.device, view.device)
    h = view.link
    if view.device == "sim" and (h is None or h.port == "sim://"):
        return f"<small>link: {name} in the loop process (no serial link)</small>"
    if h is None:
        return f"<small>link: {name} · starting…</small>"
    where = f" {h.port}" if view.device == "port" else ""
    rtt = "–" if h.rtt_ms_p99 is None else f"{h.rtt_ms_p99:.2f} ms"
    return (f'<small data-testid="control-link">link: {name}{where} · {h.state} · '
            f"{'ARMED' if h.armed else 'disarmed'} · round trip p99 {rtt} · lost {h.lost}"
            "</small>")


def kappa_html(view: ControlView) -> str:
    """Measured and target curvature per segment (1/m), two decimals; cells have test ids."""
    c = view.snapshot.control
    if c is None:
        return ""
    n = len(c.kappa_ref)
    meas = c.kappa_meas if c.kappa_meas is not None else [None] * n

    def row(label: str, key: str, values: Any) -> str:
        cells = "".join(f'<td style="{_CELL}" data-testid="kappa-{key}-{i}">'
                        f"{'–' if v is None else f'{v:+.2f}'}</td>" for i, v in enumerate(values))
        return f'<tr><td style="{_CELL};text-align:left">{label}</td>{cells}</tr>'

    head = "".join(f'<th style="{_CELL}">{i + 1}</th>' for i in range(n))
    return (f'<div data-testid="control-kappa" style="font-size:0.72em">'
            f'<table style="border-collapse:collapse;width:100%">'
            f'<tr><th style="{_CELL};text-align:left">κ (1/m)</th>{head}</tr>'
            f"{row('measured', 'meas', meas)}{row('target', 'ref', c.kappa_ref)}</table></div>")
