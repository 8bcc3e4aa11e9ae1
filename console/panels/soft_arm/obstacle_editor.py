"""The Objects panel's obstacle editor: the obstacles on the table, select one, type its x, y and
radius (mm), remove it; a table click places one while the panel's "Table click places" says
"Obstacle" (a click on an obstacle selects it).

Obstacles are shared like objects: every change is operator-only (a viewer's edit snaps back
and the viewer is told who holds control); a bad value (radius not positive, not a number, on
the arm's base) is refused with its reason and changes nothing. The session
(:class:`console.core.grasp_session.GraspSession`) keeps them and re-plans.
"""

from __future__ import annotations

import html
from collections.abc import Callable
from typing import Any

from console.core.grasp_session import GraspSession
from console.core.grasp_state import SessionView
from console.panels.common.base import Panel, operator_only
from console.panels.common.typed_fields import TypedFields

NONE = "(none)"


def mm(metres: float) -> float:
    """A length for a field people read: millimetres, to 0.1 mm."""
    return round(float(metres) * 1e3, 1)


class ObstacleEditor:
    """Obstacle widgets inside the Objects panel (built in its folder; the panel owns us).

    Args:
        panel: The panel whose folder the widgets go in (and whose operator gate they use).
        session: The grasp session that keeps the obstacles.
        error: Tells a browser's event why its edit was refused (``error(event, message)``).
    """

    def __init__(self, panel: Panel, session: GraspSession,
                 error: Callable[[Any, str], None]) -> None:
        self.panel = panel
        self.session = session
        self._error = error
        gui = panel.gui
        view = self.session.view()
        self.folder = gui.add_folder("Obstacles", expand_by_default=False)  # editing: folded
        with self.folder:
            self.selected = gui.add_dropdown(
                "Obstacle", [o.name for o in view.obstacles] or [NONE],
                initial_value=view.obstacle_selected or NONE,
                hint="Obstacles: the arm keeps the planner's clearance from them.")
            self.x = gui.add_number("obstacle x (mm)", 0.0, step=1.0)
            self.y = gui.add_number("obstacle y (mm)", 0.0, step=1.0)
            self.r = gui.add_number("obstacle r (mm)", 20.0, step=1.0,
                                    hint="Radius of the next obstacle placed, or of the "
                                         "selected one.")
            self.remove_button = gui.add_button("Remove obstacle", color="red")
            self.info = gui.add_html("")
        # What a refused edit puts back: the session's value (never a value viser stored for a
        # browser whose callback has not run yet). A write of ours calls back at once, in this
        # thread, with no client: that is how a mirror is told from a browser's edit.
        self._fields = {id(h): h.value for h in (self.x, self.y, self.r)}
        self._typed = TypedFields((self.x, self.y, self.r))  # refresh skips a field just typed
        self.selected.on_update(operator_only(self._on_select, panel=panel,
                                              action="select an obstacle"))
        for handle in (self.x, self.y, self.r):
            handle.on_update(operator_only(self._on_typed, panel=panel,
                                           action="edit an obstacle"))
        self.remove_button.on_click(operator_only(self._on_remove, panel=panel,
                                                  action="remove an obstacle"))
        self.place_at = operator_only(self._place_at, panel=panel,
                                      action="place or select an obstacle")

    def owns(self, target: Any) -> bool:
        return target is self.selected or id(target) in self._fields

    # -- callbacks (thin; wrapped operator-only in __init__) ---------------------------------
    def _place_at(self, event, hit: tuple[float, float]) -> None:
        try:
            self.session.place_obstacle(*hit, r=float(self.r.value) / 1e3)
        except ValueError as exc:
            self._error(event, str(exc))

    def _on_select(self, event) -> None:
        if event.client is None or self.selected.value == NONE:
            return
        try:
            self.session.select_obstacle(self.selected.value)
        except ValueError as exc:
            self._error(event, str(exc))

    def _on_typed(self, event) -> None:
        if event.client is None:  # our own write (restore, refresh): already in _fields
            self._fields[id(event.target)] = event.target.value
            return
        value, = self._typed.read([event.target])  # taken: the next echo may show another
        name = self.session.view().obstacle_selected
        if name is None:
            self._fields[id(event.target)] = event.target.value   # r of the next obstacle
            return
        field = "x" if event.target is self.x else "y" if event.target is self.y else "r"
        try:
            self.session.update_obstacle(name, **{field: value / 1e3})
        except (TypeError, ValueError) as exc:
            self._error(event, str(exc))
            self.restore(event.target)
            return
        self._fields[id(event.target)] = event.target.value

    def _on_remove(self, event) -> None:
        name = self.session.view().obstacle_selected
        if name is not None:
            self.session.remove_obstacle(name)

    def restore(self, target: Any) -> None:
        """Put a refused or bad edit back."""
        if target is self.selected:
            self.selected.value = self.session.view().obstacle_selected or NONE
        elif target is not None and id(target) in self._fields:
            self._typed.show([self._fields[id(target)]], [target], typed_too=True)

    # -- display (grasp worker thread) -------------------------------------------------------
    def refresh(self, view: SessionView) -> None:
        names = [o.name for o in view.obstacles] or [NONE]
        if tuple(self.selected.options) != tuple(names):
            self.selected.options = names
        want = view.obstacle_selected or NONE
        if self.selected.value != want:
            self.selected.value = want
        obs = next((o for o in view.obstacles if o.name == view.obstacle_selected), None)
        if obs is not None:
            shown = [mm(obs.x), mm(obs.y), mm(obs.r)]
            for handle, value in zip((self.x, self.y, self.r), shown):
                self._fields[id(handle)] = value  # before the write: its mirror reads it
            self._typed.show(shown)
        count = len(view.obstacles)
        items = "".join(
            f"<br>{html.escape(o.name)}: ({mm(o.x):.0f}, {mm(o.y):.0f}) mm, r {mm(o.r):.0f} mm"
            for o in view.obstacles)
        sel = html.escape(view.obstacle_selected or "", quote=True)
        self.info.content = (
            f'<small data-testid="obstacles-info" data-count="{count}" data-selected="{sel}">'
            f"{count} obstacle{'s' if count != 1 else ''}; the arm keeps "
            f"{mm(view.clearance):.0f} mm from each (Grasp planner: Clearance){items}</small>")
