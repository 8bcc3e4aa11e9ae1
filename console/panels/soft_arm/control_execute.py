"""Control panel (soft arm): Execute and Click to grasp act on the Objects panel's selected object.

One object model (issue 19.1 / 18): the objects are the Objects panel's (the grasp session's).
Execute acts on its selected object, with the Grasp planner's plan for exactly that object when
there is one (else the controller plans the approach), and says which; the state line names it
and counts waypoints as the planner does. *Click to grasp* places (or selects) an object in the
Objects panel where the click ray meets the table and executes it. Only Arm arms (issue 19.3):
Execute or a click while disarmed is refused with "Arm first (press Arm)". Once the arm has
released the object in the bin it is taken off the table (the Objects panel), as a row's
released objects are (:mod:`console.panels.soft_arm.control_row`), so no later grasp or row goes back
for it.

:class:`ExecuteControls` is built by the Control panel inside its folder (the target line,
*Execute grasp-and-place*, *Click to grasp*); the panel's state line and header fields name
:attr:`ExecuteControls.target`, what the last Execute acts on.
"""

from __future__ import annotations

import dataclasses
import html
from typing import Any

import numpy as np
import viser

from console.panels.common.base import operator_only
from console.panels.soft_arm.control_text import IDLE_PHASES, ExecuteTarget, execute_target, table_point
from console.core.run_state import fmt_seconds
from console.core.table_scene import validate_object
from core.control.run_estimate import LegTimer, plan_seconds
from console.panels.common.events import client_of
from hw_bridge.soft_arm_process import ARM_FIRST


def bin_sentence(robot: Any, table_bin: Any, radius: float) -> str:
    """Where Execute takes an object of ``radius`` (m): into ``table_bin`` (a placed
    ``console.core.table_bin.TableBin``), else into the robot file's ``[bin]`` (drawn dimmed on
    the table by ``console.scene.bin_view.BinView``), whose drop point of each finger is named."""
    if table_bin is not None:
        return f"into the {table_bin.describe()}"
    from console.core.table_bin import robot_file_drops
    drops = robot_file_drops(robot, radius)
    points = [f"({x * 1e3:.0f}, {y * 1e3:.0f}) mm" + (f" ({side} finger)" if len(drops) > 1 else "")
              for side, x, y in drops]
    return ("no bin placed: into the robot file's bin (drawn dimmed on the table), dropped at "
            + " or ".join(points) + "; to choose, set Table click places: Bin (top of Operate) "
            "and click the table")


def target_object(target: ExecuteTarget) -> Any:
    """``target`` as the session's TableObject (to validate it like the Objects panel does)."""
    from console.core.table_scene import TableObject
    return TableObject(target.name, target.x, target.y, target.r)


@dataclasses.dataclass
class SentGrasp:
    """A single grasp-and-place this console sent: the table object it takes (name and where
    it lay, m) and whether the arm has left the idle phases for it yet (a view from before the
    command still shows the last task's "released")."""

    name: str
    x: float
    y: float
    started: bool = False


