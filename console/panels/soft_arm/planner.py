"""Planner panel: "Plan grasp" at the top of Operate, naming the object it plans for, the outcome
in plain words, and the planner's settings folded away (a first demo needs none of them).

The panel works on the console's :class:`console.core.grasp_session.GraspSession`
(``app.soft_arm_grasp()``, shared with the Objects and Waypoints panels; ``GraspSession`` is
re-exported here): "Plan grasp", the selected object's name (``data-testid="plan-for"``), the
outcome, the reachability note, and, in the folder *Planner settings* (collapsed), delta_d (mm; metres inside) and weight inputs, the clearance (mm) every plan keeps
between the arm (gripper included) and every obstacle, live re-plan
and shading toggles, and the outcome ("5 waypoints, 1.3 ms", or why not). The panel shows the
session's outcome from the start (a plan made before the panel existed is not hidden).

Sharing: the plan and its settings are the same for every browser, so Plan grasp and every
settings change is operator-only (a viewer's edit snaps back); so are the Objects and Waypoints
panels' changes (see there).

``console.panels.soft_arm.panel_set.grasp_panels()`` lists the three grasp panels.
"""

from __future__ import annotations

import html

from console.panels.common.events import target_of
from console.core.grasp_session import GraspSession
from console.core.grasp_state import SessionView
from console.panels.common.base import Panel, operator_only
from console.scene.plan_view import outcome_html, planning_html
from core.planning.reachability import ReachMap

__all__ = ["GraspSession", "PlannerPanel", "outcome_html", "plan_for_html"]


def plan_for_html(view: SessionView) -> str:
    """Which object Plan grasp plans for: the selected one by name, where it lies and its
    diameter (mm), or what to do when none is selected (``data-testid="plan-for"``)."""
    chosen = next((o for o in view.objects if o.name == view.selected), None)
    if chosen is None:
        text = ("No object selected: click the table to place one (top of Operate: "
                "<i>Table click places</i>).")
        name = ""
    else:
        name = html.escape(chosen.name)
        text = (f"Object: <b>{name}</b> at ({chosen.x * 1e3:.0f}, {chosen.y * 1e3:.0f}) mm, "
                f"⌀ {2 * chosen.r * 1e3:.0f} mm")
    return f'<small data-testid="plan-for" data-object="{name}">{text}</small>'


