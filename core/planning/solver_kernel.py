"""Scalar evaluation kernel of the grasp SQP: q(kappa), its Jacobian and Lagrangian Hessian.

With N = 6 every numpy call costs more in dispatch than in arithmetic, so the kinematics,
Jacobian and exact Hessian of the object-centre point are evaluated with Python complex scalars
in one pass (the formulas are derived in :mod:`core.planning.arm_model`, whose batched numpy
versions are the reference the tests compare this kernel with), and only the KKT solve goes to
LAPACK (``dgesv`` directly, without numpy.linalg's wrapper overhead).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.linalg import lapack

from core.planning.arm_model import ArmModel

Array = npt.NDArray[np.float64]


class PointEval:
    """Object-centre point q, Jacobian and Hessian pieces at one kappa, as Python scalars.

    The chord direction of segment j is exp(i mid_j) = exp(i theta_start_j) exp(i u_j) with
    u_j = kappa_j L_j / 2, so one sin/cos pair per segment serves the sinc terms and the
    rotations.
    """

    __slots__ = ("x", "e", "viol", "f", "J", "D1", "M", "T", "c2E", "hc", "aux", "heading")

    def __init__(self, k: "Kernel", x: list[float]):
        sin, cos = math.sin, math.cos
        E = k.E0
        tc = 0j
        f = 0.0
        T, M, D1, c2E = [], [], [], []
        for xj, Lj, c1j, c2j, oj, wj in zip(x, k.L, k.c1, k.c2, k.xo, k.w):
            u = 0.5 * xj * Lj
            su = sin(u)
            cu = cos(u)
            if u > 1e-3 or u < -1e-3:
                s0 = su / u
                s1 = (u * cu - su) / (u * u)
                s2 = -s0 - 2.0 * s1 / u
            else:
                uu = u * u
                s0 = 1.0 - uu / 6.0 + uu * uu / 120.0
                s1 = u * (uu / 30.0 - 1.0 / 3.0)
                s2 = uu / 10.0 - 1.0 / 3.0
            r = complex(cu, su)
            E *= r                      # chord direction exp(i mid_j)
            t = (Lj * s0) * E
            M.append(tc + 0.5 * t)
            tc += t
            T.append(t)
            D1.append((c1j * s1) * E)
            c2E.append((c2j * s2) * E)
            E *= r                      # heading at the segment's end
            d = xj - oj
            f += wj * d * d
        self.heading = E
        q_rel = tc + k.offset * E
        self.J = [d1 + il * (q_rel - mj) for d1, il, mj in zip(D1, k.iL, M)]
        self.x, self.T, self.M, self.D1, self.c2E, self.f = x, T, M, D1, c2E, f
        e = self.e = q_rel + k.base_minus_center
        self.viol = abs(e.real) + abs(e.imag)
        self.hc = None
        if k.clearance is not None:
            # Inequality constraints h(kappa) >= 0 (grasp_solver.Clearance and any other set
            # with the same evaluate / jacobian protocol, e.g. obstacle disks).
            self.hc, self.aux = k.clearance.evaluate(k.model, x)
            self.viol += float(np.maximum(0.0, -self.hc).sum())


class Kernel:
    """Constants of one waypoint problem as Python floats (model constants cached on the model)."""

    def __init__(self, model: ArmModel, center: complex, offset: complex, kappa_off: Array,
                 weights: Array, clearance: Any):
        c = model.py
        self.model = model
        self.n, self.L, self.c1, self.c2, self.iL, self.L2q, self.LL = (
            c.n, c.L, c.c1, c.c2, c.iL, c.L2q, c.LL)
        self.lo, self.hi = c.lo, c.hi
        self.E0 = complex(math.cos(model.theta0), math.sin(model.theta0))
        self.base_minus_center = model.base - center
        self.offset = offset
        self.xo = np.asarray(kappa_off, float).tolist()
        self.w = np.asarray(weights, float).tolist()
        self.w2 = [2.0 * v for v in self.w]
        self.clearance = clearance

    def kkt_rows(self, p: PointEval, lam: tuple[float, float]) -> list[list[float]]:
        """Stationarity rows [W | -J^T] of the KKT matrix, W the exact Lagrangian Hessian.

        W = diag(2R) - lam . Hess(q). With lb = lam_x - i lam_y, lam . Hess(q) = Re(lb H). For
        k < j the complex Hessian is H_jk = i L_k D1_j + i L_j (J_k - D1_k) + L_j L_k (M_j - M_k)
        and on the diagonal H_jj = c''_j E_j + i L_j J_j + L_j^2 T_j / 4 (derivation in
        arm_model's docstring).
        """
        n, L, LL = self.n, self.L, self.LL
        lb = complex(lam[0], -lam[1])
        a = [(lb * d).imag for d in p.D1]
        b = [(lb * (jj - d)).imag for jj, d in zip(p.J, p.D1)]
        mm = [(lb * v).real for v in p.M]
        W = [[0.0] * n + [-jj.real, -jj.imag] for jj in p.J]
        for j in range(n):
            Lj, aj, mj, Wj, LLj = L[j], a[j], mm[j], W[j], LL[j]
            for k in range(j):
                v = L[k] * aj + Lj * b[k] - LLj[k] * (mj - mm[k])
                Wj[k] = v
                W[k][j] = v
            Wj[j] = self.w2[j] - ((lb * p.c2E[j]).real - Lj * (lb * p.J[j]).imag
                                  + self.L2q[j] * (lb * p.T[j]).real)
        return W


@functools.lru_cache(maxsize=8)
def unit_rows(n: int) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(r) for r in np.eye(n).tolist())


def kkt_solve(rows: list, rhs: list[float]) -> list[float]:
    """Solve the small KKT system (LAPACK dgesv directly; least squares if singular)."""
    _, _, sol, info = lapack.dgesv(rows, rhs)
    if info != 0:
        sol = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
    return sol.tolist()
