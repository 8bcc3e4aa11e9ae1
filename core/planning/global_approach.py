"""The long way round to a grasp: when every local approach around the obstacles fails, keep
Algorithm 1's final approach and reach its first waypoint by a certified path.

:func:`plan_around <core.planning.obstacle_planning.plan_around>` searches locally (obstacle
rows in the waypoint solves, more circles, other first configurations): it fails when the arm
has to go round an obstacle the straight lines in kappa from ``kappa_meas`` cannot clear. The
plans it made still end well: their last waypoints, near the object, are solved and clear.
:func:`connect_final_approach` takes the longest such tail of each plan (every waypoint solved,
at least the clearance from every obstacle, every line between them certified), and connects
``kappa_meas`` to its first waypoint with :func:`core.planning.clear_path.clear_path` (arm and
gripper clear of the obstacles by the clearance and of the object by the planner's margin).
The vias become inserted waypoints of an ordinary :class:`GraspPlan`, every line certified.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import wrap
from core.planning.clear_path import ClearPathProblem, ClearPathRefused, clear_path
from core.planning.clearance import certify_lines
from core.planning.feasibility import GraspRefused, seeds_near
from core.planning.obstacles import Obstacle, ObstacleSetup
from core.planning.plan_types import GraspPlan

Array = npt.NDArray[np.float64]

MIN_TAIL_BUDGET_S = 0.2     # s: a tail is tried with at least this much search
RELAY_CIRCLES = (1.0, 2.0, 3.0)  # relay palms this many delta_d outside the final circle
RELAYS = 12                 # relay configurations tried at most
RELAY_BUDGET_S = 0.15       # s of path search to each relay


def clear_tail(planner, setup: ObstacleSetup, plan: GraspPlan) -> int | None:
    """Index of the first waypoint of ``plan``'s longest clear tail (None: none)."""
    m, cfg = planner.model, planner.config
    k = np.asarray(plan.kappas, float)
    if not len(k):
        return None
    gaps = setup.gaps(m, k).min(axis=1, initial=math.inf)
    lines = setup.certify(m, k[:-1], k[1:], cfg.line_samples) if len(k) > 1 else np.array([])
    obj = certify_lines(m, k[:-1], k[1:], complex(*plan.center), plan.radius, 0.0,
                        cfg.line_samples).lower_bound if len(k) > 1 else np.array([])
    first = None
    for i in range(len(k) - 1, -1, -1):
        # A waypoint marked "clearance" was solved; only the line into it is not clear, and
        # that line is replaced. Any other failure leaves no usable shape.
        usable = plan.status[i] == "ok" or (i < len(k) - 1 and plan.status[i] == "clearance"
                                            and plan.clearance[i] >= 0.0)
        if not usable or gaps[i] < setup.clearance:
            break
        if i < len(k) - 1 and (lines[i] < setup.clearance or obj[i] < 0.0):
            break
        first = i
    return first


def connect_final_approach(planner, setup: ObstacleSetup, km: Array, plans: Sequence[GraspPlan],
                           deadline: float, seed: int = 0) -> GraspPlan | None:
    """A plan reaching one of ``plans``' clear tails from ``km`` (see the module docstring),
    longest tail first; None when none connects before ``deadline`` (time.thread_time: the planning thread's CPU time)."""
    cfg = planner.config
    tails = []
    for plan in plans:
        i = clear_tail(planner, setup, plan)
        if i is not None:
            tails.append((i - plan.n, len(tails), plan, i))
    for _, _, plan, i in sorted(tails, key=lambda t: t[:2]):
        budget = max(MIN_TAIL_BUDGET_S, deadline - time.thread_time())
        problem = _problem(planner, setup, plan)
        try:
            path = clear_path(problem, km, plan.kappas[i], budget_s=budget, seed=seed,
                              samples=cfg.line_samples, goal_name="the final approach",
                              hints=plan.kappas[:i])
        except ClearPathRefused:
            if time.thread_time() > deadline:
                break
            continue
        out = splice(planner, setup, plan, i, path.kappas[1:-1])
        if out is not None:
            return out
    return None


def plan_by_relay(planner, constrained, setup: ObstacleSetup, km: Array, center: Array,
                  radius: float, delta_d: float, kw: dict, deadline: float,
                  seed: int = 0) -> GraspPlan | None:
    """Algorithm 1 from a relay configuration near the object (a table configuration with the
    palm a few ``delta_d`` outside the final circle, clear of the obstacles and the object),
    reached from ``km`` by a certified path; the cheapest relays (cost to ``km``) first."""
    m, cfg = planner.model, planner.config
    c = complex(float(center[0]), float(center[1]))
    seeds = np.vstack([seeds_near(m, c, complex(planner.w_along, 2.0 * planner.g_off + radius
                                                + k * delta_d), 32, cfg.seed_table)
                       for k in RELAY_CIRCLES])
    seeds = setup.clear_seeds(m, seeds, cfg.clearance_margin)
    if not len(seeds):
        return None
    body = m.body_clearance(seeds, c, radius)
    seeds = seeds[body >= cfg.clearance_margin]
    cost = ((seeds - km) ** 2) @ np.asarray(cfg.weights, float)
    obj = Obstacle("the object", c.real, c.imag, float(radius))
    problem = ClearPathProblem(m, setup.gripper, setup.obstacles, setup.clearance, 0.0,
                               extra=[(obj, cfg.clearance_margin)])
    for v in seeds[np.argsort(cost)][:RELAYS]:
        if time.thread_time() > deadline:
            break
        try:
            path = clear_path(problem, km, v, budget_s=RELAY_BUDGET_S, seed=seed,
                              samples=cfg.line_samples, goal_name="a relay")
            plan = constrained._plan(v, center, radius, **kw)
        except GraspRefused:
            continue
        if not plan.success:
            plan = repair(planner, setup, plan, min(deadline, time.thread_time()
                                                    + RELAY_BUDGET_S), seed)
        if plan is not None:
            out = splice(planner, setup, dataclasses.replace(plan, kappa_meas=km), 0,
                         path.kappas[1:])
            if out is not None:
                return out
    return None


