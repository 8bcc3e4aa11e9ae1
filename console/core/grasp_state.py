"""What the grasp session tells its views: a consistent snapshot (:class:`SessionView`) of the
table and the newest plan, and which parts of it changed, so views redraw only those.

The parts (``changed``) a listener of :class:`console.core.grasp_session.GraspSession` is told:

* ``objects``: the table objects or the selection;  ``obstacles``: the obstacles, the
  selected one or the clearance;  ``bin``: the bin;
* ``plan``: a new outcome;  ``inspect``: the inspected waypoint, playback or the trail;
* ``reach``: the reachability map (or its progress) or whether its shading is shown;
* ``planning``: only ``planning_s`` (a plan has run that long; nothing else is new);
* ``run``: what the arm runs (:class:`console.core.run_state.RunView`: its plan, waypoint or
  object changed, or it began or ended).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from console.core.run_state import RunView
from console.core.table_bin import TableBin
from console.core.table_scene import TableObject
from core.planning.obstacles import Obstacle, with_other_objects
from core.planning.plan_types import GraspPlan
from core.planning.reachability import ReachMap

LIVE_HZ = 20.0   # at most this many live re-plans a second while an object is dragged
PARTS = frozenset({"objects", "obstacles", "bin", "plan", "inspect", "reach", "planning",
                   "run"})


@dataclasses.dataclass(frozen=True)
class Outcome:
    """Result of the newest planning request: a plan, or the refusal in words."""

    obj: TableObject | None
    plan: GraspPlan | None
    refusal: str | None
    seq: int
    carry_note: str | None = None   # why the plan has no carry to the bin (grasp_carry)
    others: tuple[str, ...] = ()    # the other objects the plan kept clear of, as obstacles


@dataclasses.dataclass(frozen=True)
class SessionView:
    """Consistent snapshot of a grasp session for its views (3D layers, panels, recordings)."""

    objects: tuple[TableObject, ...]
    selected: str | None
    outcome: Outcome | None
    index: int
    playing: bool
    speed: float
    trail: bool
    reach: ReachMap | str | None
    reach_note: str = ""
    trail_from: int = 0     # the trail shows no waypoint before this one ("Clear trails")
    bin: TableBin | None = None  # where a row takes the objects, or None
    obstacles: tuple[Obstacle, ...] = ()
    obstacle_selected: str | None = None
    clearance: float = 0.0  # m, the planner keeps the arm this far from every obstacle
    planning_s: float | None = None  # s the running plan has taken so far (None: idle)
    show_reach: bool = True  # whether the reachability shading is shown
    run: RunView | None = None  # what the arm runs (from the loop's view), None: no task

    def running_other_plan(self) -> bool:
        """Whether the arm runs a plan other than the newest one here (the operator's next
        plan, drawn apart until executed)."""
        run = self.run
        if run is None:
            return False
        plan = self.outcome.plan if self.outcome is not None else None
        return run.plan is None or plan is None or not run.plan.same_waypoints(plan.kappas)

    def plan_obstacles(self, name: str | None = None) -> tuple[Obstacle, ...]:
        """What a plan for the object ``name`` (default: the selected one) keeps
        ``clearance`` from: the obstacles and every other object on the table (each a disk of
        its radius, :func:`core.planning.obstacles.with_other_objects`)."""
        target = self.selected if name is None else name
        return with_other_objects(self.obstacles,
                                  [o for o in self.objects if o.name != target])


# A listener of the session: the snapshot and the parts that changed (see the module docstring).
GraspListener = Callable[[SessionView, frozenset[str]], None]
