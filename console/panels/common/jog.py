"""Jog panel: one row per coordinate -- its set-point slider with hold-to-jog − / + beside it.

Soft arm: a curvature per segment (+-kappa_max, 1/m), and under the sliders each segment's
bend angle θᵢ = κᵢ·Lᵢ in degrees. Extensible arm: Δx, Δy, δL per segment in mm (SI inside: the
panel converts), one folder per segment; a move that would push a rack outside
[rack_min, rack_max], or bend a segment beyond theta_max (theta = |(dx, dy)| / d; robot file
``segments.theta_max``), is clamped to the feasible interval of that coordinate
(``console.core.model.ExtensibleModel.set_coordinate``), the slider snaps to the value applied
and the panel says which rack hit which limit, or that the segment is at its bending limit.
The Δx / Δy sliders span what the racks and the bending limit allow. "Straighten" removes all
bending; on the extensible arm "Retract" returns to delta = 0.

Layout: viser 1.1.1 stacks every widget on its own full-width row and has no row container
(a button group sends clicks only, no hold events). The panel keeps real hold buttons and lays
each slider and its − / + out on one grid row with a small style sheet (:func:`row_css`, in an
HTML widget of the panel) keyed on the widgets' ids. A browser without CSS ``:has()`` shows
the same buttons stacked under their slider: the same row order, only taller.

All motion goes through ``app.core.hold`` (``console.core.hold_to_run.HoldToRun``), clamped to
the soft limits and no arm point faster than the *jog speed* (the field "Jog speed (mm/s)" at
the top of the panel, within 1 mm/s and the arm's limit; the console core starts it at 20 mm/s on
the extensible arm, at the 250 mm/s cap on the soft arm). The field only asks the core
(``hold.set_jog_speed``), which refuses a bad value with a message; the panel keeps no speed:

* The − / + buttons hold to jog: the arm moves only while the button is held
  (viser's ``on_hold`` renews the jog 20 times a second; a jog expires 300 ms after its last
  renewal; letting go ends it at once). The browser sends the renewals from its main thread: a
  software-rendered tab busy drawing the moving arm was measured sending them 0.5-0.8 s apart,
  so there a held jog advances in 300 ms bursts (safe, but jerky); with a GPU it is smooth.
* Sliders, Straighten, Retract: a set-point; the arm moves towards it at the capped speed only
  while heartbeats from the operator's tab arrive (the lease probe's answers, every 0.1 s): with
  none for 300 ms it holds where it is, and goes on when the tab answers again. A lost lease
  (2 s of silence, a closed tab), STOP or another command ends the move.

Every callback is wrapped with ``operator_only``: viewers are told who holds control.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from functools import partial
from typing import Any

import numpy as np
import viser

from console.core.model import Coordinate, subscript
from console.panels.common.base import Panel, operator_only
from console.core.state import ArmState
from console.panels.common.events import target_of
from console.web.widgets import widget_id
from console.panels.common.disarmed import disarmed_note
from core.units import MM_PER_M, fmt_deg, fmt_mm

HOLD_HZ = 20.0
MINUS, PLUS = "−", "+"


@dataclasses.dataclass(frozen=True)
class DisplayUnit:
    """How a coordinate's SI value is shown on its slider: ``shown = si * scale``."""

    label: str
    scale: float
    step: float | None = None  # slider step in shown units (None: the coordinate's, scaled)


DISPLAY_UNITS = {"m": DisplayUnit("mm", MM_PER_M, 0.1)}


def display_unit(coord: Coordinate) -> DisplayUnit:
    """The unit a person reads for ``coord`` (metres as mm; others as they are)."""
    return DISPLAY_UNITS.get(coord.unit, DisplayUnit(coord.unit, 1.0))


@dataclasses.dataclass(frozen=True)
class JogRow:
    """One coordinate's row: its slider and its hold-to-jog − / + buttons."""

    coord: Coordinate
    unit: DisplayUnit
    slider: viser.GuiSliderHandle[float]
    minus: viser.GuiButtonHandle
    plus: viser.GuiButtonHandle