class ExecuteControls:
    """The Control panel's target line, Execute button and Click to grasp (see the module
    docstring). ``panel`` is the Control panel (its ``ctl``, ``app``, ``is_disarmed``,
    ``refuse_action`` and ``report_done``); the task starts through the console core."""

    def __init__(self, panel: Any) -> None:
        self.panel, self.app = panel, panel.app
        gui = panel.gui
        self._timer = LegTimer(panel.app.robot)  # the estimate's (the grasp session's thread)
        self.target_md = gui.add_html(self._target_html())
        self.execute_btn = gui.add_button(
            "Execute grasp-and-place", icon=viser.Icon.PLAYER_PLAY,
            hint="the Objects panel's selected object, with the Grasp planner's plan for it "
                 "when there is one; arm first")
        self.click_mode = gui.add_checkbox("Click to grasp", False,
                                           hint="one click on the table places (or selects) an "
                                                "object there in the Objects panel and runs the "
                                                "whole grasp-and-place; arm first")
        self.execute_btn.on_click(operator_only(lambda e: self._execute(e), panel=panel,
                                                action="run grasp-and-place"))
        panel.app.server.scene.on_click()(self._on_scene_click)
        self.target: ExecuteTarget | None = None  # what the last Execute acts on
        self.sent: SentGrasp | None = None  # taken off the table once the arm released it
        panel.when_closed(self.app.soft_arm_grasp().add_listener(
            lambda _view, changed: changed != {"planning"} and self._show_target()))

    def _target_html(self) -> str:
        """Which object Execute would act on now (the Objects panel's selection), how long it
        would take (estimated from the plan) and, while the arm runs a task, that this is the
        next one, not the running one."""
        estimate = ""
        try:
            view = self.app.soft_arm_grasp().view()
            target = execute_target(view)
            seconds = self.estimate(target, view.bin)
            estimate = "" if seconds is None else f"{seconds:.1f}"
            text = html.escape(f"Execute acts on {target.describe()}; "
                               f"{bin_sentence(self.app.robot, view.bin, target.r)}")
            text += ("; ≈ " + fmt_seconds(seconds) + " (estimated from the plan)"
                     if seconds is not None else "; time estimated once planned")
            if view.run is not None:
                busy = view.run.object_text() or "a task"
                text = html.escape(f"The arm is running {busy}; next: ") + text
        except ValueError as exc:
            text = html.escape(str(exc))
        return f'<small data-testid="control-target" data-estimate="{estimate}">{text}</small>'

    def estimate(self, target: ExecuteTarget, table_bin: Any) -> float | None:
        """Estimated seconds of Execute with ``target``'s plan from where the arm is
        (:func:`core.control.run_estimate.plan_seconds`); None without a plan (the controller
        plans the approach: not known before)."""
        plan = target.plan
        if plan is None:
            return None
        view = getattr(self.panel.ctl, "view", None)
        c = None if view is None else view.snapshot.control
        now = (np.asarray(plan.kappas, float)[0] if c is None else
               c.kappa_meas if c.kappa_meas is not None else c.kappa_ref)
        carry = plan.carry
        if carry is None:
            bin_params = self.app.robot.bin if table_bin is None else table_bin.params()
            carry = bin_params.kappa_for(plan.side or "left")
        return plan_seconds(self.app.robot, self._timer, now, plan.kappas, carry)

    def _show_target(self) -> None:
        text = self._target_html()
        if text != self.target_md.content:
            self.target_md.content = text

    def _target(self, event: Any) -> ExecuteTarget | None:
        """The selected object (and its plan) Execute acts on, or None after telling the
        operator why (nothing is sent: a radius of 1e308 must not reach the arm)."""
        if self.panel.is_disarmed():  # arming is the operator's own act (issue 19.3)
            self.panel.refuse_action(event, "Arm first", ARM_FIRST)
            return None
        try:
            target = execute_target(self.app.soft_arm_grasp().view())
            validate_object(target_object(target), self.app.robot)
        except ValueError as exc:
            self.panel.refuse_action(event, "Refused", str(exc))
            return None
        return target

    def _run(self, event: Any, target: ExecuteTarget) -> None:
        """Send the grasp-and-place of ``target`` and tell the operator which object it is."""
        self.target = target
        sent = self.sent = SentGrasp(target.name, target.x, target.y)
        view = self.app.soft_arm_grasp().view()
        table_bin = view.bin  # a placed bin; None: the robot file's
        ctl, start = self.panel.ctl, self.app.core.start_motion
        if target.plan is not None:
            plan = target.plan
            fut = start(lambda: ctl.execute(plan, target.x, target.y, target.r,
                                            bin_params=table_bin))
        else:
            obstacles, clearance = view.plan_obstacles(target.name), float(view.clearance)
            fut = start(lambda: ctl.grasp_at(target.x, target.y, target.r, obstacles, clearance,
                                             bin_params=table_bin))
        fut.add_done_callback(lambda f: self._report(event, f, sent))
        client = client_of(event)
        if client is not None:
            where = bin_sentence(self.app.robot, table_bin, target.r)
            client.add_notification("Grasp-and-place", f"{target.describe()}; {where}",
                                    color="blue", auto_close_seconds=6.0)
        self.app.recorder.action(f"execute grasp-and-place: {target.describe()}", None)

    def _report(self, event: Any, fut: Any, sent: SentGrasp) -> None:
        """The control process took the grasp or refused it (then nothing leaves the table)."""
        if fut.exception() is not None and self.sent is sent:
            self.sent = None
        self.panel.report_done(event, fut)

    def show(self, view: Any) -> None:
        """The Control panel's refresh: once the arm, having started on the sent grasp, reads
        "released", its object leaves the table (if it still lies where it was grasped); a
        stop or a row ends the wait without taking anything off."""
        sent, c = self.sent, view.snapshot.control
        if sent is None or c is None:
            return
        if view.row is not None and view.row.running:
            self.sent = None
            return
        if c.phase not in IDLE_PHASES:
            sent.started = True
            return
        if not sent.started:
            return
        self.sent = None
        session = self.app.soft_arm_grasp()
        if c.phase != "released":
            return
        for o in session.view().objects:
            if o.name == sent.name and np.hypot(o.x - sent.x, o.y - sent.y) <= o.r:
                session.remove(o.name)
                self.app.recorder.action(f"{o.name} released in the bin: taken off the table",
                                         None)
                return

    def _execute(self, event: Any) -> None:
        target = self._target(event)
        if target is not None:
            self._run(event, target)

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
        if self.panel.is_disarmed():
            self.panel.refuse_action(event, "Arm first", ARM_FIRST)
            return
        session = self.app.soft_arm_grasp()
        try:  # the Objects panel's object there (selected), or a new one
            session.place(p[0], p[1])
        except ValueError as exc:
            self.panel.refuse_action(event, "Refused", str(exc))
            return
        target = self._target(event)
        if target is not None:
            self._run(event, target)
