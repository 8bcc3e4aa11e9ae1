"""The grasp SQP's two corrective steps, apart from its main loop: feasibility restoration
when no line search accepts a step, and the refinement that takes the KKT regularisation's
error out of a step (:mod:`core.planning.grasp_solver`).
"""

from __future__ import annotations

from operator import add, mul

from core.planning.grasp_solver_types import SolverOptions
from core.planning.solver_kernel import Kernel, PointEval, kkt_solve


def restore_feasibility(kn: Kernel, p: PointEval, Jx: list[float], Jy: list[float],
                        opts: SolverOptions) -> PointEval | None:
    """Feasibility restoration: min-norm Gauss-Newton step on |q - c|, damped and backtracked
    until the violation drops by 1e-4 relative; None when it cannot."""
    axx = sum(map(mul, Jx, Jx))
    ayy = sum(map(mul, Jy, Jy))
    axy = sum(map(mul, Jx, Jy))
    reg = 1e-6 * (axx + ayy) + 1e-16
    axx, ayy = axx + reg, ayy + reg
    det = axx * ayy - axy * axy
    ex, ey = p.e.real, p.e.imag
    zx = (ayy * ex - axy * ey) / det
    zy = (axx * ey - axy * ex) / det
    d = [-(a * zx + b * zy) for a, b in zip(Jx, Jy)]
    big = max(map(abs, d))
    if big > opts.max_step:
        d = [v * opts.max_step / big for v in d]
    alpha = 1.0
    while alpha > 1e-3:
        cand = PointEval(kn, [min(max(xj + alpha * dj, a), b)
                           for xj, dj, a, b in zip(p.x, d, kn.lo, kn.hi)])
        if cand.viol < (1.0 - 1e-4) * p.viol:
            return cand
        alpha *= 0.5
    return None


KKT_REG = 1e-13  # regularisation of the two equality rows of the KKT matrix (see refine_kkt_step)


def refine_kkt_step(rows: list, sol: list[float], n: int, viol: float, opts: SolverOptions
                    ) -> list[float]:
    """``sol`` with the regularisation's error taken out (one step of iterative refinement).

    The equality rows carry ``-KKT_REG`` on the diagonal so the KKT matrix stays invertible
    when the palm-point Jacobian is (nearly) rank-deficient; the step then meets the linearised
    equalities only up to ``KKT_REG * lam``. With huge multipliers (a nearly singular Jacobian:
    e.g. the arm stretched with a curvature at its limit) that error exceeds the solver's
    tolerance and, divided by the small singular value, becomes a spurious step that no line
    search accepts from a feasible point (the waypoint was then refused with curvature_limit
    although it had been found). Re-solving for the residual removes it; it is skipped while
    that error is small next to the violation ``viol`` the step has to remove.
    """
    l0, l1 = sol[n], sol[n + 1]
    if KKT_REG * max(abs(l0), abs(l1)) <= 1e-3 * max(viol, opts.ctol):
        return sol
    r = [0.0] * len(rows)
    r[n], r[n + 1] = -KKT_REG * l0, -KKT_REG * l1
    return list(map(add, sol, kkt_solve(rows, r)))
