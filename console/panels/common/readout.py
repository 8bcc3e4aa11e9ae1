"""Readout panel: the displayed tip pose and, for the extensible arm, rack lengths vs. limits.

Values are computed from the displayed configuration with ``core.kinematics`` and shown in mm
and degrees. Soft arm: arm tip (gripper root) [x, y, theta] and the palm point w_t. Extensible
arm: tip position, tilt of the tip axis from vertical, and every rack's length as a bar between
rack_min and rack_max, flagged when within ``NEAR_LIMIT`` of a limit.

The readout follows the drawn arm: it changes only when the arm view sent a new frame (a still
arm inside the view's dead band costs nothing), at most ``READOUT_HZ`` times a second (a person
reads no faster); a state held back is shown when the display goes idle.
"""

from __future__ import annotations

import html
import math

import numpy as np

from console.scene.arm_view import RACK_COLORS
from console.core.model import ExtensibleModel, SoftArmModel
from console.panels.common.base import Panel
from console.core.state import ArmState
from core.units import fmt_deg, fmt_mm

NEAR_LIMIT = 0.005  # m
READOUT_HZ = 10.0
_CELL = "padding:1px 6px;text-align:right;white-space:nowrap"


def _pose_table(rows: list[tuple[str, str, list[str | None]]], columns: list[str]) -> str:
    """A compact table; each value cell gets ``data-testid="<row id>-<column index>"``."""
    head = "".join(f'<th style="{_CELL}">{c}</th>' for c in columns)
    body = ""
    for row_id, label, values in rows:
        cells = "".join(
            f'<td style="{_CELL}" data-testid="{row_id}-{k}"><code>{v}</code></td>'
            if v is not None else f'<td style="{_CELL}"></td>' for k, v in enumerate(values))
        body += f'<tr><td style="{_CELL};text-align:left"><b>{label}</b></td>{cells}</tr>'
    return (f'<table style="border-collapse:collapse"><tr><th></th>{head}</tr>{body}</table>')


def soft_arm_readout_html(model: SoftArmModel, q: np.ndarray) -> str:
    """HTML for the soft arm: tip pose [x, y, theta] and palm point, in mm / degrees."""
    tip = model.poses(q)[-1]
    palm = model.palm_point(tip)
    rows = [
        ("tip", "Arm tip", [fmt_mm(tip[0], sign=True), fmt_mm(tip[1], sign=True),
                            fmt_deg(tip[2], sign=True, wrap=True)]),
        ("palm", "Palm w<sub>t</sub>", [fmt_mm(palm[0], sign=True), fmt_mm(palm[1], sign=True),
                                        None]),
    ]
    return ('<div data-testid="tip-readout" style="font-size:0.85em;line-height:1.5">'
            + _pose_table(rows, ["x (mm)", "y (mm)", "θ (°)"])
            + "<span style='opacity:.6'>arm tip = gripper root; θ = heading</span></div>")


def _rack_cell(cell_id: str, length: float, lo: float, hi: float,
               color: tuple[int, int, int]) -> str:
    frac = min(max((length - lo) / (hi - lo), 0.0), 1.0)
    near = length <= lo + NEAR_LIMIT or length >= hi - NEAR_LIMIT
    text_style = "color:#c92a2a;font-weight:600" if near else ""
    flag = " ⚠" if near else ""
    rgb = f"rgb{color}"
    return (
        f'<td style="{_CELL}" data-testid="{cell_id}" data-near-limit="{str(near).lower()}">'
        f'<span style="{text_style}">{fmt_mm(length)}{flag}</span>'
        f'<div style="height:4px;background:#e9ecef;border-radius:2px;margin-top:1px">'
        f'<div style="height:4px;width:{frac * 100:.1f}%;background:{rgb};border-radius:2px">'
        "</div></div></td>")


def extensible_readout_html(model: ExtensibleModel, q: np.ndarray) -> str:
    """HTML for the extensible arm: tip position and tilt, rack lengths against their limits."""
    r = model.robot
    tip = model.frames(q)[-1]
    p = tip[:3, 3]
    tilt = math.acos(min(max(float(tip[2, 2]), -1.0), 1.0))
    racks = model.rack_lengths(q)
    head = "".join(
        f'<th style="{_CELL}"><span style="color:rgb{RACK_COLORS[j]}">■</span> rack {j + 1}</th>'
        for j in range(3))
    rows = "".join(
        f'<tr><td style="{_CELL};text-align:left">seg {i + 1}</td>'
        + "".join(_rack_cell(f"rack-{i + 1}-{j + 1}", float(racks[i, j]), r.rack_min,
                             r.rack_max, RACK_COLORS[j])
                  for j in range(3))
        + "</tr>"
        for i in range(r.n_segments))
    return (
        '<div style="font-size:0.85em;line-height:1.6">'
        '<div data-testid="tip-readout">'
        + _pose_table([("tip", "Tip", [fmt_mm(p[0], sign=True), fmt_mm(p[1], sign=True),
                                        fmt_mm(p[2], sign=True), fmt_deg(tilt)])],
                      ["x (mm)", "y (mm)", "z (mm)", "tilt (°)"])
        + "<span style='opacity:.6'>tilt = tip axis from vertical</span></div>"
        '<div data-testid="rack-readout" style="margin-top:6px">'
        f"<b>Rack lengths</b> (mm) <span style='opacity:.6'>limits {fmt_mm(r.rack_min, 0)}–"
        f"{fmt_mm(r.rack_max, 0)} mm; ⚠ within {fmt_mm(NEAR_LIMIT, 0)} mm</span>"
        f'<table style="border-collapse:collapse;margin-top:2px"><tr><th></th>{head}</tr>'
        f"{rows}</table></div></div>")


class ReadoutPanel(Panel):
    """Tip pose and rack lengths of the displayed configuration."""

    title = "Readout"
    order = 25.0
    expand_by_default = False  # the numbers behind the drawn arm: diagnostics, folded

    def build(self) -> None:
        self.html = self.gui.add_html(self._render(self.app.store.display))
        self.source = self.gui.add_markdown("")
        self._pending: ArmState | None = None
        self._shown_at = -1e9
        self._frame_shown = -1

    def _render(self, state: ArmState) -> str:
        model = self.app.model
        q = np.asarray(state.q)
        if isinstance(model, SoftArmModel):
            return soft_arm_readout_html(model, q)
        assert isinstance(model, ExtensibleModel)
        return extensible_readout_html(model, q)

    def on_state(self, state: ArmState) -> None:
        self._pending = state
        if self.app.core.clock() - self._shown_at >= 1.0 / READOUT_HZ:
            self._show()

    def on_idle(self) -> None:
        self._show()

    def _show(self) -> None:
        state = self._pending
        frame = self.app.view.frames_sent
        if state is None or frame == self._frame_shown:
            return  # nothing new, or the drawn arm did not change
        self._pending = None
        self._shown_at = self.app.core.clock()
        self._frame_shown = frame
        self.html.content = self._render(state)
        self.source.content = f"<small>shown: {html.escape(state.source)} · #{state.seq}</small>"
