"""Baselines for the grasp-planner benchmark: Algorithm 1 as a user would write it without us.

* :func:`literal_port` - Algorithm 1 line by line with scipy's SLSQP and finite-difference
  gradients over (kappa, phi) with the paper's three equality constraints, as MATLAB's fmincon
  (SQP, no user gradients) would run it; each radius starts from the previous solution.
* :class:`CasadiPlanner` - the same problem in CasADi with exact automatic-differentiation
  derivatives, solved by ``sqpmethod`` (or ``ipopt``); the NLP is built once and reused.
* :class:`SidedCasadiPlanner` - :class:`CasadiPlanner` on the side of the arm the object lies
  on, exactly as the console plans (:class:`core.planning.sides.SidedPlanner`): a right-side
  object is the mirrored request solved on the same left-finger NLP, its plan mirrored back.

Both return a :class:`BaselinePlan`; a plan counts as a success when every waypoint meets the
paper's acceptance (constraint violation <= 2e-3, curvatures within the limits), whatever the
solver's own status says. casadi is a benchmark-only dependency.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize

from core.kinematics import planar
from core.planning.sides import mirror_heading, mirror_xy, object_side

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class BaselinePlan:
    """Waypoints of a baseline run: radii (n,), kappas (n, N), phis (n,), success flag."""

    radii: Array
    kappas: Array
    phis: Array
    success: bool


def _setup(robot, kappa_meas, center, radius, delta_d):
    """Algorithm 1's planGrasp() preamble: w_t, d1, d2, numMoves and the radii."""
    g = robot.gripper
    tip = planar.forward_kinematics(kappa_meas, robot.lengths, robot.base_pose)[-1]
    w_t = planar.point_in_frame(tip, g.w_off)
    c = np.asarray(center, float)
    d1 = float(np.hypot(*(c - w_t)))
    d2 = d1 - radius - g.g_off
    num_moves = max(1, math.floor(d2 / delta_d))
    radii = d1 - np.arange(1, num_moves + 1) * d2 / num_moves
    # phi of the current palm point, on the branch where heading - phi - pi/2 is smallest.
    phi = math.atan2(w_t[1] - c[1], w_t[0] - c[0])
    ref = tip[2] - math.pi / 2
    phi = ref + (phi - ref + math.pi) % (2 * math.pi) - math.pi
    return c, radii, phi


def literal_port(robot, kappa_meas, center, radius, delta_d=None, tol=2e-3) -> BaselinePlan:
    """Algorithm 1 with SLSQP and finite-difference gradients (the paper's MATLAB set-up)."""
    delta_d = robot.delta_d if delta_d is None else delta_d
    kappa_meas = np.asarray(kappa_meas, float)
    c, radii, phi0 = _setup(robot, kappa_meas, center, radius, delta_d)
    L, base, w_off = robot.lengths, robot.base_pose, robot.gripper.w_off
    n = robot.n_segments
    lo, hi = robot.kappa_limits
    bounds = [(a, b) for a, b in zip(lo, hi)] + [(None, None)]

    def forw(z):
        tip = planar.forward_kinematics(z[:n], L, base)[-1]
        return planar.point_in_frame(tip, w_off), tip[2]

    def cons(z, ra):
        w, th = forw(z)
        phi = z[n]
        return np.array([w[0] - c[0] - ra * math.cos(phi), w[1] - c[1] - ra * math.sin(phi),
                         th - phi - math.pi / 2])

    def cost(z):
        return float(np.sum((z[:n] - kappa_meas) ** 2))

    z = np.r_[kappa_meas, phi0]
    kappas, phis, ok = [], [], True
    for ra in radii:
        res = minimize(cost, z, method="SLSQP", bounds=bounds,
                       constraints=[{"type": "eq", "fun": cons, "args": (ra,)}],
                       options={"ftol": 1e-6, "maxiter": 200})
        z = res.x
        ok &= float(np.abs(cons(z, ra)).max()) <= tol and bool(np.all(np.abs(z[:n]) <= hi + 1e-9))
        kappas.append(z[:n].copy())
        phis.append(z[n])
    return BaselinePlan(radii, np.array(kappas), np.array(phis), ok)


