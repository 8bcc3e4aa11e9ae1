"""Waypoints panel: step, scrub or play through the plan's waypoints and read each one.

Previous / Next, a slider, play / pause with a speed, and a trail toggle (ghost arms of the
waypoints already passed). The inspected waypoint is highlighted in the 3D view (orange ghost
arm, bright circle, palm point, and the capture region at the final one) and listed here with
its kappa, phi, r_a and gaps to the object and, with obstacles, to them (mm and degrees). "Move
arm here" commands the waypoint's configuration. Shown from the start, so it and the Grasp planner tell the same plan.
While the arm runs a task, a line at the top says where the ARM is (the loop's waypoint and
object, :mod:`console.core.run_state`); when it executes this very plan the waypoint shown is
the arm's, and when it runs another, the plan here is headed "Next plan (not running)".

Everything here is operator-only, browsing included: the inspected waypoint, playback, speed
and trail are drawn in the 3D view every browser shares, so a viewer stepping through the
waypoints would change what everyone (the operator included) sees. A viewer's slider / speed /
trail edit snaps back; viewers watch the operator's inspection.
"""

from __future__ import annotations

import html
import math
from typing import Any

from console.panels.common.events import target_of
from console.core.grasp_state import SessionView
from console.panels.common.base import Panel, operator_only


def obstacle_rows(plan: Any, k: int) -> list[tuple[str, str]]:
    """With obstacles: waypoint ``k``'s gap to the nearest one, the certified bound along the
    line into it, and the clearance the planner keeps (mm); nothing without obstacles."""
    if not plan.obstacles or plan.obstacle_clearance is None:
        return []
    return [("to obstacles", f"{plan.obstacle_clearance[k] * 1e3:.1f} mm (path ≥ "
                             f"{plan.obstacle_path_clearance[k] * 1e3:.1f} mm; keeps "
                             f"{plan.obstacle_margin * 1e3:.0f} mm)")]


def run_html(view: SessionView) -> str:
    """What the arm runs, from the loop's view (``data-testid="waypoint-run"`` with the
    executing waypoint, its plan's length and the object): empty when it runs nothing."""
    run = view.run
    if run is None:
        return ""
    wp = "" if run.waypoint is None else str(run.waypoint + 1)
    n = "" if run.plan is None else str(run.plan.n)
    name = html.escape(run.name or "", quote=True)
    what = run.object_text()
    mine = not view.running_other_plan()
    below = ("the plan below" if mine else
             "its plan is drawn in colour; the plan below (grey in the 3D view) is the next "
             "one, run by Execute")
    return (f'<div data-testid="waypoint-run" data-index="{wp}" data-count="{n}" '
            f'data-object="{name}" data-mine="{int(mine)}" style="font-size:0.85em">'
            f"<b>Arm at {html.escape(run.waypoint_text())}</b>"
            f"{' of ' + html.escape(what) if what else ''} ({below})</div>")


def waypoint_html(view: SessionView) -> str:
    """The inspected waypoint, in words and numbers (with test ids); while the arm executes
    this very plan, the waypoint it goes to (the loop's, not the inspected one)."""
    plan = view.outcome.plan if view.outcome else None
    if plan is None or plan.n == 0:
        return '<div data-testid="waypoint-info" data-index="" style="font-size:0.85em">' \
               "No plan to inspect.</div>"
    k = view.index
    run = view.run
    title = "Waypoint"
    if run is not None and not view.running_other_plan():
        if run.waypoint is not None:
            k, title = min(run.waypoint, plan.n - 1), "Arm at waypoint"
    elif run is not None:
        title = "Next plan (not running): waypoint"
    kappa = ", ".join(f"{v:.2f}" for v in plan.kappas[k])
    tag = " (inserted)" if plan.inserted[k] else ""
    status = plan.status[k]
    colour = "#2b8a3e" if status == "ok" else "#c92a2a"
    rows = [
        ("r_a", f"{plan.radii[k] * 1e3:.1f} mm"),
        ("φ", f"{math.degrees(plan.phis[k]):.1f}°"),
        ("κ (1/m)", kappa),
        ("palm", f"({plan.palm_poses[k, 0] * 1e3:.1f}, {plan.palm_poses[k, 1] * 1e3:.1f}) mm, "
                 f"{math.degrees(plan.palm_poses[k, 2]):.1f}°"),
        ("to the object", f"{plan.clearance[k] * 1e3:.1f} mm (path ≥ "
                          f"{plan.path_clearance[k] * 1e3:.1f} mm)"),
        *obstacle_rows(plan, k),
        ("solver", f"{plan.iterations[k]} iterations, {plan.solve_ms[k]:.2f} ms"),
        ("status", f"<span style='color:{colour}'>{status.replace('_', ' ')}</span>"),
    ]
    body = "".join(f"<tr><td style='padding-right:6px'>{a}</td><td>{b}</td></tr>"
                   for a, b in rows)
    return (f'<div data-testid="waypoint-info" data-index="{k + 1}" data-count="{plan.n}" '
            f'data-ra="{plan.radii[k]:.6f}" style="font-size:0.85em">'
            f"<b>{title} {k + 1} of {plan.n}</b>{tag}<table>{body}</table></div>")


