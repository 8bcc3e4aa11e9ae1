"""Grasp Object Planner (Katzschmann 2015, Sec. 4.3, Algorithm 1) that plans in milliseconds.

``plan_grasp(robot, kappa_meas, center, radius)`` follows Algorithm 1: the palm point w_t of the
measured configuration gives d1 = |c - w_t|, d2 = d1 - r_o - g_off, numMoves =
max(1, floor(d2 / delta_d)) and the approach radii r_a,i = d1 - i d2 / numMoves; each radius is
solved by findOptimalConfig (min sum R (kappa - kappa_off)^2 with the palm point on the circle,
heading phi + pi/2, |kappa| <= kappa_max) with :mod:`core.planning.grasp_solver`, warm-started
from the previous radius, with restarts when that fails. What the paper leaves to its convexity
argument is checked and enforced: waypoints whose optimum lets the arm body touch the object are
re-solved with clearance constraints, and where the straight line in kappa between consecutive
waypoints (from kappa_meas) cannot be certified clear (:mod:`core.planning.clearance`),
waypoints are inserted between Algorithm 1's radii. Requests that cannot work raise
:class:`GraspRefused` with a plain-words reason (:mod:`core.planning.feasibility`).

Command line: ``python -m core.planning.grasp --object X Y R [--json]``
(:mod:`core.planning.grasp.__main__`).
"""

from __future__ import annotations

import cmath
import functools
import math
import time

import numpy as np
import numpy.typing as npt

from core.planning import grasp_solver as gs
from core.planning.arm_model import ArmModel, wrap
from core.planning.feasibility import (GraspRefused, best_start, check_request, find_final_config,
                                      seeds_near)
from core.planning.grasp_waypoint import REASONS, PlannedWaypoint
from core.planning.obstacles import Obstacle, ObstacleSetup
from core.planning.plan_types import GraspPlan, PlannerConfig, RadiusFailure, format_plan
from core.planning.sweep_clearance import SweepClearance

Array = npt.NDArray[np.float64]

__all__ = ["GraspPlan", "GraspPlanner", "GraspRefused", "Obstacle", "PlannerConfig",
           "RadiusFailure", "format_plan", "plan_grasp"]