def row_css(rows: list[JogRow]) -> str:
    """A style sheet putting each row's slider, − and + on one line of its folder's grid.

    The folder's container (the element whose children are the widgets' boxes) becomes a
    three-column grid: every child spans the row, except a row's slider (first column) and its
    two buttons (auto-sized columns). Selectors name the widgets by id, so nothing else on the
    page changes; ``!important`` beats the inline margins viser gives a button's box.
    """
    rules = []
    for row in rows:
        s, m, p = (widget_id(h) for h in (row.slider, row.minus, row.plus))
        box = f'div:has(> div > button[id="{m}"])'
        rules += [
            f"{box}{{display:grid;grid-template-columns:minmax(0,1fr) auto auto;"
            "align-items:start}",
            f"{box}>*{{grid-column:1/-1}}",
            f'{box}>div:has([id="{s}"]){{grid-column:1}}',
            # the label column, 6.6 em in a folder, leaves the track too short beside buttons
            f'{box}>div:has([id="{s}"])>div>div:first-child{{width:4.6em!important}}',
            f'{box}>div:has(>button[id="{m}"]),{box}>div:has(>button[id="{p}"])'
            "{grid-column:auto;margin:0 0 0 2px!important}",
            f'{box}>div:has(>button[id="{p}"]){{margin-right:var(--mantine-spacing-xs)!important}}',
            f'button[id="{m}"],button[id="{p}"]{{height:1.75em!important;'
            "padding:0 0.55em;min-width:2.1em}",
        ]
    return "<style>" + "\n".join(rules) + "</style>"


def bend_html(thetas: np.ndarray) -> str:
    """One line of each segment's bend angle θᵢ = κᵢ·Lᵢ, in degrees."""
    cell = "padding:0 4px;text-align:right"
    head = "".join(f'<th style="{cell}">θ{subscript(i + 1)}</th>' for i in range(len(thetas)))
    vals = "".join(f'<td style="{cell}" data-testid="bend-{i + 1}">{fmt_deg(t, 0)}</td>'
                   for i, t in enumerate(thetas))
    return ('<div style="font-size:0.8em;padding:0 var(--mantine-spacing-xs)">'
            '<span style="opacity:.7">bend θ = κL (°)</span>'
            f'<table style="border-collapse:collapse"><tr>{head}</tr><tr>{vals}</tr></table>'
            "</div>")


