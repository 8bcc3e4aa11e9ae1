"""Final grasp shapes anywhere around the obstacles, each with its final approach: what the
long way round aims at when the local search only finds shapes on the wrong side.

The local search (:func:`core.planning.obstacle_planning.plan_around`) finds final shapes near
where Algorithm 1's warm starts lead; around an obstacle those often lie on the far side of it
in configuration space. :func:`grasp_shapes` samples the manifold of final shapes directly: each
sample is one findOptimalConfig solve (palm on the final circle, gripper facing the object)
whose cost pulls toward a random configuration of the curvature box (a seeded generator), with
the obstacle rows and the object's clearance rows as constraints, kept only when it is clear
of every obstacle by the clearance plus the planner's waypoint margin. :func:`approach_tails`
gives each shape its final approach: a relay on the circle ``delta_d`` further out (solved
next to the shape) and Algorithm 1 from it, kept only when every waypoint is solved and every
line certified clear of the obstacles and the object. The relays are the goals of
:func:`core.planning.goal_set_path.goal_set_path`.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import numpy.typing as npt

from core.planning import grasp_solver as gs
from core.planning.clearance import certify_lines
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import ObstacleSetup
from core.planning.plan_types import GraspPlan

Array = npt.NDArray[np.float64]

RELAY_STEPS = (0.1, 0.25, 0.5, 1.0)  # relay circles followed out, in delta_d beyond the final


@dataclasses.dataclass(frozen=True)
class ShapeSearch:
    """What :func:`grasp_shapes` found.

    Attributes:
        shapes: (k, N) final shapes clear of every obstacle (clearance + waypoint margin).
        tried: Solves run.
        solved: Solves that put the palm on the final circle (with or without obstacles).
        closest: Per obstacle, how many solved shapes had it as the one too close.
    """

    shapes: Array
    tried: int
    solved: int
    closest: Array


@dataclasses.dataclass(frozen=True)
class Tail:
    """A final shape's approach: Algorithm 1's plan from ``relay`` (every line certified)."""

    relay: Array
    plan: GraspPlan


def _final_offset(planner, radius: float) -> complex:
    return complex(planner.w_along, 2.0 * planner.g_off + float(radius))


def grasp_shapes(planner, setup: ObstacleSetup, center: complex, radius: float, count: int,
                 tries: int, seed: int, deadline: float,
                 plain: Array | None = None) -> ShapeSearch:
    """Up to ``count`` clear final shapes from at most ``tries`` solves (stops at ``deadline``,
    time.thread_time); ``plain`` (a final shape found without obstacles) is tried first."""
    m, cfg = planner.model, planner.config
    rng = np.random.default_rng(seed)
    off = _final_offset(planner, radius)
    rho = radius + m.half_width + cfg.clearance_margin
    rows = gs.joined(gs.Clearance(center, rho), setup.rows)
    w = np.asarray(cfg.weights, float)
    need = setup.clearance + cfg.clearance_margin
    shapes: list[Array] = []
    closest = np.zeros(len(setup.obstacles), int)
    tried = solved = 0
    while tried < tries and len(shapes) < count:
        if tried and time.thread_time() > deadline:
            break
        target = plain if (tried == 0 and plain is not None) else rng.uniform(m.lo, m.hi)
        tried += 1
        res = planner._solve(m, center, off, target, target, w, None, rows, opts=planner.solver)
        if not res.ok:
            free = gs.solve(m, center, off, target, target, w, None, gs.Clearance(center, rho),
                            opts=planner.solver)
            if free.ok:         # a grasp shape exists there, the obstacles are in its way
                solved += 1
                closest[int(np.argmin(setup.gaps(m, free.kappa) - setup.clearance))] += 1
            continue
        solved += 1
        gaps = setup.gaps(m, res.kappa)
        if gaps.min() < need or m.clearance_py(res.kappa.tolist(), center, radius) < 0.0:
            closest[int(np.argmin(gaps))] += 1
            continue
        if shapes and np.min(np.abs(np.array(shapes) - res.kappa).max(axis=1)) < 0.5:
            continue            # the same shape again
        shapes.append(res.kappa)
    return ShapeSearch(np.array(shapes).reshape(-1, m.n), tried, solved, closest)


def approach_tails(planner, constrained, setup: ObstacleSetup, shapes: Array, center: complex,
                   radius: float, delta_d: float, deadline: float) -> list[Tail]:
    """Each shape's final approach from a relay outside the final circle (see the module
    docstring): the relay is followed out from the shape by continuation, at most
    ``delta_d``, as far as it stays solvable and clear; shapes without one are left out."""
    m, cfg = planner.model, planner.config
    r_final = float(radius) + planner.g_off
    rows = gs.joined(gs.Clearance(center, float(radius) + m.half_width + cfg.clearance_margin),
                     setup.rows)
    w = np.asarray(cfg.weights, float)
    ctr = np.array([center.real, center.imag])
    need = setup.clearance + cfg.clearance_margin
    tails: list[Tail] = []
    for q in shapes:
        if time.thread_time() > deadline:
            break
        x, out = q, None
        for f in RELAY_STEPS:
            off = complex(planner.w_along, planner.g_off + r_final + f * delta_d)
            res = planner._solve(m, center, off, x, q, w, None, rows, opts=planner.solver)
            if not res.ok or setup.gaps(m, res.kappa).min() < need:
                break
            x, out = res.kappa, (res.kappa, f * delta_d * (1.0 - 1e-6))
        if out is None:
            continue
        try:
            plan = constrained._plan(out[0], ctr, radius, delta_d=out[1])
        except GraspRefused:
            continue
        if not plan.success or not _certified(planner, setup, plan):
            continue
        tails.append(Tail(out[0], plan))
    return tails


def _certified(planner, setup: ObstacleSetup, plan: GraspPlan) -> bool:
    """Every line of ``plan`` (from its kappa_meas) clear of the obstacles and the object."""
    m, n = planner.model, planner.config.line_samples
    chain = np.vstack([plan.kappa_meas[None], plan.kappas])
    obj = certify_lines(m, chain[:-1], chain[1:], complex(*plan.center), plan.radius, 0.0,
                        n).lower_bound
    return bool(obj.min() >= 0.0 and setup.certify(m, chain[:-1], chain[1:], n).min()
                >= setup.clearance and math.isfinite(float(plan.kappas.sum())))


@dataclasses.dataclass(frozen=True)
class ShapeOutcome:
    """What :func:`plan_by_shapes` found: a plan, or why not (``shapes`` empty: no clear final
    shape in ``search.tried`` solves; ``tails`` empty: none with a clear final approach; else
    no certified path to any of them)."""

    plan: GraspPlan | None
    search: ShapeSearch
    tails: int


def plan_by_shapes(planner, constrained, setup: ObstacleSetup, km: Array, center: npt.ArrayLike,
                   radius: float, delta_d: float, deadline: float, *, seed: int = 0,
                   count: int = 12, tries: int = 48, iterations: int = 3000,
                   plain: Array | None = None) -> ShapeOutcome:
    """Sample clear final shapes, give them their final approach, reach one of the relays
    from ``km`` by a certified path (:func:`goal_set_path`), splice; see the module doc."""
    from core.planning.clear_path import ClearPathProblem
    from core.planning.global_approach import splice
    from core.planning.goal_set_path import goal_set_path
    from core.planning.obstacles import Obstacle

    cfg = planner.config
    ctr = np.asarray(center, float)
    c = complex(ctr[0], ctr[1])
    search = grasp_shapes(planner, setup, c, radius, count, tries, seed, deadline, plain)
    tails = approach_tails(planner, constrained, setup, search.shapes, c, radius, delta_d,
                           deadline)
    if not tails:
        return ShapeOutcome(None, search, 0)
    obj = Obstacle("the object", c.real, c.imag, float(radius))
    problem = ClearPathProblem(planner.model, setup.gripper, setup.obstacles, setup.clearance,
                               0.0, extra=[(obj, cfg.clearance_margin)])
    relays = np.array([t.relay for t in tails])
    ok = problem.margin(relays) >= 0.0
    tails = [t for t, good in zip(tails, ok) if good]
    if not tails or problem.margin(np.asarray(km, float)) < 0.0:
        return ShapeOutcome(None, search, len(tails))
    path = goal_set_path(problem, np.asarray(km, float), relays[ok], deadline, seed,
                         cfg.line_samples, iterations)
    if path is None:
        return ShapeOutcome(None, search, len(tails))
    tail = tails[path.goal]
    plan = splice(planner, setup, dataclasses.replace(tail.plan, kappa_meas=np.asarray(km, float)),
                  0, path.kappas[1:])
    return ShapeOutcome(plan, search, len(tails))
