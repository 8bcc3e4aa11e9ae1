"""Grasp plans around obstacles: try approaches until one keeps the whole arm clear, else say
which obstacle is in the way and by how much.

:func:`plan_around` is what ``GraspPlanner.plan(..., obstacles=..., clearance=...)`` runs:

1. Bad obstacles or clearance, an object on an obstacle, or an arm that already stands closer
   than the clearance to one are refused before any planning (:class:`GraspRefused`,
   ``bad_input`` or ``obstacle``).
2. The plain plan (Algorithm 1 without obstacles) is made first: if every waypoint-to-waypoint
   line is certified at least ``clearance`` from every obstacle
   (:func:`core.planning.obstacles.certify_obstacle_lines`, arm body and gripper), it is the
   plan; an object the arm cannot grasp even without obstacles is refused as before.
3. Otherwise the planner runs with the obstacles as constraints of every waypoint solve (padded
   by the planner's waypoint margin; restarts from table configurations clear of them),
   inserting waypoints where a line comes too close and going past an approach circle on
   which no clear shape is found: first with the operator's delta_d, then with more approach
   circles (delta_d / 2), then from other first configurations around the object (table
   configurations clear of the obstacles), for at most :data:`SEARCH_BUDGET_S`.
4. Then the long way round (``global_search``, :mod:`core.planning.global_approach`, every
   line certified): those plans with each line that is not clear replaced by a certified path
   (:func:`core.planning.clear_path.clear_path`); Algorithm 1 from relay configurations near
   the object reached by such a path; the clear final approach of one of the plans reached
   from ``kappa_meas`` by such a path; for what is left of the budget plus
   :data:`GLOBAL_BUDGET_S`.
5. Then final shapes sampled all around the object, each with its final approach, reached by
   a certified path to any of them (:func:`core.planning.grasp_shapes.plan_by_shapes`), for
   :data:`SHAPES_BUDGET_S` more (``shape_search``).
6. When none succeeds the request is refused (``obstacle``), naming the obstacle in the way,
   how close the plain approach comes to it, how much clearance is missing, and which case it
   is: no sampled grasp shape keeps the clearance from it, or clear grasp shapes exist but no
   clear way to them was found in the time.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time

import numpy as np
import numpy.typing as npt

from core.planning.feasibility import GraspRefused, seeds_near
from core.planning.global_approach import connect_final_approach, plan_by_relay, repair
from core.planning.grasp_shapes import ShapeOutcome, plan_by_shapes
from core.planning.obstacles import (GripperShape, Obstacle, ObstacleSetup, check_clearance,
                                     check_obstacles, first_overlap)
from core.planning.plan_types import GraspPlan

Array = npt.NDArray[np.float64]

OTHER_STARTS = 2        # first configurations around the object tried after the warm starts
OBSTACLE_RESTARTS = 2   # restarts per radius while planning around obstacles
SEARCH_BUDGET_S = 2.5   # s of the planning thread's CPU time: no new approach after this (refusal)
GLOBAL_BUDGET_S = 0.5   # the long way round gets what is left of that, plus this much
SHAPES_BUDGET_S = 1.0   # then sampled final shapes and a path to one of them get this much
SHAPES = {"count": 8, "tries": 24, "iterations": 800}   # that search's caps (deterministic)


class ObstacleRefused(GraspRefused):
    """No plan keeps the arm clear of an obstacle.

    Attributes:
        obstacle: Name of the obstacle in the way.
        gap: Closest the plain approach comes to it (m; negative: through it).
        clearance: The set clearance (m).
    """

    def __init__(self, message: str, obstacle: str, gap: float, clearance: float):
        super().__init__("obstacle", message)
        self.obstacle, self.gap, self.clearance = obstacle, gap, clearance

    def __reduce__(self):
        return (type(self), (str(self), self.obstacle, self.gap, self.clearance))


def _mm(v: float) -> str:
    return f"{v * 1e3:.0f} mm"


def _check(planner, km: Array, center, radius: float, obstacles: tuple[Obstacle, ...],
           clearance: float) -> ObstacleSetup:
    m = planner.model
    try:
        clearance = check_clearance(clearance)
        obstacles = check_obstacles(obstacles, m, planner.config.base_keepout)
    except (TypeError, ValueError) as exc:
        raise GraspRefused("bad_input", str(exc)[:1].upper() + str(exc)[1:] + ".") from None
    setup = ObstacleSetup.build(m, obstacles, GripperShape.from_robot(planner.robot), clearance,
                                planner.config.clearance_margin)
    ctr = np.asarray(center, float)
    if ctr.shape == (2,) and np.isfinite(ctr).all():
        hit = first_overlap(float(ctr[0]), float(ctr[1]), float(radius), obstacles)
        if hit is not None:
            o, gap = hit
            raise ObstacleRefused(
                f"The object overlaps {o.name} (by {_mm(-gap)}); move one of them.",
                o.name, gap, clearance)
    km = np.asarray(km, float)
    if km.shape == (m.n,) and np.isfinite(km).all() and obstacles:
        gaps = setup.gaps(m, km)
        j = int(np.argmin(gaps))
        if gaps[j] < clearance:
            o = obstacles[j]
            where = (f"overlaps it by {_mm(-gaps[j])}" if gaps[j] < 0 else
                     f"is {_mm(gaps[j])} from it")
            raise ObstacleRefused(
                f"The arm stands too close to {o.name} now: it {where}, the clearance is "
                f"{_mm(clearance)}. Move the arm or {o.name}, or lower the clearance.",
                o.name, float(gaps[j]), clearance)
    return setup


def _clear_lines(planner, setup: ObstacleSetup, plan: GraspPlan) -> tuple[Array, Array]:
    """Per-obstacle certified bounds (n, K) and sampled minima along the plan's lines."""
    chain = np.vstack([plan.kappa_meas[None], plan.kappas])
    cert = setup.certificate(planner.model, chain[:-1], chain[1:], planner.config.line_samples)
    return cert.lower_bound, cert.worst_tau