class GraspPlanner(SweepClearance):
    """Algorithm 1 for one robot; keeps the model and settings between plans.

    With obstacles (``plan(..., obstacles=..., clearance=...)``) the plan is made by a shallow
    copy whose ``obstacles`` is set (:mod:`core.planning.obstacle_planning`), so one planner
    may serve several threads.
    """

    obstacles: ObstacleSetup | None = None  # set only on the per-plan copy

    def __init__(self, robot, config: PlannerConfig | None = None,
                 solver: gs.SolverOptions = gs.SolverOptions()):
        self.robot = robot
        self.config = config if config is not None else PlannerConfig.from_robot(robot)
        self.model = ArmModel.from_robot(robot)
        self.solver = solver
        self.w_along = robot.gripper.w_off_along
        self.g_off = robot.gripper.g_off

    def _offset(self, radius: float) -> complex:
        """Tip-frame offset of the object centre when the palm is on a circle of ``radius``."""
        return complex(self.w_along, self.g_off + radius)

    def plan(self, kappa_meas: npt.ArrayLike, center: npt.ArrayLike, radius: float, *,
             delta_d: float | None = None, weights: npt.ArrayLike | None = None,
             obstacles: tuple[Obstacle, ...] | list[Obstacle] = (),
             clearance: float = 0.0) -> GraspPlan:
        """Plan the approach to a cylinder at ``center`` (x, y) of ``radius``; see the module doc.

        Args:
            obstacles: Disks the whole arm, gripper included, keeps ``clearance`` (m) from, at
                and between waypoints (:func:`core.planning.obstacle_planning.plan_around`).

        Raises:
            GraspRefused: the request cannot work; the message says why (with obstacles:
                which obstacle is in the way and by how much).
        """
        if obstacles:
            from core.planning.obstacle_planning import plan_around
            return plan_around(self, kappa_meas, center, radius, delta_d, weights,
                               tuple(obstacles), clearance)
        return self._plan(kappa_meas, center, radius, delta_d=delta_d, weights=weights)

    def _plan(self, kappa_meas: npt.ArrayLike, center: npt.ArrayLike, radius: float, *,
              delta_d: float | None = None, weights: npt.ArrayLike | None = None,
              first_start: Array | None = None) -> GraspPlan:
        """:meth:`plan` without obstacle handling (``self.obstacles`` constrains it, if set);
        ``first_start`` replaces the first waypoint's warm start."""
        t_start = time.perf_counter()
        cfg, m = self.config, self.model
        # Checks on Python lists: with N = 6 each numpy call costs more than the arithmetic.
        km = np.asarray(kappa_meas, dtype=float)
        km_l = km.tolist()
        if km.shape != (m.n,) or not all(map(math.isfinite, km_l)):
            raise GraspRefused("bad_input", f"kappa_meas must be {m.n} finite curvatures, "
                               f"got shape {km.shape}.")
        ctr = np.asarray(center, dtype=float)
        if ctr.shape != (2,):
            raise GraspRefused("bad_input", f"The object centre must be (x, y), got {ctr!r}.")
        dd = cfg.delta_d if delta_d is None else float(delta_d)
        if not (math.isfinite(dd) and dd > 0):
            raise GraspRefused("bad_input", f"delta_d must be a positive distance, got {dd!r}.")
        w = np.asarray(cfg.weights if weights is None else weights, dtype=float)
        w_l = w.tolist()
        if w.shape != (m.n,) or not all(math.isfinite(v) and v > 0 for v in w_l):
            raise GraspRefused("bad_input", f"weights must be {m.n} positive numbers.")
        cx, cy = ctr.tolist()
        c, r_o = complex(cx, cy), float(radius)
        check_request(self.robot, m, km, c, r_o, cfg.base_keepout)

        # Algorithm 1: radii of the approach circles.
        palm0, _ = m.point_py(km_l, complex(self.w_along, self.g_off))
        d1 = abs(c - palm0)
        d2 = d1 - r_o - self.g_off
        num_moves = max(1, math.floor(d2 / dd))
        radii = [d1 - i * d2 / num_moves for i in range(1, num_moves + 1)]

        # Warm starts: the first radius from the best table configuration (or kappa_meas);
        # later radii from the previous waypoint moved along its sensitivity d kappa / d r_a
        # (the optimal kappa(r_a) is smooth); the plain previous waypoint is the first restart.
        wps: list[PlannedWaypoint] = []
        prev: PlannedWaypoint | None = None
        witness: Array | None = None
        witness_tried = False
        for i, ra in enumerate(radii, start=1):
            if prev is None:
                x, lam = km, None
                x0, lam0 = best_start(m, c, self._offset(ra), km, w, cfg.seed_table), None
                if first_start is not None:
                    x0 = first_start
            else:
                x, lam = prev.kappa, prev.lam
                x0, lam0 = x, lam
                if prev.dk is not None:
                    dr = ra - prev.radius
                    x0 = [min(max(a + dr * b, lo_j), hi_j) for a, b, lo_j, hi_j in
                          zip(x.tolist(), prev.dk.tolist(), m.py.lo, m.py.hi)]
                    lam0 = (lam[0] + dr * prev.dl[0], lam[1] + dr * prev.dl[1])
            wp = self._solve_radius(c, ra, x0, lam0, km, w, i, first_restart=x,
                                    tangent=i < num_moves)
            if wp.status != gs.OK:
                if not witness_tried:
                    witness, witness_tried = self._witness(c, r_o, km, w), True
                if witness is not None:
                    prev_r = wps[-1].radius if wps else d1
                    frac = (prev_r - ra) / max(prev_r - radii[-1], 1e-9)
                    wp = self._solve_radius(c, ra, x, lam, km, w, i,
                                            [x + frac * (witness - x), witness], wp)
            if wp.status != gs.OK and self.obstacles is not None:
                if i < num_moves:
                    continue    # no shape on this circle clears the obstacles: go past it
                wps.append(wp)
                break
            wps.append(wp)
            if wp.status == gs.OK:
                prev = wp
        wps = self._secure_clearance(wps, km, d1, c, r_o, w)
        return self._assemble(wps, km, ctr, r_o, d1, d2, num_moves, dd, w, t_start)

    # ------------------------------------------------------------------ per radius

    def _solve_radius(self, c: complex, ra: float, x0: Array, lam0, km: Array, w: Array,
                      index: int, seeds: list[Array] | None = None,
                      previous: PlannedWaypoint | None = None,
                      first_restart: Array | None = None, tangent: bool = True) -> PlannedWaypoint:
        """findOptimalConfig(r_a): from the warm start, then from restart seeds if that fails.

        With ``previous`` (a failed attempt at this radius) only ``seeds`` are tried and the
        statistics accumulate on it.
        """
        t0 = time.perf_counter()
        off = self._offset(ra)
        if previous is None:
            res = self._solve(self.model, c, off, x0, km, w, lam0, self._rows(), opts=self.solver,
                           tangent=tangent)
            wp = PlannedWaypoint(ra, res.kappa, res.lam, res.status, res.iterations, 0, 0.0, index,
                           cost=res.cost, violation=res.violation, error=res.error,
                           dk=res.dkappa_dr, dl=res.dlam_dr)
            if not res.ok:
                n = self.config.max_restarts
                seeds = [] if first_restart is None or first_restart is km else [first_restart]
                seeds = (seeds + [km] + self._table_seeds(c, off, n))[:n]
        else:
            wp = previous
        if wp.status != gs.OK:
            for s in seeds or []:
                wp.restarts += 1
                res = self._solve(self.model, c, off, s, km, w, clearance=self._rows(),
                               opts=self.solver, tangent=True)
                wp.iterations += res.iterations
                if res.ok:
                    wp.kappa, wp.lam, wp.status = res.kappa, res.lam, gs.OK
                    wp.dk, wp.dl = res.dkappa_dr, res.dlam_dr
                    wp.cost, wp.violation, wp.detail = res.cost, res.violation, ""
                    wp.error = res.error
                    break
            else:
                wp.detail = REASONS[wp.status][1]
        wp.ms += (time.perf_counter() - t0) * 1e3
        return wp

    def _table_seeds(self, c: complex, off: complex, n: int) -> list[Array]:
        """Table configurations whose object-centre point is nearest ``c``; around obstacles
        only those clear of them (other directions to approach from)."""
        if self.obstacles is None:
            return list(seeds_near(self.model, c, off, n, self.config.seed_table))
        return list(self.obstacles.clear_seeds(
            self.model, seeds_near(self.model, c, off, 16 * n, self.config.seed_table),
            self.config.clearance_margin)[:n])

    def _witness(self, c: complex, r_o: float, km: Array, w: Array) -> Array | None:
        """A final configuration, or GraspRefused('out_of_reach') if none can be found (around
        obstacles: None, and the planner goes on without one)."""
        cfg = self.config
        off = self._offset(r_o + self.g_off)
        seeds = None if self.obstacles is None else self._table_seeds(c, off, 2 * cfg.max_restarts)
        kappa, _ = find_final_config(self.model, c, r_o, off, km, w,
                                     cfg.clearance_margin, cfg.seed_table, cfg.max_restarts,
                                     self._rows(), seeds)
        if kappa is None and self.obstacles is not None:
            return None
        if kappa is None:
            raise GraspRefused(
                "out_of_reach",
                f"The object is out of reach: no arm shape within the curvature limit "
                f"(|kappa| <= {self.model.hi.max():g} 1/m) puts the gripper around it (on the "
                f"gripper's closing side) with the arm clear of it.")
        return kappa

    # ------------------------------------------------------------------ clearance

    def _solve(self, *args, **kwargs) -> gs.SolveResult:
        """:func:`grasp_solver.solve`; around obstacles a solve that ran out of iterations
        within :data:`core.planning.obstacles.NEAR_TOL` of every constraint counts as solved
        (the SQP's Hessian leaves out the distance rows' curvature, so it can creep along an
        active obstacle row; the rows are padded by the waypoint margin, and lines are
        certified anyway)."""
        res = gs.solve(*args, **kwargs)
        if res.status == gs.NO_CONVERGENCE and self.obstacles is not None:
            rows = kwargs.get("clearance", args[7] if len(args) > 7 else None)
            if self.obstacles.nearly_solved(self.model, res, rows):
                res.status = gs.OK
        return res

    def _rows(self):
        """Obstacle constraint rows for the solver (None without obstacles)."""
        return None if self.obstacles is None else self.obstacles.rows

    # ------------------------------------------------------------------ result

    def _assemble(self, wps: list[PlannedWaypoint], km: Array, ctr: Array, r_o: float, d1: float,
                  d2: float, num_moves: int, dd: float, w: Array, t_start: float) -> GraspPlan:
        m = self.model
        n_wp = len(wps)
        kappas = np.array([p.kappa for p in wps]).reshape(n_wp, m.n)
        th = (kappas @ m.lengths + m.theta0).tolist()
        # Palm point = object-centre point - r_a * (left normal): q_palm = c + (q - c) - i r e^{i th}.
        # Per-waypoint numbers are gathered in Python and turned into arrays in two calls (a
        # handful of waypoints: each numpy call would cost more than its arithmetic).
        c = complex(ctr[0], ctr[1])
        floats, ints, failures, status = [], [], [], []
        for p, t in zip(wps, th):
            q = c + p.error - 1j * p.radius * cmath.exp(1j * t)
            floats.append((p.radius, wrap(t - 0.5 * math.pi), q.real, q.imag, t, p.clearance,
                           p.path_clearance, p.ms, p.cost, p.violation,
                           p.obstacle_path_clearance))
            ints.append((p.depth > 0, p.constrained, p.iterations, p.restarts))
            if p.status != gs.OK:
                name = REASONS[p.status][0]
                failures.append(RadiusFailure(p.index, p.radius, name, p.detail))
                status.append(name)
            else:
                status.append("ok")
        fl = np.array(floats, float).reshape(n_wp, 11).T.copy()
        it = np.array(ints, np.int64).reshape(n_wp, 4).T.copy()
        obs = self.obstacles
        extra = {} if obs is None else dict(
            obstacles=obs.obstacles, obstacle_margin=obs.clearance,
            obstacle_clearance=obs.gaps(m, kappas).min(axis=1, initial=math.inf),
            obstacle_path_clearance=fl[10])
        return GraspPlan(
            center=ctr.copy(), radius=r_o, kappa_meas=km.copy(), d1=d1, d2=d2,
            num_moves=num_moves, delta_d=dd, weights=w.copy(), radii=fl[0], phis=fl[1],
            kappas=kappas, palm_poses=np.ascontiguousarray(fl[2:5].T), clearance=fl[5],
            path_clearance=fl[6],
            inserted=it[0].astype(bool), clearance_constrained=it[1].astype(bool),
            iterations=it[2], restarts=it[3], solve_ms=fl[7], cost=fl[8], violation=fl[9],
            status=tuple(status), failures=tuple(failures),
            total_ms=(time.perf_counter() - t_start) * 1e3, **extra)


