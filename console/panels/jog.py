"""Jog panel: one slider per configuration coordinate, reshaping the arm live within its limits.

Planar arm: a curvature slider per segment (+-kappa_max, 1/m). Extensible arm: dx, dy, dL per
segment (m); a move that would push a rack outside [rack_min, rack_max] is clamped to the
feasible interval of that coordinate, the slider snaps to the value applied and the panel says
which rack hit which limit. "Straighten" removes all bending; on the extensible arm "Retract"
returns to delta = 0.
"""

from __future__ import annotations

import contextlib
from functools import partial

import numpy as np
import viser

from console.model import Coordinate
from console.panels.base import Panel
from console.state import ArmState


class JogPanel(Panel):
    """Sliders for every coordinate plus straighten / retract buttons."""

    title = "Jog"
    order = 10.0

    def build(self) -> None:
        model = self.app.model
        q = self.app.store.command.q
        self.sliders: dict[str, viser.GuiSliderHandle[float]] = {}
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
        self.straighten.on_click(lambda _: self.app.store.edit(model.straightened, "straighten"))
        self.retract = None
        if model.kind == "delta":
            self.retract = self.gui.add_button("Retract (Δ = 0)",
                                               hint="Straight and fully retracted.")
            self.retract.on_click(lambda _: self.app.store.edit(lambda q: model.zero(), "retract"))
        self.note = self.gui.add_markdown("")
        self._synced_seq = self.app.store.command.seq

    def _add_slider(self, coord: Coordinate, value: float) -> viser.GuiSliderHandle[float]:
        value = min(max(value, coord.lo), coord.hi)
        return self.gui.add_slider(f"{coord.label} ({coord.unit})", min=coord.lo, max=coord.hi,
                                   step=coord.step, initial_value=value, hint=coord.hint)

    def _on_slider(self, coord: Coordinate, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own mirror of the state into the slider
            return
        handle = self.sliders[coord.key]
        model = self.app.model
        # Read the handle inside the locked edit: of concurrent callbacks the last to run
        # applies the newest slider value, whatever order the thread pool ran them in.
        state = self.app.store.edit(
            lambda q: model.set_coordinate(q, coord, float(handle.value)), "jog")
        applied = float(state.q[coord.index])
        if abs(applied - float(handle.value)) > 1e-9:
            handle.value = round(applied, 6)  # snap back to what the racks allow
        self._show_notes(state)

    def _show_notes(self, state: ArmState) -> None:
        self.note.content = "\n\n".join(f"⚠ {n}" for n in state.notes)

    def on_state(self, state: ArmState) -> None:
        command = self.app.store.command
        if command.seq == self._synced_seq:
            return
        self._synced_seq = command.seq
        if command.source == "jog":
            return  # the sliders are the source; re-setting them would fight the operator
        for coord in self.app.model.coordinates:
            value = round(min(max(float(command.q[coord.index]), coord.lo), coord.hi), 6)
            handle = self.sliders[coord.key]
            if not np.isclose(handle.value, value, atol=1e-9):
                handle.value = value
        self._show_notes(command)