def _with_obstacles(planner, setup: ObstacleSetup, plan: GraspPlan) -> GraspPlan:
    """The plain plan with its obstacle fields filled in."""
    lb, _ = _clear_lines(planner, setup, plan)
    return dataclasses.replace(
        plan, obstacles=setup.obstacles, obstacle_margin=setup.clearance,
        obstacle_clearance=setup.gaps(planner.model, plan.kappas).min(axis=1, initial=math.inf),
        obstacle_path_clearance=lb.min(axis=1, initial=math.inf))


def _closest(planner, setup: ObstacleSetup, plan: GraspPlan) -> Array:
    """(K,) the smallest gap of the plan to each obstacle (dense sampling)."""
    chain = np.vstack([plan.kappa_meas[None], plan.kappas])
    tau = np.linspace(0.0, 1.0, 65)
    a, b = chain[:-1], chain[1:]
    ks = a[:, None, :] + tau[:, None] * (b - a)[:, None, :]
    return setup.gaps(planner.model, ks).min(axis=(0, 1))


def _other_starts(planner, setup: ObstacleSetup, km, center, radius: float,
                  dd: float) -> Array:
    """Table configurations that put the object-centre point near Algorithm 1's first
    approach circle with the arm clear of the obstacles: other directions to approach from,
    cheapest (closest to kappa_meas) first."""
    m = planner.model
    km = np.asarray(km, float)
    c = complex(*np.asarray(center, float))
    palm0, _ = m.point_py(km.tolist(), complex(planner.w_along, planner.g_off))
    d1 = abs(c - palm0)
    d2 = d1 - float(radius) - planner.g_off
    ra = d1 - d2 / max(1, math.floor(d2 / dd))
    seeds = seeds_near(m, c, complex(planner.w_along, planner.g_off + ra), 64,
                       planner.config.seed_table)
    clear = seeds[setup.gaps(m, seeds).min(axis=1) >= setup.clearance
                  + planner.config.clearance_margin]
    cost = ((clear - km) ** 2) @ np.asarray(planner.config.weights, float)
    return clear[np.argsort(cost)][:OTHER_STARTS]