class CasadiPlanner:
    """Algorithm 1 on CasADi (exact AD derivatives); the NLP is built once per robot."""

    def __init__(self, robot, solver: str = "sqpmethod", tol: float = 2e-3):
        import casadi as ca

        self.robot, self.tol, self.solver_name = robot, tol, solver
        n = robot.n_segments
        L = robot.lengths
        g = robot.gripper
        k = ca.SX.sym("kappa", n)
        phi = ca.SX.sym("phi")
        p = ca.SX.sym("p", 3 + n)          # cx, cy, r_a, kappa_off
        x, y, th = (float(v) for v in robot.base_pose)
        for i in range(n):
            t = k[i] * L[i]
            u = t / 2
            sinc = ca.if_else(ca.fabs(u) < 1e-6, 1 - u ** 2 / 6, ca.sin(u) / u)
            x = x + L[i] * sinc * ca.cos(th + u)
            y = y + L[i] * sinc * ca.sin(th + u)
            th = th + t
        wx = x + g.w_off_along * ca.cos(th) - g.g_off * ca.sin(th)
        wy = y + g.w_off_along * ca.sin(th) + g.g_off * ca.cos(th)
        cons = ca.vertcat(wx - p[0] - p[2] * ca.cos(phi), wy - p[1] - p[2] * ca.sin(phi),
                          th - phi - math.pi / 2)
        nlp = {"x": ca.vertcat(k, phi), "p": p, "f": ca.sumsqr(k - p[3:]), "g": cons}
        if solver == "sqpmethod":
            opts = {"qpsol": "qrqp", "print_time": False, "print_header": False,
                    "print_iteration": False, "print_status": False, "error_on_fail": False,
                    "qpsol_options": {"print_iter": False, "print_header": False,
                                      "error_on_fail": False}}
        else:
            opts = {"print_time": False, "error_on_fail": False,
                    "ipopt": {"print_level": 0, "sb": "yes"}}
        self.S = ca.nlpsol("grasp", solver, nlp, opts)
        self.cons = ca.Function("cons", [nlp["x"], p], [cons])
        lo, hi = robot.kappa_limits
        self.lbx = np.r_[lo, -np.inf]
        self.ubx = np.r_[hi, np.inf]

    def plan(self, kappa_meas, center, radius, delta_d=None) -> BaselinePlan:
        delta_d = self.robot.delta_d if delta_d is None else delta_d
        kappa_meas = np.asarray(kappa_meas, float)
        c, radii, phi0 = _setup(self.robot, kappa_meas, center, radius, delta_d)
        z = np.r_[kappa_meas, phi0]
        kappas, phis, ok = [], [], True
        for ra in radii:
            p = np.r_[c, ra, kappa_meas]
            sol = self.S(x0=z, p=p, lbx=self.lbx, ubx=self.ubx, lbg=0.0, ubg=0.0)
            z = np.asarray(sol["x"]).ravel()
            viol = float(np.abs(np.asarray(self.cons(z, p))).max())
            ok &= viol <= self.tol and bool(np.all(np.abs(z[:-1]) <= self.ubx[:-1] + 1e-9))
            kappas.append(z[:-1].copy())
            phis.append(z[-1])
        return BaselinePlan(radii, np.array(kappas), np.array(phis), ok)


class SidedCasadiPlanner:
    """:class:`CasadiPlanner` for the finger on the object's side, as the console plans.

    A robot with the stacked pair (``[gripper] fingers = "both"``) grasps a right-side object
    with the right finger, the mirror image of the left one about the base's heading line
    (:mod:`core.planning.sides`). So, like :class:`core.planning.sides.SidedPlanner`, a
    right-side request is mirrored (start curvatures negated, object reflected), solved on the
    left-finger NLP with the same tolerances, and the plan mirrored back (curvatures negated,
    approach angles reflected): the NLP this planner solves for that object, in CasADi.
    """

    def __init__(self, robot, left: CasadiPlanner):
        self.robot, self.left = robot, left

    def plan(self, kappa_meas, center, radius, delta_d=None) -> BaselinePlan:
        if "right" not in self.robot.gripper.sides or object_side(self.robot, center) == "left":
            return self.left.plan(kappa_meas, center, radius, delta_d)
        p = self.left.plan(-np.asarray(kappa_meas, float), mirror_xy(self.robot, center),
                           radius, delta_d)
        return BaselinePlan(p.radii, -p.kappas, mirror_heading(self.robot, p.phis), p.success)