class WaypointsPanel(Panel):
    """Inspect the plan's waypoints one by one."""

    title = "Waypoints"
    order = 7.0
    expand_by_default = False  # inspecting a plan step by step: not what a first demo needs
    kinds = ("planar",)

    def build(self) -> None:
        self.session = self.app.soft_arm_grasp()
        s = self.session
        self.run_info = self.gui.add_html("", visible=False)  # what the arm runs now
        self.prev_button = self.gui.add_button("Previous waypoint")
        self.next_button = self.gui.add_button("Next waypoint")
        self.slider = self.gui.add_slider("Waypoint", min=1, max=2, step=1, initial_value=1,
                                          disabled=True)
        self.play_button = self.gui.add_button("Play")
        self.speed = self.gui.add_slider("Speed (waypoints/s)", min=0.5, max=10.0, step=0.5,
                                         initial_value=2.0)
        self.trail = self.gui.add_checkbox("Trail", True, hint="Show the waypoints already "
                                                               "passed as ghost arms.")
        self.info = self.gui.add_html(waypoint_html(s.view()))
        self.move_button = self.gui.add_button(
            "Move arm here", hint="Command this waypoint's curvatures (simulation / hardware).")
        step = "step through the waypoints"
        self.prev_button.on_click(self.operator_only(lambda _: s.inspect(step=-1), step))
        self.next_button.on_click(self.operator_only(lambda _: s.inspect(step=+1), step))
        self.slider.on_update(self._on_slider)
        self.play_button.on_click(self._on_play)
        self.speed.on_update(self.operator_only(
            lambda e: e.client and s.play(s.view().playing, float(self.speed.value)),
            "change the playback speed"))
        self.trail.on_update(self.operator_only(
            lambda e: e.client and s.set_trail(self.trail.value), "change the trail"))
        self.move_button.on_click(self._on_move)
        self._shown: tuple | None = None
        self.when_closed(s.add_listener(lambda view, _changed: self.refresh(view)))
        self.when_closed(s.add_run_listener(lambda _run: self._show_run(s.view())))  # at once
        self.refresh(s.view())

    @operator_only(action="step through the waypoints")
    def _on_slider(self, event) -> None:
        if event.client is not None:
            self.session.inspect(int(self.slider.value) - 1)

    @operator_only(action="play the waypoints")
    def _on_play(self, event) -> None:
        view = self.session.view()
        plan = view.outcome.plan if view.outcome else None
        n = 0 if plan is None else plan.n
        if not view.playing and n < 2:  # nothing to play: say why instead of doing nothing
            why = ("No plan to play: the Grasp planner has none for the selected object."
                   if n == 0 else "The plan has one waypoint: nothing to play.")
            if event.client is not None:
                event.client.add_notification("Waypoints", why, color="yellow",
                                              auto_close_seconds=4)
            return
        self.session.play(not view.playing, float(self.speed.value))

    @operator_only(action="move the arm")
    def _on_move(self, event) -> None:
        kappa = self.session.inspected_kappa()
        if kappa is None:
            if event.client is not None:
                event.client.add_notification("Waypoints", "No plan to move along.",
                                              color="yellow", auto_close_seconds=4)
            return
        self.app.store.request(kappa, "planner")

    def on_refused(self, event) -> None:
        """Put a refused viewer's slider / speed / trail edit back, for everyone."""
        view, target = self.session.view(), target_of(event)
        if target is self.slider:
            self.slider.value = view.index + 1
        elif target is self.speed:
            self.speed.value = view.speed
        elif target is self.trail:
            self.trail.value = view.trail

    def _show_run(self, view: SessionView) -> None:
        """The line saying where the arm is (hidden while it runs nothing)."""
        text = run_html(view)
        if text != self.run_info.content:
            self.run_info.content = text
        self.run_info.visible = view.run is not None

    def refresh(self, view: SessionView) -> None:
        """Grasp worker thread: mirror the inspection state into the widgets."""
        plan = view.outcome.plan if view.outcome else None
        n = plan.n if plan is not None else 0
        run = view.run
        key = (id(plan), view.index, view.playing, None if run is None else run.key())
        if key == self._shown:
            return
        self._shown = key
        self._show_run(view)
        self.slider.max = max(n, 2)
        self.slider.disabled = n < 2
        if int(self.slider.value) != view.index + 1:
            self.slider.value = view.index + 1
        self.play_button.label = "Pause" if view.playing else "Play"
        self.info.content = waypoint_html(view)
