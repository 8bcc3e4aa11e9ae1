"""Data types of the grasp planner: its settings (from the robot file) and the plan it returns."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.robot_schema import Section
from core.units import fmt_deg, fmt_mm

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class PlannerConfig:
    """Planner settings, read from the robot file's ``[planner]`` table by :func:`core.robots.load`.

    Attributes:
        delta_d: Allowable incremental distance between approach circles (m) [paper].
        constraint_tolerance: The paper's solver tolerance on the constraints (2e-3) [paper]; the
            baselines are judged by it. This planner converges to 1e-8 m, far inside it.
        weights: Cost weights R_n, one per segment.
        clearance_margin: Gap the arm body keeps from the object at waypoints (m).
        base_keepout: Objects closer than this (plus their radius) to the base are refused (m).
        max_restarts: Extra starts tried when the warm-started solve of a radius fails.
        max_insertions: Bisection depth of waypoints inserted where a straight line in kappa
            between two waypoints would touch the object.
        line_samples: Initial samples per line for the clearance certificate.
        seed_table: Size of the cached table of sampled configurations used for restarts.
    """

    delta_d: float
    constraint_tolerance: float
    weights: tuple[float, ...]
    clearance_margin: float = 0.002
    base_keepout: float = 0.03
    max_restarts: int = 6
    max_insertions: int = 3
    line_samples: int = 8
    seed_table: int = 2048

    @classmethod
    def read(cls, sec: Section, n: int) -> "PlannerConfig":
        """Read ``[planner]`` of a soft-arm file for ``n`` segments; unknown keys are refused.

        ``weights`` defaults to 1 for every segment; one number applies to all segments.
        """
        d = cls(delta_d=0.05, constraint_tolerance=2e-3, weights=(1.0,) * n)
        cfg = cls(
            delta_d=sec.num("delta_d", lo=0, hi=10.0, strict_lo=True),
            constraint_tolerance=sec.num("constraint_tolerance", lo=0, hi=1.0, strict_lo=True),
            weights=sec.numbers("weights", n, lo=0, hi=1e9, strict_lo=True, default=1.0),
            clearance_margin=sec.num("clearance_margin", lo=0, hi=1.0, default=d.clearance_margin),
            base_keepout=sec.num("base_keepout", lo=0, hi=10.0, default=d.base_keepout),
            max_restarts=sec.integer("max_restarts", lo=0, hi=100, default=d.max_restarts),
            max_insertions=sec.integer("max_insertions", lo=0, hi=8, default=d.max_insertions),
            line_samples=sec.integer("line_samples", lo=1, hi=1000, default=d.line_samples),
            seed_table=sec.integer("seed_table", lo=1, hi=65_536, default=d.seed_table),
        )
        sec.finish()
        return cfg

    @classmethod
    def from_robot(cls, robot) -> "PlannerConfig":
        """The robot's ``[planner]`` (validated when the file was loaded)."""
        return robot.planner

    def validate(self, n: int) -> None:
        """Raise ValueError naming the bad setting."""
        if len(self.weights) != n or not all(math.isfinite(w) and w > 0 for w in self.weights):
            raise ValueError(f"planner.weights: need {n} positive numbers, got {self.weights}")
        for name in ("delta_d", "constraint_tolerance"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"planner.{name}: must be > 0, got {v!r}")
        for name in ("clearance_margin", "base_keepout"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"planner.{name}: must be >= 0, got {v!r}")
        for name in ("max_restarts", "max_insertions", "line_samples", "seed_table"):
            if getattr(self, name) < (1 if name in ("line_samples", "seed_table") else 0):
                raise ValueError(f"planner.{name}: too small, got {getattr(self, name)!r}")


@dataclasses.dataclass(frozen=True)
class RadiusFailure:
    """Why an approach radius of Algorithm 1 could not be planned.

    Attributes:
        index: Algorithm 1's i (1-based).
        radius: r_a,i (m).
        reason: ``curvature_limit`` (the palm cannot reach the circle tangentially within the
            curvature limits), ``clearance`` (only configurations or motions touching the
            object were found), or ``no_convergence`` (the solver ran out of iterations).
        detail: One sentence for the operator.
    """

    index: int
    radius: float
    reason: str
    detail: str