class JogPanel(Panel):
    """Per coordinate a set-point slider with hold-to-jog − / + beside it; straighten / retract."""

    title = "Jog"
    order = 20.0
    expand_by_default = False  # below the task's panels, one click away

    def build(self) -> None:
        model = self.app.model
        q = self.app.store.command.q
        self._target_lock = threading.Lock()
        self.sliders: dict[str, viser.GuiSliderHandle[float]] = {}
        self.jog_buttons: dict[tuple[str, int], viser.GuiButtonHandle] = {}
        self.rows: list[JogRow] = []
        lo, hi = self.app.core.hold.jog_speed_limits
        self.speed = self.gui.add_number(
            "Jog speed (mm/s)", round(self.app.core.hold.jog_speed * MM_PER_M, 1),
            min=round(lo * MM_PER_M, 1), max=round(hi * MM_PER_M, 1), step=1.0,
            hint=f"Fastest any point of the arm moves while jogging ({fmt_mm(lo, 0)}–"
                 f"{fmt_mm(hi, 0)} mm/s): held − / +, the sliders, Straighten and Retract.")
        self.speed.on_update(self._on_speed)
        current_segment = -1
        container = None
        for coord in model.coordinates:
            if model.kind == "delta" and coord.segment != current_segment:
                current_segment = coord.segment
                container = self.gui.add_folder(f"Segment {coord.segment + 1}")
            with container if container is not None else contextlib.nullcontext():
                self.rows.append(self._add_row(coord, float(q[coord.index])))
        self.bend = None
        if model.kind == "planar":
            self.bend = self.gui.add_html(bend_html(self._bends(np.asarray(q))))
        self.straighten = self.gui.add_button("Straighten", hint="Remove all bending.")
        self.straighten.on_click(self.operator_only(
            lambda e: self._go(e, model.straightened), "straighten the arm"))
        self.retract = None
        if model.kind == "delta":
            self.retract = self.gui.add_button("Retract (Δ = 0)",
                                               hint="Straight and fully retracted.")
            self.retract.on_click(self.operator_only(
                lambda e: self._go(e, lambda q: model.zero()), "retract the arm"))
        self.note = self.gui.add_markdown("")
        self.layout = self.gui.add_html(row_css(self.rows))
        self._synced_seq = self.app.store.command.seq

    def _add_row(self, coord: Coordinate, value: float) -> JogRow:
        unit = display_unit(coord)
        lo, hi = (round(v * unit.scale, 6) for v in (coord.lo, coord.hi))
        step = unit.step if unit.step is not None else round(coord.step * unit.scale, 6)
        slider = self.gui.add_slider(
            f"{coord.label} ({unit.label})", min=lo, max=hi, step=step,
            initial_value=round(min(max(value, coord.lo), coord.hi) * unit.scale, 6),
            hint=coord.hint)
        slider.on_update(partial(self._on_slider, coord))
        self.sliders[coord.key] = slider
        buttons = []
        for direction, sign in ((-1, MINUS), (1, PLUS)):
            button = self.gui.add_button(
                sign, hint=f"Hold to move {coord.label} {sign} (stops when released).")
            button.on_hold(self.operator_only(partial(self._on_hold, coord, direction), "jog"),
                           callback_hz=HOLD_HZ)
            button.on_click(partial(self._on_release, coord))
            self.jog_buttons[(coord.key, direction)] = button
            buttons.append(button)
        return JogRow(coord, unit, slider, buttons[0], buttons[1])

    def _bends(self, q: np.ndarray) -> np.ndarray:
        """Bend angle of each soft-arm segment, θᵢ = κᵢ·Lᵢ (rad)."""
        return np.asarray(q, dtype=float) * np.asarray(self.app.robot.lengths, dtype=float)

    def _base(self) -> np.ndarray:
        target = self.app.core.hold.target()
        return np.array(self.app.store.command.q) if target is None else target

    def _refused_disarmed(self) -> bool:
        """A disarmed extensible arm on hardware does not move: say so, move nothing."""
        note = disarmed_note(self.app)
        if note is None:
            return False
        self.note.content = f"⚠ Not moved: {note}"
        self._sync_sliders(self._base())
        return True

    @operator_only(action="change the jog speed")
    def _on_speed(self, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own mirror of the core's speed
            return
        hold = self.app.core.hold
        try:
            applied = hold.set_jog_speed(float(self.speed.value) / MM_PER_M)
        except ValueError as exc:
            self.note.content = f"⚠ Jog speed not changed: {exc}."
        else:
            self.note.content = f"Jog speed {fmt_mm(applied, 0)} mm/s."
        self._sync_speed()

    def _sync_speed(self) -> None:
        """Show the core's jog speed in the field (after a refused or clamped value)."""
        shown = round(self.app.core.hold.jog_speed * MM_PER_M, 1)
        if self.speed.value != shown:
            self.speed.value = shown

    @operator_only(action="jog")
    def _on_slider(self, coord: Coordinate, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own mirror of the state into the slider
            return
        if self._refused_disarmed():
            return
        handle = self.sliders[coord.key]
        scale = display_unit(coord).scale
        model = self.app.model
        # Read the handle under the lock: of concurrent callbacks the last to run applies the
        # newest slider value, whatever order the thread pool ran them in.
        with self._target_lock:
            requested = float(handle.value) / scale
            target, note = model.set_coordinate(self._base(), coord, requested)
            note = note or model.limit_note(target, coord)
            self.app.core.hold.move_to(event.client.client_id, target, jog=True)
        applied = float(target[coord.index])
        if abs(applied - requested) > 1e-9:
            # Snap back to what the limits allow, within the slider's range: the bending limit
            # can lie a fraction of a step beyond the range (floored to whole steps), and a
            # browser pulls an out-of-range value back, which would come in as a new request.
            handle.value = round(min(max(applied, coord.lo), coord.hi) * scale, 6)
        self.note.content = f"⚠ {note}" if note else ""

    def _go(self, event: viser.GuiEvent, fn: Any) -> None:
        if event.client is None or self._refused_disarmed():
            return
        with self._target_lock:
            self.app.core.hold.move_to(event.client.client_id, fn(self._base()), jog=True)
        self._sync_sliders(self.app.core.hold.target())

    def _on_hold(self, coord: Coordinate, direction: int, event: viser.GuiEvent) -> None:
        if event.client is not None and not self._refused_disarmed():
            self.app.core.hold.hold(event.client.client_id, coord, direction)

    def _on_release(self, coord: Coordinate, event: viser.GuiEvent) -> None:
        if event.client is not None:  # letting go is always allowed: it only stops
            self.app.core.hold.release(event.client.client_id, coord)

    def on_refused(self, event: Any) -> None:
        # viser already showed the viewer's slider value to everyone: put the arm's back.
        if isinstance(target_of(event), viser.GuiSliderHandle):
            self._sync_sliders(self._base())
        if target_of(event) is self.speed:
            self._sync_speed()

    def _sync_sliders(self, q: np.ndarray | None) -> None:
        if q is None:
            return
        for row in self.rows:
            coord, scale = row.coord, row.unit.scale
            value = round(min(max(float(q[coord.index]), coord.lo), coord.hi) * scale, 6)
            if not np.isclose(row.slider.value, value, atol=1e-9 * scale):
                row.slider.value = value

    def _show_notes(self, state: ArmState) -> None:
        self.note.content = "\n\n".join(f"⚠ {n}" for n in state.notes)

    def on_state(self, state: ArmState) -> None:
        command = self.app.store.command
        if command.seq == self._synced_seq:
            return
        self._synced_seq = command.seq
        if self.bend is not None:
            content = bend_html(self._bends(np.asarray(command.q)))
            if content != self.bend.content:
                self.bend.content = content
        if command.source == "jog":
            return  # moving to the sliders' set-point: they show where it is going
        self._sync_sliders(np.asarray(command.q))
        self._show_notes(command)