def repair(planner, setup: ObstacleSetup, plan: GraspPlan, deadline: float,
           seed: int = 0) -> GraspPlan | None:
    """``plan`` with each line that is not clear (a waypoint marked ``clearance``: solved, the
    line into it not clear) replaced by a certified path; None if a waypoint has no usable
    shape or a path is not found before ``deadline``."""
    cfg = planner.config
    k = np.asarray(plan.kappas, float)
    if not len(k) or any(s not in ("ok", "clearance") for s in plan.status):
        return None
    bad = [i for i, s in enumerate(plan.status) if s == "clearance"]
    if not bad or np.any(plan.clearance[bad] < 0.0):
        return None
    if np.any(setup.gaps(planner.model, k[bad]).min(axis=1) < setup.clearance):
        return None
    problem = _problem(planner, setup, plan)
    inserts = {}
    for i in bad:
        a = plan.kappa_meas if i == 0 else k[i - 1]
        try:
            path = clear_path(problem, a, k[i], samples=cfg.line_samples, seed=seed,
                              budget_s=max(MIN_TAIL_BUDGET_S, deadline - time.thread_time()),
                              goal_name="the next waypoint")
        except GraspRefused:
            return None
        inserts[i] = path.kappas[1:-1]
    return splice(planner, setup, plan, 0, inserts)


def _problem(planner, setup: ObstacleSetup, plan: GraspPlan) -> ClearPathProblem:
    obj = Obstacle("the object", float(plan.center[0]), float(plan.center[1]),
                   float(plan.radius))
    return ClearPathProblem(planner.model, setup.gripper, setup.obstacles, setup.clearance,
                            0.0, extra=[(obj, planner.config.clearance_margin)])


def splice(planner, setup: ObstacleSetup, plan: GraspPlan, first: int,
           vias: Array | dict[int, Array]) -> GraspPlan | None:
    """``plan`` from waypoint ``first`` on with inserted waypoints: ``vias`` before ``first``,
    or a dict {waypoint index: vias before it}; None if a line of the result is not
    certified clear (object and obstacles)."""
    t0 = time.perf_counter()
    m = planner.model
    c = complex(*plan.center)
    inserts = vias if isinstance(vias, dict) else {first: vias}
    rows: list[tuple[int, Array | None]] = []     # (source waypoint or -1, via kappa)
    for j in range(first, plan.n):
        rows += [(-1, v) for v in np.asarray(inserts.get(j, ()), float).reshape(-1, m.n)]
        rows.append((j, None))
    kappas = np.array([plan.kappas[j] if v is None else v for j, v in rows])
    chain = np.vstack([plan.kappa_meas[None], kappas])
    obj = certify_lines(m, chain[:-1], chain[1:], c, plan.radius, 0.0,
                        planner.config.line_samples).lower_bound
    obs = setup.certify(m, chain[:-1], chain[1:], planner.config.line_samples)
    if obj.min() < 0.0 or obs.min() < setup.clearance:
        return None
    w = np.asarray(plan.weights, float)

    def via_row(v: Array) -> dict:
        p, th = m.point_py(v.tolist(), complex(planner.w_along, planner.g_off))
        return dict(radii=abs(c - p), phis=wrap(th - 0.5 * math.pi), palm_poses=[p.real, p.imag,
                    th], clearance=m.clearance_py(v.tolist(), c, plan.radius), inserted=True,
                    clearance_constrained=False, iterations=0, restarts=0, solve_ms=0.0,
                    cost=float(w @ (v - plan.kappa_meas) ** 2), violation=0.0)

    fields = ("radii", "phis", "palm_poses", "clearance", "inserted", "clearance_constrained",
              "iterations", "restarts", "solve_ms", "cost", "violation")
    cols: dict[str, list] = {f: [] for f in fields}
    for j, v in rows:
        row = via_row(v) if v is not None else {f: getattr(plan, f)[j] for f in fields}
        for f in fields:
            cols[f].append(row[f])
    arrays = {f: np.asarray(cols[f], dtype=np.asarray(getattr(plan, f)).dtype) for f in fields}
    return dataclasses.replace(
        plan, kappas=kappas, path_clearance=obj, **arrays,
        status=tuple("ok" for _ in rows), failures=(),
        total_ms=plan.total_ms + (time.perf_counter() - t0) * 1e3,
        obstacles=setup.obstacles, obstacle_margin=setup.clearance,
        obstacle_clearance=setup.gaps(m, kappas).min(axis=1, initial=math.inf),
        obstacle_path_clearance=obs)