def plan_around(planner, kappa_meas: npt.ArrayLike, center: npt.ArrayLike, radius: float,
                delta_d: float | None, weights: npt.ArrayLike | None,
                obstacles: tuple[Obstacle, ...], clearance: float,
                global_search: bool = True, shape_search: bool = True) -> GraspPlan:
    """Plan a grasp that keeps the arm and gripper ``clearance`` from every obstacle; see the
    module docstring (``global_search`` False: the local search only, steps 1-3 and 5).
    Raises :class:`GraspRefused` (``ObstacleRefused`` when obstacles are in the way)."""
    setup = _check(planner, kappa_meas, center, radius, tuple(obstacles), clearance)
    kw = dict(delta_d=delta_d, weights=weights)
    plain = planner._plan(kappa_meas, center, radius, **kw)   # refuses what cannot work at all
    if setup.rows is None:
        return _with_obstacles(planner, setup, plain)
    if plain.success:
        lb, _ = _clear_lines(planner, setup, plain)
        if lb.min(initial=math.inf) >= setup.clearance:
            return _with_obstacles(planner, setup, plain)
    constrained = copy.copy(planner)
    constrained.obstacles = setup
    cfg = planner.config
    constrained.config = dataclasses.replace(cfg, max_restarts=min(cfg.max_restarts,
                                                                   OBSTACLE_RESTARTS))
    dd = cfg.delta_d if delta_d is None else float(delta_d)
    km = np.asarray(kappa_meas, float)
    attempts = [dict(kw), dict(kw, delta_d=dd / 2.0)]
    attempts += [dict(kw, first_start=s)
                 for s in _other_starts(planner, setup, km, center, radius, dd)]
    first: GraspPlan | None = None
    made = [plain] if plain.success else []
    tried = 0
    deadline = time.thread_time() + SEARCH_BUDGET_S  # CPU time: load does not change the answer
    for attempt in attempts:
        if tried and time.thread_time() > deadline:
            break
        tried += 1
        try:
            plan = constrained._plan(km, center, radius, **attempt)
        except GraspRefused:        # no final configuration clear of the obstacles
            continue
        first = first or plan
        if plan.success:
            return plan
        made.append(plan)
    shapes: ShapeOutcome | None = None
    t_shapes = 0.0
    if global_search and plain.success:
        end = deadline + GLOBAL_BUDGET_S
        found = next((p for p in (repair(planner, setup, q, end) for q in made[1:])
                      if p is not None), None)
        if found is None:
            found = plan_by_relay(planner, constrained, setup, km, center, radius, dd, kw, end)
        if found is None:
            found = connect_final_approach(planner, setup, km, made[1:] + made[:1], end)
        if found is None and shape_search:
            t0 = time.thread_time()
            known = made[0].kappas[-1] if plain.success else None
            shapes = plan_by_shapes(planner, constrained, setup, km, center, radius, dd,
                                    max(end, t0) + SHAPES_BUDGET_S, plain=known, **SHAPES)
            found, t_shapes = shapes.plan, time.thread_time() - t0
        if found is not None:
            return found
    if not plain.success:
        return first if first is not None else plain
    raise _refusal(setup, _closest(planner, setup, plain), tried, shapes, t_shapes)


def _refusal(setup: ObstacleSetup, gaps: Array, tried: int, shapes: ShapeOutcome | None,
             seconds: float) -> ObstacleRefused:
    """The refusal: the obstacle in the way (the one the sampled grasp shapes were most
    often too close to, else the one the plain approach comes closest to), and which case."""
    j = int(np.argmin(gaps))
    if shapes is not None and not len(shapes.search.shapes) and shapes.search.closest.any():
        j = int(np.argmax(shapes.search.closest))
    o, gap = setup.obstacles[j], float(gaps[j])
    how = (f"passes through it by {_mm(-gap)}" if gap < 0 else f"passes {_mm(gap)} from it, "
           f"{_mm(setup.clearance - gap)} inside the clearance")
    approaches = f"{tried} approach{'es' if tried > 1 else ''} tried"
    if shapes is None:
        why = f"no approach found keeps the arm and gripper {_mm(setup.clearance)} clear of it"
    elif not len(shapes.search.shapes):
        why = (f"no grasp shape found keeps the arm and gripper {_mm(setup.clearance)} clear "
               f"of it ({shapes.search.solved} of {shapes.search.tried} sampled grasp shapes "
               f"reach the object, each closer)")
    else:
        n = len(shapes.search.shapes)
        why = (f"grasp shapes {_mm(setup.clearance)} clear of it exist ({n} found, "
               f"{shapes.tails} with a clear final approach) but no clear way to them was "
               f"found in {seconds:.1f} s ({approaches})")
        approaches = ""
    return ObstacleRefused(
        f"{o.name} is in the way: {why}{f' ({approaches})' if approaches else ''}; the direct "
        f"approach {how}. Move {o.name} or the object, or lower the clearance.",
        o.name, gap, setup.clearance)
