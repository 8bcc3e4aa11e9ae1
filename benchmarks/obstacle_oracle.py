"""The obstacle benchmark's oracle: slow, large-budget answer to "does a clear grasp plan
exist here?", so the planner's refusals can be told apart from spots with no plan.

For one blocked spot it samples many final grasp shapes (palm on the final circle, gripper
facing the object; :func:`core.planning.grasp_shapes.grasp_shapes`, each clear of the obstacle
by the clearance plus the waypoint margin), gives each its final approach
(:func:`~core.planning.grasp_shapes.approach_tails`) and searches a certified path from the
straight arm to any of them (:func:`core.planning.goal_set_path.goal_set_path`), with budgets
a user would not wait for, over several seeds. The answer is one of:

* ``planned``: a plan (the benchmark checks it by dense forward kinematics, not by the
  certificate);
* ``unconnected``: clear grasp shapes with a clear final approach exist, none was reached;
* ``no_tail``: clear grasp shapes exist, none has a clear final approach;
* ``no_shape``: no clear grasp shape among the samples (not a proof: a sample count).
"""

from __future__ import annotations

import copy
import dataclasses
import time

import numpy as np

from core.planning.grasp_shapes import plan_by_shapes
from core.planning.obstacle_planning import OBSTACLE_RESTARTS, _check

SEEDS = (0, 1)          # independent searches
BUDGET_S = 12.0         # CPU s per seed
CAPS = {"count": 24, "tries": 160, "iterations": 6000}


@dataclasses.dataclass(frozen=True)
class OracleAnswer:
    verdict: str        # planned | unconnected | no_tail | no_shape
    plan: object | None
    shapes: int
    tails: int
    seconds: float


def oracle(planner, km, center, radius: float, obstacles, clearance: float,
           quick: bool = False) -> OracleAnswer:
    """The oracle's answer for one request (see the module docstring)."""
    km = np.asarray(km, float)
    setup = _check(planner, km, center, radius, tuple(obstacles), clearance)
    constrained = copy.copy(planner)
    constrained.obstacles = setup
    constrained.config = dataclasses.replace(planner.config, max_restarts=OBSTACLE_RESTARTS)
    t0 = time.thread_time()
    shapes = tails = 0
    for seed in SEEDS[:1] if quick else SEEDS:
        out = plan_by_shapes(planner, constrained, setup, km, center, radius,
                             planner.config.delta_d, time.thread_time() + BUDGET_S, seed=seed,
                             **CAPS)
        shapes, tails = max(shapes, len(out.search.shapes)), max(tails, out.tails)
        if out.plan is not None:
            return OracleAnswer("planned", out.plan, shapes, tails, time.thread_time() - t0)
    verdict = "no_shape" if not shapes else "no_tail" if not tails else "unconnected"
    return OracleAnswer(verdict, None, shapes, tails, time.thread_time() - t0)
