"""Makes Algorithm 1's waypoints, and the straight lines in kappa between them, clear of the
object and of obstacles: what the paper leaves to its convexity argument, checked and enforced.

:class:`SweepClearance` is a part of :class:`core.planning.grasp.GraspPlanner` (which it is
mixed into, for ``model``, ``config``, ``obstacles``, ``solver`` and the per-radius solves
``_solve``, ``_rows``, ``_solve_radius``, ``_offset``): waypoints too close to the object are
re-solved with arm-body clearance constraints, and lines that cannot be certified clear get
waypoints inserted on intermediate circles (bisection).
"""

from __future__ import annotations

import math
import time

import numpy as np
import numpy.typing as npt

from core.planning import grasp_solver as gs
from core.planning.clearance import certify_lines
from core.planning.grasp_waypoint import PlannedWaypoint, sweep_detail

Array = npt.NDArray[np.float64]


class SweepClearance:
    """The clearance pass of :class:`core.planning.grasp.GraspPlanner` (see the module doc)."""

    def _certify(self, starts: Array, ends: Array, c: complex, r_o: float) -> tuple[Array, Array]:
        """Certified lower bounds along lines: (n,) to the object, (n,) to the nearest
        obstacle (inf without obstacles)."""
        cfg = self.config
        cert = certify_lines(self.model, starts, ends, c, r_o, 0.0, cfg.line_samples)
        if self.obstacles is None:
            return cert.lower_bound, np.full(len(cert.lower_bound), math.inf)
        return cert.lower_bound, self.obstacles.certify(self.model, starts, ends,
                                                        cfg.line_samples)

    def _line_bad(self, p: PlannedWaypoint) -> bool:
        """The line into ``p`` touches the object or comes closer than the set clearance to
        an obstacle."""
        need = -math.inf if self.obstacles is None else self.obstacles.clearance
        return p.path_clearance < 0.0 or p.obstacle_path_clearance < need

    def _constrained(self, wp: PlannedWaypoint, starts: list[Array], c: complex, r_o: float,
                     km: Array, w: Array) -> None:
        """Re-solve a waypoint with arm-body clearance constraints, in place."""
        t0 = time.perf_counter()
        clr = gs.Clearance(c, r_o + self.model.half_width + self.config.clearance_margin)
        for s in starts:
            res = self._solve(self.model, c, self._offset(wp.radius), s, km, w, wp.lam,
                           gs.joined(clr, self._rows()), self.solver)
            wp.iterations += res.iterations
            if res.ok:
                wp.kappa, wp.lam, wp.cost, wp.violation = res.kappa, res.lam, res.cost, \
                    res.violation
                wp.error = res.error
                break
        else:
            wp.status = gs.CLEARANCE
            wp.detail = (f"no configuration on this circle keeps the arm "
                         f"{self.config.clearance_margin * 1e3:.0f} mm clear of the object")
        wp.constrained = True
        wp.ms += (time.perf_counter() - t0) * 1e3

    def _secure_clearance(self, wps: list[PlannedWaypoint], km: Array, d1: float, c: complex,
                          r_o: float, w: Array) -> list[PlannedWaypoint]:
        """Make every waypoint and every straight line in kappa between them clear the object.

        Waypoints closer than the margin are re-solved with clearance constraints; lines whose
        certified clearance is negative get waypoints inserted on intermediate circles.
        """
        cfg, m = self.config, self.model
        cert = None
        for _ in range(2):
            good = [p for p in wps if p.status == gs.OK]
            if not good:
                return wps
            chain = np.array([km] + [p.kappa for p in good])
            cert = certify_lines(m, chain[:-1], chain[1:], c, r_o, 0.0, cfg.line_samples)
            obs_lb = (None if self.obstacles is None else
                      self.obstacles.certify(m, chain[:-1], chain[1:], cfg.line_samples))
            changed = False
            prev_k = km
            for p, gap in zip(good, cert.end_clearance.tolist()):
                p.clearance = gap
                if gap < cfg.clearance_margin - 1e-9 and not p.constrained:
                    self._constrained(p, [p.kappa, prev_k], c, r_o, km, w)
                    changed = True
                if p.status == gs.OK:
                    prev_k = p.kappa
            if not changed:
                break
        out: list[PlannedWaypoint] = []
        prev_k, prev_r = km, d1
        k = 0
        for p in wps:
            if p.status == gs.OK:
                p.path_clearance = float(cert.lower_bound[k])
                if obs_lb is not None:
                    p.obstacle_path_clearance = float(obs_lb[k])
                k += 1
                if self._line_bad(p):
                    out += self._bridge(prev_k, prev_r, p, 1, c, r_o, km, w)
                prev_k, prev_r = p.kappa, p.radius
            out.append(p)
        return out

    def _bridge(self, ka: Array, ra: float, p: PlannedWaypoint, depth: int, c: complex, r_o: float,
                km: Array, w: Array) -> list[PlannedWaypoint]:
        """Waypoints on circles between r_a and ``p`` so every straight line in kappa is clear.

        Bisects the radius: the midpoint waypoint is solved from the midpoint of the line; the
        two halves are certified and bisected again, up to ``max_insertions`` levels. When the
        depth runs out, the waypoint at the end of the failing line is marked ``clearance``.
        """
        cfg, m = self.config, self.model
        mid = self._solve_radius(c, 0.5 * (ra + p.radius), 0.5 * (ka + p.kappa), p.lam, km, w,
                                 p.index)
        mid.depth = depth
        if mid.status == gs.OK:
            mid.clearance = m.clearance_py(mid.kappa.tolist(), c, r_o)
            if mid.clearance < cfg.clearance_margin - 1e-9:
                self._constrained(mid, [mid.kappa, ka, p.kappa], c, r_o, km, w)
                mid.clearance = m.clearance_py(mid.kappa.tolist(), c, r_o)
        if mid.status != gs.OK:
            p.status = gs.CLEARANCE
            p.detail = sweep_detail(p, ka is km) + (
                ", and no waypoint in between could be found")
            return []
        obj_lb, obs_lb = self._certify(np.array([ka, mid.kappa]), np.array([mid.kappa, p.kappa]),
                                       c, r_o)
        mid.path_clearance, p.path_clearance = (float(v) for v in obj_lb)
        mid.obstacle_path_clearance, p.obstacle_path_clearance = (float(v) for v in obs_lb)
        out: list[PlannedWaypoint] = []
        for lo_k, lo_r, hi_wp in ((ka, ra, mid), (mid.kappa, mid.radius, p)):
            if self._line_bad(hi_wp):
                if depth < cfg.max_insertions:
                    out += self._bridge(lo_k, lo_r, hi_wp, depth + 1, c, r_o, km, w)
                else:
                    hi_wp.status = gs.CLEARANCE
                    hi_wp.detail = sweep_detail(hi_wp, lo_k is km)
            if hi_wp is mid:
                out.append(mid)
        return out