class _Identity:
    """Hashable by identity, so a planner can be memoised per robot object."""

    def __init__(self, obj):
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other) -> bool:
        return isinstance(other, _Identity) and other.obj is self.obj


@functools.lru_cache(maxsize=4)
def _planner_for(key: _Identity) -> GraspPlanner:
    return GraspPlanner(key.obj)


def plan_grasp(robot, kappa_meas: npt.ArrayLike, center: npt.ArrayLike, radius: float, *,
               delta_d: float | None = None, weights: npt.ArrayLike | None = None,
               obstacles: tuple[Obstacle, ...] | list[Obstacle] = (),
               clearance: float = 0.0) -> GraspPlan:
    """Plan the approach to an object (Algorithm 1); see :class:`GraspPlanner`.

    Args:
        robot: A :class:`core.robots.SoftArm`.
        kappa_meas: Measured curvatures (N,), also the cost's kappa_off.
        center: Object centre (x, y) in m.
        radius: Object radius r_o in m.
        delta_d: Allowable incremental distance (default: the robot file's).
        weights: Cost weights R (N,) (default: the robot file's).
        obstacles: :class:`Obstacle` disks the arm and gripper keep ``clearance`` (m) from.

    Raises:
        GraspRefused: (a ValueError) when the grasp cannot work; the message says why.
    """
    return _planner_for(_Identity(robot)).plan(kappa_meas, center, radius, delta_d=delta_d,
                                               weights=weights, obstacles=obstacles,
                                               clearance=clearance)
