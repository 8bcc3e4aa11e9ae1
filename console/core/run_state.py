"""What the arm is running, read from the loop's published view, so every part of the screen
shows the ARM's plan (issue 31.1): the plan it executes, its current waypoint, the row's object
"k of n", the remaining time and the progress.

:func:`run_of` turns one :class:`hw_bridge.soft_arm_process.ControlView` into a :class:`RunView`
(None while the arm runs no task). The Control panel hands it to the grasp session
(:meth:`console.core.grasp_session.GraspSession.set_run`), whose listeners (the 3D layers, the
Waypoints panel) draw it; the header and the progress bar read the same :class:`RunView`. Nothing
here guesses: the plan and the waypoint are the loop's, the times are
:mod:`core.control.run_estimate`'s from that plan.

Headless and pure (no viser, no threads).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from core.control.run_estimate import ExecutingPlan, LegTimer, remaining_seconds
from core.robots import SoftArm

IDLE = ("idle", "released", "stopped")


@dataclasses.dataclass(frozen=True)
class RunView:
    """The task the arm runs, as the loop published it.

    Attributes:
        phase: The state machine's phase.
        plan: The plan it executes (None while it settles or plans).
        waypoint: The waypoint it goes to (0-based) while approaching, else None.
        name: The object's name when this console knows it (else None).
        index: The object's place in the order the row takes them (0-based: the objects
            finished before it), None for a single grasp.
        count: How many objects the row takes (1 for a single grasp).
        remaining_s: Estimated seconds to the release of this object (None: not known yet).
        row_remaining_s: The same for the whole row: this object's and the objects not yet
            begun (:func:`row_seconds`); equals ``remaining_s`` for a single grasp.
        fraction: Done, 0..1 (of the row for a row).
    """

    phase: str
    plan: ExecutingPlan | None
    waypoint: int | None
    name: str | None
    index: int | None
    count: int
    remaining_s: float | None
    row_remaining_s: float | None
    fraction: float

    def key(self) -> tuple[Any, ...]:
        """What the drawn plan and its label depend on: the plan, the waypoint, the object and
        the phase (the label says "grasp (after 5 waypoints)", then "move_to_bin (…)"), not the
        times."""
        p = self.plan
        plan_key = None if p is None else (p.kappas.tobytes(), p.center, p.replans)
        return (plan_key, self.waypoint, self.name, self.index, self.count, self.phase)

    def object_text(self) -> str:
        """ "Object 2 (object 2 of 3)", "Object 1", or "object 2 of 3"; empty if nothing known."""
        row = "" if self.index is None else f"object {self.index + 1} of {self.count}"
        if self.name and row:
            return f"{self.name} ({row})"
        return self.name or row

    def waypoint_text(self) -> str:
        """ "waypoint 3 of 9" while approaching; the phase otherwise (the plan's length)."""
        if self.plan is None:
            return self.phase
        if self.waypoint is not None:
            return f"waypoint {self.waypoint + 1} of {self.plan.n}"
        n = self.plan.n
        return f"{self.phase} (after {n} waypoint{'s' if n != 1 else ''})" if self.phase in (
            "grasp", "move_to_bin", "release") else self.phase

    def time_text(self) -> str:
        """ "≈ 42 s left" (the row's, for a row), or "time left: estimating" without a plan."""
        left = self.row_remaining_s
        return "time left: estimating (no plan yet)" if left is None else \
            f"≈ {fmt_seconds(left)} left"


def fmt_seconds(s: float) -> str:
    """Seconds for people: "42 s", "1 min 05 s"."""
    s = max(0, round(float(s)))
    return f"{s} s" if s < 60 else f"{s // 60} min {s % 60:02d} s"


def run_of(view: Any, robot: SoftArm, timer: LegTimer, names: tuple[str, ...] | None = None,
           single: str | None = None) -> RunView | None:
    """The task the arm runs according to ``view`` (a ControlView), or None when it runs none.

    Args:
        view: The loop's newest published view.
        robot: The soft arm (its state machine's waits).
        timer: Times the reference's legs (:class:`core.control.run_estimate.LegTimer`).
        names: The objects' names of the row this console sent, in order (None: unknown).
        single: The object's name of a single grasp this console sent (None: unknown).
    """
    c = None if view is None else view.snapshot.control
    if c is None or not c.armed:
        return None
    row = getattr(view, "row", None)
    in_row = row is not None and row.running
    if c.phase in IDLE and not in_row:
        return None
    plan: ExecutingPlan | None = getattr(view, "executing", None)
    kappa = c.kappa_meas if c.kappa_meas is not None else c.kappa_ref
    left = remaining_seconds(robot, timer, c.phase, kappa, plan, c.waypoint)
    waypoint = c.waypoint if c.phase == "approach" and plan is not None else None
    elapsed = max(0.0, c.t - plan.started_t) if plan is not None else 0.0
    own = 0.0 if left is None else (left / (elapsed + left) if elapsed + left > 0 else 0.0)
    done_here = 1.0 - own if left is not None else 0.0
    if in_row:
        queued, n = int(row.current or 0), int(row.n)
        name = names[queued] if names is not None and queued < len(names) else None
        # Its place in the order taken: the objects finished before it. (A row takes an
        # object whose way a waiting one blocks after the others: the third in the queue
        # can be the first taken, and "object 3 of 3", no time left for the two waiting and
        # a bar two thirds full were shown with nothing released.)
        k = row_position(row)
        total, here = row_seconds(row, k, n, float(c.t), left, elapsed)
        return RunView(c.phase, plan, waypoint, name, k, n, left, total,
                       (k + (done_here if here is None else here)) / n)
    return RunView(c.phase, plan, waypoint, single, None, 1, left, left, done_here)


def row_position(row: Any) -> int:
    """The running object's place (0-based) in the order a row takes them: the objects finished
    before it (a row takes an object whose way a waiting one blocks after the others, so its
    place in the queue, ``row.current``, is not it)."""
    return min(len(getattr(row, "outcomes", ())), int(row.n) - 1)


def row_seconds(row: Any, k: int, n: int, t: float, left: float | None,
                elapsed: float) -> tuple[float | None, float | None]:
    """The row's remaining seconds with object ``k`` (0-based) of ``n`` under way at loop time
    ``t``, and (when estimated from the row's pace) the share of object ``k`` done.

    Each object not yet begun takes the row's own pace: the mean time its finished objects
    took (``row.outcomes``: loop-time start and end), from the bin to the bin; before the first
    is finished, the current object's whole estimate (``elapsed`` + ``left``). While the current
    object has no plan yet (``left`` None: settling, planning) its remaining time is that pace
    less the time since the previous object ended. None while nothing is known (the first
    object, before its plan)."""
    spans = [o.ended_s - o.started_s for o in getattr(row, "outcomes", ())
             if o.started_s is not None and o.ended_s is not None and o.ended_s >= o.started_s]
    pace = sum(spans) / len(spans) if spans else (None if left is None else elapsed + left)
    if pace is None:
        return None, None
    here: float | None = None
    if left is None:  # between objects: this one's plan is being made
        ends = [o.ended_s for o in row.outcomes if o.ended_s is not None]
        since = max(0.0, t - max(ends)) if ends else 0.0
        left = max(0.0, pace - since)
        here = 1.0 - left / pace if pace > 0 else 0.0
    return left + (n - k - 1) * pace, here