@dataclasses.dataclass(frozen=True)
class GraspPlan:
    """Approach waypoints for one object, in execution order, with their diagnostics.

    Waypoint arrays have one row per waypoint. Waypoints inserted by the planner between
    Algorithm 1's radii (to keep the swept path clear of the object) have ``inserted`` True;
    ``radii[~inserted]`` are exactly Algorithm 1's r_a,i = d1 - i d2 / numMoves.

    Attributes:
        center, radius: Object centre (2,) and radius.
        kappa_meas: Start configuration (N,) (also kappa_off of the cost).
        d1, d2, num_moves, delta_d: Algorithm 1's quantities.
        weights: Cost weights R (N,).
        radii: (n,) approach radii r_a.
        phis: (n,) angle of the palm point on its circle (rad); palm heading is phi + pi/2
            (``side`` left: counter-clockwise circles) or phi - pi/2 (right: clockwise).
        kappas: (n, N) waypoint curvatures.
        palm_poses: (n, 3) [x, y, theta] of the palm point w_t.
        clearance: (n,) gap between the arm body and the object's disk at each waypoint (m).
        path_clearance: (n,) certified lower bound of that gap along the straight line in kappa
            from the previous waypoint (kappa_meas for the first) to this one (m).
        inserted, clearance_constrained: (n,) flags: waypoint added by the planner; waypoint
            re-solved with clearance constraints because the plain optimum touched the object.
        iterations, restarts: (n,) solver iterations (all attempts) and extra starts used.
        solve_ms, cost, violation: (n,) solve time, cost sum R (kappa - kappa_off)^2 and
            palm-point error (m).
        status: (n,) ``ok`` or a failure reason per waypoint.
        failures: Failed radii with reasons.
        total_ms: Wall time of the whole plan.
        side: The side of the arm the gripper closes toward: ``left`` (Algorithm 1 as in the
            paper) or ``right`` (the mirror image, :mod:`core.planning.sides`).
        obstacles: The obstacles (``core.planning.obstacles.Obstacle``) planned around.
        obstacle_margin: The clearance the arm and gripper keep from them (m).
        obstacle_clearance: (n,) gap between the arm (gripper included) and the nearest
            obstacle at each waypoint (m); None without obstacles.
        obstacle_path_clearance: (n,) certified lower bound of that gap along the straight
            line in kappa into each waypoint (m); None without obstacles.
        carry: (m, N) the targets of the carry to the bin after the grasp (vias, then the bin
            pose), certified clear of the obstacles (:mod:`core.control.carry`); None: straight
            to the bin.
    """

    center: Array
    radius: float
    kappa_meas: Array
    d1: float
    d2: float
    num_moves: int
    delta_d: float
    weights: Array
    radii: Array
    phis: Array
    kappas: Array
    palm_poses: Array
    clearance: Array
    path_clearance: Array
    inserted: npt.NDArray[np.bool_]
    clearance_constrained: npt.NDArray[np.bool_]
    iterations: npt.NDArray[np.int64]
    restarts: npt.NDArray[np.int64]
    solve_ms: Array
    cost: Array
    violation: Array
    status: tuple[str, ...]
    failures: tuple[RadiusFailure, ...]
    total_ms: float
    side: str = "left"
    obstacles: tuple = ()
    obstacle_margin: float = 0.0
    obstacle_clearance: Array | None = None
    obstacle_path_clearance: Array | None = None
    carry: Array | None = None

    @property
    def n(self) -> int:
        """Number of waypoints."""
        return int(self.radii.shape[0])

    @property
    def success(self) -> bool:
        """True when every waypoint was planned and every motion between them is clear."""
        return not self.failures

    @property
    def circles(self) -> Array:
        """(n, 3) approach circles [cx, cy, r_a]."""
        return np.column_stack([np.broadcast_to(self.center, (self.n, 2)), self.radii])

    def summary(self) -> str:
        """One line for the operator, e.g. ``5 waypoints, 1.2 ms``."""
        text = f"{self.n} waypoints, {self.total_ms:.1f} ms"
        if self.failures:
            f = self.failures[0]
            text += f"; FAILED at radius {f.index} ({f.reason}): {f.detail}"
        return text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (arrays as lists)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = v.tolist()
            elif f.name in ("failures", "obstacles"):
                v = [dataclasses.asdict(x) for x in v]
            elif f.name == "status":
                v = list(v)
            out[f.name] = v
        out["success"] = self.success
        out["circles"] = self.circles.tolist()
        return out


def format_plan(plan: GraspPlan) -> str:
    """Human-readable table of a plan's waypoints: lengths in mm, angles in degrees, the unit
    in every header (``to_dict`` / ``--json`` stay SI)."""
    cx, cy = plan.center
    finger = ", right finger" if plan.side == "right" else ""
    lines = [f"Object at ({fmt_mm(cx)}, {fmt_mm(cy)}) mm, r = {fmt_mm(plan.radius)} mm{finger}: "
             f"{plan.summary()}",
             f"d1 = {fmt_mm(plan.d1)} mm, d2 = {fmt_mm(plan.d2)} mm, numMoves = {plan.num_moves}, "
             f"delta_d = {fmt_mm(plan.delta_d)} mm",
             f"{'#':>2} {'r_a (mm)':>8} {'phi (deg)':>9}  {'kappa (1/m)':^41}  {'palm x (mm)':>11} "
             f"{'palm y (mm)':>11} {'th (deg)':>8} {'clr (mm)':>8} {'path (mm)':>9} {'it':>3}  "
             "status"]
    for k in range(plan.n):
        kap = " ".join(f"{v + 0.0:6.2f}" for v in np.round(plan.kappas[k], 2))
        px, py, pt = plan.palm_poses[k]
        tag = "+" if plan.inserted[k] else " "
        lines.append(
            f"{k + 1:>2}{tag}{fmt_mm(plan.radii[k]):>8} {fmt_deg(plan.phis[k]):>9}  {kap}  "
            f"{fmt_mm(px):>11} {fmt_mm(py):>11} {fmt_deg(pt):>8} {fmt_mm(plan.clearance[k]):>8} "
            f"{fmt_mm(plan.path_clearance[k]):>9} {plan.iterations[k]:3d}  {plan.status[k]}")
    if plan.inserted.any():
        lines.append("+ inserted between Algorithm 1's radii to keep the swept path clear")
    if plan.obstacles and plan.obstacle_path_clearance is not None:
        names = ", ".join(o.name for o in plan.obstacles)
        lines.append(f"Obstacles ({names}): the arm and gripper keep >= "
                     f"{fmt_mm(float(np.min(plan.obstacle_path_clearance)))} mm from them "
                     f"between waypoints (certified; clearance {fmt_mm(plan.obstacle_margin)} "
                     f"mm)")
    return "\n".join(lines)