class PlannerPanel(Panel):
    """Plan the selected object's grasp; settings; the outcome in plain words."""

    title = "Grasp planner"
    order = 2.0  # first in Operate: Plan, then the Control panel's Arm and Execute
    kinds = ("planar",)

    def build(self) -> None:
        self.session = self.app.soft_arm_grasp()
        s = self.session
        self.plan_button = self.gui.add_button(
            "Plan grasp", hint="Plan the approach to the selected object (Algorithm 1).")
        self.plan_for = self.gui.add_html(plan_for_html(s.view()))
        self.summary = self.gui.add_html(outcome_html(s.view().outcome))
        self.reach_note = self.gui.add_html("<small>Reachability map: computing…</small>")
        self.settings = self.gui.add_folder("Planner settings", expand_by_default=False)
        with self.settings:
            self._build_settings()
        self.plan_button.on_click(self.operator_only(lambda _: s.request_plan(), "plan a grasp"))
        self.delta_d.on_update(self._on_delta_d)
        self.weights.on_update(self._on_weights)
        self.clearance.on_update(self._on_clearance)
        self.live.on_update(self.operator_only(
            lambda e: e.client and s.configure(live=self.live.value), "change the planner"))
        self.reach.on_update(self.operator_only(
            lambda e: e.client and s.configure(show_reach=self.reach.value),
            "change the shading"))
        self._shown = None
        self.when_closed(s.add_listener(lambda view, _changed: self.refresh(view)))
        self.refresh(s.view())  # a plan finished before the listener was added is shown too

    def _build_settings(self) -> None:
        """Δd, weights, clearance, live re-plan and shading (inside *Planner settings*)."""
        s = self.session
        self.delta_d = self.gui.add_number("Δd (mm)", round(s.delta_d * 1e3, 1), min=5.0,
                                           max=300.0, step=5.0,
                                           hint="Allowable incremental distance between "
                                                "approach circles.")
        self.weights = self.gui.add_text("Weights R", ", ".join(f"{w:g}" for w in s.weights),
                                         hint="Cost weights of the segments' curvature change.")
        self.clearance = self.gui.add_number(
            "Clearance (mm)", round(s.clearance * 1e3, 1), step=1.0,
            hint="Every point of the arm and the gripper keeps this far from every obstacle, "
                 "at and between waypoints.")
        self.live = self.gui.add_checkbox("Re-plan while dragging", s.live)
        self.reach = self.gui.add_checkbox("Reachability shading", s.show_reach,
                                           hint="Green: a grasp can be planned from the straight "
                                                "arm; amber: reachable, approach fails.")

    def _notify(self, event, message: str) -> None:
        if event.client is not None:
            self.app.show_refusal(event.client, "Planner", message)

    @operator_only(action="change the planner")
    def _on_delta_d(self, event) -> None:
        if event.client is None:
            return
        value = float(self.delta_d.value)
        if not 0.0 < value <= 1000.0:
            self._notify(event, f"Δd must be a positive distance up to 1000 mm, got {value:g} mm")
            self.on_refused(event)
            return
        self.session.configure(delta_d=value / 1e3)

    @operator_only(action="change the planner")
    def _on_weights(self, event) -> None:
        if event.client is None:
            return
        try:
            w = tuple(float(v) for v in self.weights.value.replace(";", ",").split(","))
            if len(w) != self.app.robot.n_segments or min(w) <= 0:
                raise ValueError
        except ValueError:
            self._notify(event, f"Weights: {self.app.robot.n_segments} positive numbers, "
                                f"separated by commas.")
            self.on_refused(event)
            return
        self.session.configure(weights=w)

    @operator_only(action="change the planner")
    def _on_clearance(self, event) -> None:
        if event.client is None:
            return
        try:
            self.session.set_clearance(float(self.clearance.value) / 1e3)
        except (TypeError, ValueError) as exc:
            self._notify(event, f"Clearance: {exc}")
            self.on_refused(event)

    def on_refused(self, event) -> None:
        """Put a refused (or bad) edit back to the session's setting, for everyone."""
        s, target = self.session, target_of(event)
        if target is self.delta_d:
            self.delta_d.value = round(s.delta_d * 1e3, 1)
        elif target is self.weights:
            self.weights.value = ", ".join(f"{w:g}" for w in s.weights)
        elif target is self.clearance:
            self.clearance.value = round(s.clearance * 1e3, 1)
        elif target is self.live:
            self.live.value = s.live
        elif target is self.reach:
            self.reach.value = s.show_reach

    def refresh(self, view: SessionView) -> None:
        """Worker thread: show the newest outcome, or "Planning… (n s)" with Plan grasp
        disabled while a plan has run longer than a moment (the session's planning clock)."""
        planning = view.planning_s is not None
        text = planning_html(view.planning_s) if planning else outcome_html(view.outcome)
        if self.plan_button.disabled != planning:
            self.plan_button.disabled = planning
        if text != self._shown:
            self._shown = text
            self.summary.content = text
        target = plan_for_html(view)
        if target != self.plan_for.content:
            self.plan_for.content = target
        if isinstance(view.reach, ReachMap):
            note = ("<small>Shading: <span style='color:#2f9e44'>green</span> = a grasp can be "
                    "planned from the straight arm (object ⌀ "
                    f"{2 * view.reach.radius * 1e3:.0f} mm), <span style='color:#e8590c'>amber"
                    "</span> = reachable, but the approach fails. <span data-testid='reach-"
                    f"state' data-state='done'>Reachability map: "
                    f"{html.escape(view.reach_note)}</span>.</small>")
        else:
            text = str(view.reach)
            state = ("computing" if text == "computing" or text.endswith("%") else
                     "failed" if text.startswith("failed") else "off")
            note = (f"<small data-testid='reach-state' data-state='{state}'>Reachability map: "
                    f"{html.escape(text)}{'…' if state == 'computing' else ''}</small>")
        if note != getattr(self, "_note", None):
            self._note = note
            self.reach_note.content = note
