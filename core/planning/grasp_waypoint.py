"""A waypoint as Algorithm 1's planner (:mod:`core.planning.grasp`) works on it: one approach
radius's solve with its statistics and clearances, and the words a failed one is reported with.

Shared by the waypoint loop (``grasp/__init__.py``) and the clearance pass
(:mod:`core.planning.sweep_clearance`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from core.planning import grasp_solver as gs

Array = npt.NDArray[np.float64]

# Solver status -> (the plan's status name, why a radius failed in words).
REASONS = {
    gs.CURVATURE_LIMIT: ("curvature_limit", "the palm cannot lie tangent on this circle within "
                         "the curvature limits"),
    gs.NO_CONVERGENCE: ("no_convergence", "the optimiser did not converge"),
    gs.CLEARANCE: ("clearance", "every configuration found lets the arm touch the object"),
}


@dataclasses.dataclass(eq=False)
class PlannedWaypoint:
    """One approach radius's waypoint while the planner works on it (solve, statistics,
    clearances); :meth:`GraspPlanner._assemble` turns the list into a ``GraspPlan``."""

    radius: float
    kappa: Array
    lam: tuple[float, float] | None
    status: int
    iterations: int
    restarts: int
    ms: float
    index: int                  # Algorithm 1's i; inserted waypoints carry the next i
    depth: int = 0              # insertion depth (0 = Algorithm 1's radius)
    constrained: bool = False
    clearance: float = math.nan
    path_clearance: float = math.nan
    cost: float = math.nan
    violation: float = math.nan
    error: complex = 0j         # object-centre point error q - c of the solution
    obstacle_clearance: float = math.inf        # gap to the nearest obstacle here
    obstacle_path_clearance: float = math.inf   # certified bound along the line into it
    detail: str = ""
    dk: Array | None = None     # d kappa / d r_a at the solution (predictor)
    dl: tuple[float, float] | None = None


def sweep_detail(p: PlannedWaypoint, from_start: bool) -> str:
    """Why the line in kappa into ``p`` is not clear, in words."""
    where = ("the arm's current shape to the first waypoint" if from_start
             else "the previous waypoint")
    if p.path_clearance < 0.0:
        return (f"the motion from {where} would sweep the arm {-p.path_clearance * 1e3:.1f} mm "
                f"into the object")
    return (f"the motion from {where} would bring the arm within "
            f"{max(p.obstacle_path_clearance, 0.0) * 1e3:.1f} mm of an obstacle")
