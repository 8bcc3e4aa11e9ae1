"""Jog panel: hold-to-run buttons and set-point sliders per coordinate, operator only.

Planar arm: a curvature per segment (+-kappa_max, 1/m). Extensible arm: dx, dy, dL per
segment (m); a move that would push a rack outside [rack_min, rack_max], or bend a segment
beyond theta_max (theta = |(dx, dy)| / d; robot file ``segments.theta_max``), is clamped to the
feasible interval of that coordinate (``console.model.DeltaModel.set_coordinate``), the slider
snaps to the value applied and the panel says which rack hit which limit, or that the segment
is at its bending limit. The Δx / Δy sliders span what the racks and the bending limit allow.
"Straighten" removes all bending; on the extensible arm "Retract" returns to delta = 0.

All motion goes through ``app.hold`` (``console.hold_to_run.HoldToRun``), capped at 250 mm/s
for every arm point and clamped to the soft limits:

* "Hold to jog" buttons (``κ₁ −`` / ``κ₁ +`` ...): the arm moves only while the button is held
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
import threading
from functools import partial
from typing import Any

import numpy as np
import viser

from console.model import Coordinate
from console.panels.base import Panel, operator_only
from console.state import ArmState

HOLD_HZ = 20.0


class JogPanel(Panel):
    """Hold-to-run buttons, set-point sliders for every coordinate, straighten / retract."""

    title = "Jog"
    order = 20.0

    def build(self) -> None:
        model = self.app.model
        q = self.app.store.command.q
        self._target_lock = threading.Lock()
        self.sliders: dict[str, viser.GuiSliderHandle[float]] = {}
        self.jog_buttons: dict[tuple[str, int], viser.GuiButtonHandle] = {}
        current_segment = -1
        container = None
        for coord in model.coordinates:
            if model.kind == "delta" and coord.segment != current_segment:
                current_segment = coord.segment
                container = self.gui.add_folder(f"Segment {coord.segment + 1}")
            with container if container is not None else contextlib.nullcontext():
                handle = self._add_slider(coord, float(q[coord.index]))
            handle.on_update(partial(self._on_slider, coord))
            self.sliders[coord.key] = handle
        self.straighten = self.gui.add_button("Straighten", hint="Remove all bending.")
        self.straighten.on_click(self.operator_only(
            lambda e: self._go(e, model.straightened), "straighten the arm"))
        self.retract = None
        if model.kind == "delta":
            self.retract = self.gui.add_button("Retract (Δ = 0)",
                                               hint="Straight and fully retracted.")
            self.retract.on_click(self.operator_only(
                lambda e: self._go(e, lambda q: model.zero()), "retract the arm"))
        with self.gui.add_folder("Hold to jog"):
            for coord in model.coordinates:
                for direction, sign in ((-1, "−"), (1, "+")):
                    button = self.gui.add_button(
                        f"{coord.label} {sign}",
                        hint=f"Hold to move {coord.label} {sign} (stops when released).")
                    button.on_hold(self.operator_only(partial(self._on_hold, coord, direction),
                                                      "jog"), callback_hz=HOLD_HZ)
                    button.on_click(partial(self._on_release, coord))
                    self.jog_buttons[(coord.key, direction)] = button
        self.note = self.gui.add_markdown("")
        self._synced_seq = self.app.store.command.seq

    def _add_slider(self, coord: Coordinate, value: float) -> viser.GuiSliderHandle[float]:
        value = min(max(value, coord.lo), coord.hi)
        return self.gui.add_slider(f"{coord.label} ({coord.unit})", min=coord.lo, max=coord.hi,
                                   step=coord.step, initial_value=value, hint=coord.hint)

    def _base(self) -> np.ndarray:
        target = self.app.hold.target()
        return np.array(self.app.store.command.q) if target is None else target

    @operator_only(action="jog")
    def _on_slider(self, coord: Coordinate, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own mirror of the state into the slider
            return
        handle = self.sliders[coord.key]
        model = self.app.model
        # Read the handle under the lock: of concurrent callbacks the last to run applies the
        # newest slider value, whatever order the thread pool ran them in.
        with self._target_lock:
            target, note = model.set_coordinate(self._base(), coord, float(handle.value))
            note = note or model.limit_note(target, coord)
            self.app.hold.move_to(event.client.client_id, target)
        applied = float(target[coord.index])
        if abs(applied - float(handle.value)) > 1e-9:
            # Snap back to what the limits allow, within the slider's range: the bending limit
            # can lie a fraction of a step beyond the range (floored to whole steps), and a
            # browser pulls an out-of-range value back, which would come in as a new request.
            handle.value = round(min(max(applied, coord.lo), coord.hi), 6)
        self.note.content = f"⚠ {note}" if note else ""

    def _go(self, event: viser.GuiEvent, fn: Any) -> None:
        if event.client is None:
            return
        with self._target_lock:
            self.app.hold.move_to(event.client.client_id, fn(self._base()))
        self._sync_sliders(self.app.hold.target())

    def _on_hold(self, coord: Coordinate, direction: int, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.app.hold.hold(event.client.client_id, coord, direction)

    def _on_release(self, coord: Coordinate, event: viser.GuiEvent) -> None:
        if event.client is not None:  # letting go is always allowed: it only stops
            self.app.hold.release(event.client.client_id, coord)

    def on_refused(self, event: Any) -> None:
        # viser already showed the viewer's slider value to everyone: put the arm's back.
        if isinstance(getattr(event, "target", None), viser.GuiSliderHandle):
            self._sync_sliders(self._base())

    def _sync_sliders(self, q: np.ndarray | None) -> None:
        if q is None:
            return
        for coord in self.app.model.coordinates:
            value = round(min(max(float(q[coord.index]), coord.lo), coord.hi), 6)
            handle = self.sliders[coord.key]
            if not np.isclose(handle.value, value, atol=1e-9):
                handle.value = value

    def _show_notes(self, state: ArmState) -> None:
        self.note.content = "\n\n".join(f"⚠ {n}" for n in state.notes)

    def on_state(self, state: ArmState) -> None:
        command = self.app.store.command
        if command.seq == self._synced_seq:
            return
        self._synced_seq = command.seq
        if command.source == "jog":
            return  # moving to the sliders' set-point: they show where it is going
        self._sync_sliders(np.asarray(command.q))
        self._show_notes(command)
