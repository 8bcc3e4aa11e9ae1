"""SQP for findOptimalConfig (Algorithm 1): exact Hessian, active set on the bounds, l1 merit.

The paper's problem over (kappa, phi) has three equalities: palm point on the approach circle
and palm heading ``phi + pi/2``. The heading equality fixes ``phi = theta_tip - pi/2`` exactly,
and then "palm point = c + r_a (cos phi, sin phi)" is the same as "the tip-frame point at offset
(w_along, g_off + r_a) equals c" (c lies r_a to the palm's left). So a waypoint solves

    min_kappa  sum_n R_n (kappa_n - kappa_off_n)^2
    s.t.       q(kappa) = c                       (2 equalities; q, c complex)
               lo <= kappa <= hi
               h(kappa) >= 0                      (optional: arm-body clearance per segment,
                                                   obstacle disks: Clearance, Constraints)

with N = 6 variables. Each iteration forms the exact Lagrangian Hessian in closed form (see
:mod:`core.planning.arm_model`), solves the QP by a primal-dual active-set method on one small
KKT system (variables fixed at a bound and inactive clearance rows become identity rows) and
globalises with an l1 merit, Armijo backtracking and a second-order correction; negative
curvature along a step is removed by a diagonal shift and a re-solve.

Speed: the kinematics, Jacobian and Hessian come from the scalar kernel in
:mod:`core.planning.solver_kernel` (with N = 6, Python complex scalars beat 1-D numpy calls by
about 3x) and only the KKT solve goes to LAPACK. With numba installed, the plain Newton-KKT
iterations (no bound or clearance row active, full steps accepted: most waypoint solves) run
compiled in :mod:`core.planning.solver_jit` (see :func:`compiled_kernel`), which hands back to
the loop here at the first iteration that needs more.
"""

from __future__ import annotations

import functools
import os
import sys
from operator import add, mul, sub
from pathlib import Path

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel
from core.planning.grasp_solver_types import (CLEARANCE, CURVATURE_LIMIT, NO_CONVERGENCE, OK,
                                              STATUS_NAMES, Clearance, Constraints, SolveResult,
                                              SolverOptions, joined)
from core.planning.solver_kernel import Kernel, PointEval, kkt_solve, unit_rows
from core.planning.sqp_corrections import KKT_REG, refine_kkt_step, restore_feasibility

__all__ = ["CLEARANCE", "CURVATURE_LIMIT", "KKT_REG", "NO_CONVERGENCE", "OK", "STATUS_NAMES",
           "Clearance", "Constraints", "SolveResult", "SolverOptions", "compiled_kernel", "joined",
           "solve"]

Array = npt.NDArray[np.float64]


@functools.lru_cache(maxsize=1)
def compiled_kernel():
    """:func:`core.planning.solver_jit.newton_free` when numba is installed and the kernel is
    compiled on disk or ``GRASP_SOLVER_JIT=1`` asks for it (``0``: never), else None (the
    pure-Python path)."""
    want = os.environ.get("GRASP_SOLVER_JIT", "")
    if want == "0":
        return None
    if want != "1":
        # Without numba's cache files next to the kernel there is nothing to load: say so
        # without importing numba (about a second).
        cache = Path(__file__).with_name("__pycache__")
        tag = f"py{sys.version_info[0]}{sys.version_info[1]}"
        if not any(cache.glob(f"solver_jit.newton_free-*.{tag}.nbi")):
            return None
    try:
        from core.planning.solver_jit import compiled_on_disk, newton_free
    except ImportError:
        return None
    return newton_free if want == "1" or compiled_on_disk() else None


def solve(
    model: ArmModel,
    center: complex,
    offset: complex,
    kappa0: Array,
    kappa_off: Array,
    weights: Array,
    lam0: tuple[float, float] | None = None,
    clearance: Clearance | None = None,
    opts: SolverOptions = SolverOptions(),
    tangent: bool = False,
) -> SolveResult:
    """Solve one findOptimalConfig problem from ``kappa0``.

    Args:
        model: Arm model.
        center: Object centre (complex).
        offset: Tip-frame offset ``w_along + i (g_off + r_a)`` of the object centre.
        kappa0: (N,) start (clipped into the bounds); e.g. the previous waypoint.
        kappa_off: (N,) curvatures the cost pulls towards (kappa_meas at the start).
        weights: (N,) cost weights R_n > 0.
        lam0: Multiplier guess for the two equalities (e.g. the previous waypoint's).
        clearance: Optional inequality constraints: :class:`Clearance` (arm body to the
            object), obstacle disks (:mod:`core.planning.obstacles`) or both
            (:func:`joined`).
        opts: Tolerances.
        tangent: Also return d kappa / d r_a at the solution (a predictor for the next radius).

    Returns:
        :class:`SolveResult`.
    """
    mc = model.py
    x = [min(max(v, a), b) for v, a, b in zip(np.asarray(kappa0, float).tolist(), mc.lo, mc.hi)]
    lam = (0.0, 0.0) if lam0 is None else (float(lam0[0]), float(lam0[1]))
    act = [-1 if v <= a else (1 if v >= b else 0) for v, a, b in zip(x, mc.lo, mc.hi)]
    mu = 0.0
    it0 = 0
    fast = compiled_kernel() if clearance is None and not any(act) else None
    if fast is not None:
        # The plain Newton-KKT iterations, compiled (core.planning.solver_jit); it hands back
        # at the first iteration that needs the active-set loop below. Every argument has the
        # one type the kernel was compiled for (another would compile a second version).
        w_a = np.ascontiguousarray(weights, dtype=float)
        code, it0, xa, l0, l1, mu, ok, e, f, dk, dl0, dl1, has_t = fast(
            np.array(x), lam[0], lam[1], *model.jit_consts,
            np.ascontiguousarray(kappa_off, dtype=float), w_a, 2.0 * w_a,
            complex(offset), complex(model.base - center), int(opts.max_iter),
            float(opts.ctol), float(opts.xtol), float(opts.gtol), float(opts.max_step),
            float(opts.armijo), bool(tangent))
        if code == 0:
            result = SolveResult(xa, (l0, l1), OK if ok else NO_CONVERGENCE, it0,
                                 max(abs(e.real), abs(e.imag)), f, (0,) * mc.n, e)
            if has_t:
                result.dkappa_dr, result.dlam_dr = dk, (dl0, dl1)
            return result
        x, lam = xa.tolist(), (l0, l1)
    kn = Kernel(model, center, offset, kappa_off, weights, clearance)
    n, lo, hi, w2, xo = kn.n, kn.lo, kn.hi, kn.w2, kn.xo
    wmax = max(w2)
    nc = clearance.size(n) if clearance is not None else 0
    nk = n + 2 + nc
    cact = [False] * nc
    status = NO_CONVERGENCE
    p = PointEval(kn, x)
    it = it0
    unit = unit_rows(nk)
    reg_x = [-KKT_REG, 0.0] + [0.0] * nc
    reg_y = [0.0, -KKT_REG] + [0.0] * nc
    zeros_c = [0.0] * (2 + nc)
    G = hc = nu = None
    W = []
    grad = None
    for it in range(it0 + 1, opts.max_iter + 1):
        J = p.J
        Jx = [v.real for v in J]
        Jy = [v.imag for v in J]
        ex, ey = p.e.real, p.e.imag
        if grad is None:
            grad = [a * (b - c) for a, b, c in zip(w2, x, xo)]
        W = kn.kkt_rows(p, lam)
        shift = 0.0
        free = False
        if not nc and not any(act):
            # Common case first: no bound active and no clearance rows. Accept the plain
            # Newton-KKT step when it has positive curvature and stays in the bounds; anything
            # else goes through the active-set loop below (which re-solves from scratch).
            rows = W + [Jx + reg_x, Jy + reg_y]
            sol = refine_kkt_step(rows, kkt_solve(rows, [-g for g in grad] + [-ex, -ey]), n,
                                  p.viol, opts)
            d = sol[:n]
            l0, l1 = sol[n], sol[n + 1]
            gd = sum(map(mul, grad, d))
            jxd = sum(map(mul, Jx, d))
            jyd = sum(map(mul, Jy, d))
            dd = sum(map(mul, d, d))
            xu = list(map(add, x, d))
            free = ((dd <= 1e-30 or l0 * jxd + l1 * jyd - gd > 1e-12 * wmax * dd)
                    and min(map(sub, xu, lo)) >= -1e-12 and max(map(sub, xu, hi)) <= 1e-12)
        if free:
            pass
        elif nc:
            G = clearance.jacobian(model, x, p.aux)
            hc = p.hc.tolist()
            for j in range(n):
                W[j] += [-g[j] for g in G]
        for _ in range(0 if free else opts.max_qp_iter):
            if any(act) or shift:
                rows, rhs = [], []
                for j in range(n):
                    if act[j]:
                        rows.append(unit[j])
                        rhs.append((lo[j] if act[j] < 0 else hi[j]) - x[j])
                    else:
                        if shift:
                            row = list(W[j])
                            row[j] += shift
                            rows.append(row)
                        else:
                            rows.append(W[j])
                        rhs.append(-grad[j])
            else:
                rows = list(W)
                rhs = [-g for g in grad]
            rows.append(Jx + reg_x)
            rows.append(Jy + reg_y)
            rhs += [-ex, -ey]
            for i in range(nc):
                if cact[i]:
                    rows.append(G[i] + zeros_c)
                    rhs.append(-hc[i])
                else:
                    rows.append(unit[n + 2 + i])
                    rhs.append(0.0)
            sol = refine_kkt_step(rows, kkt_solve(rows, rhs), n, p.viol, opts)
            d = sol[:n]
            l0, l1 = sol[n], sol[n + 1]
            if not (nc or shift or any(act)):
                # Common case, nothing active: the bound multipliers are all zero.
                gd = sum(map(mul, grad, d))
                jxd = sum(map(mul, Jx, d))
                jyd = sum(map(mul, Jy, d))
                dd = sum(map(mul, d, d))
                if dd > 1e-30 and l0 * jxd + l1 * jyd - gd <= 1e-12 * wmax * dd:
                    shift = wmax  # negative curvature along d: shift, re-solve
                    continue
                changed = False
                for j in range(n):
                    if d[j] < lo[j] - x[j] - 1e-12:
                        act[j], changed = -1, True
                    elif d[j] > hi[j] - x[j] + 1e-12:
                        act[j], changed = 1, True
                if not changed:
                    break
                continue
            if nc:
                nu = sol[n + 2:]
            # Bound multipliers wb = (W + shift) d + grad - J^T lam - G^T nu (zero when free).
            wb = [0.0] * n
            for j in range(n):
                if act[j]:
                    Wj = W[j]
                    v = sum(map(mul, Wj[:n], d)) + shift * d[j] + grad[j] - Jx[j] * l0 - Jy[j] * l1
                    if nc:
                        v -= sum(g[j] * nu_i for g, nu_i in zip(G, nu))
                    wb[j] = v
            gd = sum(map(mul, grad, d))
            jxd = sum(map(mul, Jx, d))
            jyd = sum(map(mul, Jy, d))
            dd = sum(map(mul, d, d))
            # Curvature along d: d^T (W + shift) d = d . wb - grad . d + J^T lam . d (+ G^T nu . d).
            curv = sum(map(mul, d, wb)) - gd + l0 * jxd + l1 * jyd
            if nc:
                gdots = [sum(map(mul, g, d)) for g in G]
                curv += sum(map(mul, nu, gdots))
            if dd > 1e-30 and curv <= 1e-12 * wmax * dd and shift < 1e6 * wmax:
                shift = max(2.0 * shift, wmax)  # negative curvature along d: shift, re-solve
                continue
            changed = False
            for i in range(nc):
                new = (nu[i] >= 0.0) if cact[i] else (hc[i] + gdots[i] < -opts.clearance_tol)
                if new != cact[i]:
                    changed = True
                    cact[i] = new
            for j in range(n):
                a = act[j]
                if a == 0:
                    dj = d[j]
                    if dj < lo[j] - x[j] - 1e-12:
                        act[j], changed = -1, True
                    elif dj > hi[j] - x[j] + 1e-12:
                        act[j], changed = 1, True
                elif (a < 0 and wb[j] < 0.0) or (a > 0 and wb[j] > 0.0):
                    act[j], changed = 0, True
            if not changed:
                break
        # Damping: a step longer than max_step is shortened (far from the solution the
        # linearisation is poor and a full step lands on the bounds). Scaling keeps the step in
        # the box and scales the model decrease D by the same factor.
        big = max(map(abs, d))
        scale = opts.max_step / big if big > opts.max_step else 1.0
        if scale < 1.0:
            d = [v * scale for v in d]
        xt = [min(max(xj + dj, a), b) for xj, dj, a, b in zip(x, d, lo, hi)]
        # ---- l1 merit line search
        vlin = abs(ex + scale * jxd) + abs(ey + scale * jyd)
        mult = max(abs(l0), abs(l1))
        if nc:
            vlin += sum(max(0.0, -(h + scale * gd_i)) for h, gd_i in zip(hc, gdots))
            mult = max(mult, max(map(abs, nu)))
        mu = max(mu, 1.5 * mult + 1e-8)
        phi0 = p.f + mu * p.viol
        D = min(scale * gd - mu * (p.viol - vlin), 0.0)
        trial = PointEval(kn, xt)
        accepted = trial.f + mu * trial.viol <= phi0 + opts.armijo * D
        if not accepted:
            # Second-order correction: min-norm step back onto the linearised constraints.
            axx = sum(map(mul, Jx, Jx)) + 1e-14
            ayy = sum(map(mul, Jy, Jy)) + 1e-14
            axy = sum(map(mul, Jx, Jy))
            det = axx * ayy - axy * axy
            tx, ty = trial.e.real, trial.e.imag
            zx = (ayy * tx - axy * ty) / det
            zy = (axx * ty - axy * tx) / det
            soc = [min(max(t - a * zx - b * zy, l_), h_)
                   for t, a, b, l_, h_ in zip(xt, Jx, Jy, lo, hi)]
            cand = PointEval(kn, soc)
            if cand.f + mu * cand.viol <= phi0 + opts.armijo * D:
                trial, accepted = cand, True
            alpha = 1.0
            while not accepted and alpha > opts.min_alpha:
                alpha *= 0.5
                trial = PointEval(kn, [a + alpha * (b - a) for a, b in zip(x, xt)])
                accepted = trial.f + mu * trial.viol <= phi0 + opts.armijo * alpha * D
        if not accepted:
            # Restoration: a damped Gauss-Newton step on the constraint violation alone, then
            # SQP again with fresh multipliers. If even that cannot reduce the violation, the
            # palm cannot get closer to the circle from here within the bounds.
            trial = restore_feasibility(kn, p, Jx, Jy, opts)
            if trial is None:
                status = CURVATURE_LIMIT
                break
            x, p, lam, mu = trial.x, trial, (0.0, 0.0), 0.0
            act = [-1 if v <= a else (1 if v >= b else 0) for v, a, b in zip(x, lo, hi)]
            grad = None
            continue
        step = max(map(abs, map(sub, trial.x, x)))
        x, p, lam = trial.x, trial, (l0, l1)
        grad = [a * (b - c) for a, b, c in zip(w2, x, xo)]
        e = p.e
        if abs(e.real) <= opts.ctol and abs(e.imag) <= opts.ctol and (
                not nc or float(p.hc.min()) >= -opts.clearance_tol):
            # KKT test at the new point with the QP's multipliers (Newton-accurate): the
            # gradient of the Lagrangian must vanish on the free variables.
            scale = max(1.0, max(map(abs, grad)))
            if free:
                lbc = complex(l0, -l1)          # Re(J_j lbc) = Re J_j l0 + Im J_j l1
                gmax = max(abs(g - (Jj * lbc).real) for g, Jj in zip(grad, p.J))
            else:
                gmax = 0.0
                for j, (gj, Jj) in enumerate(zip(grad, p.J)):
                    if not act[j]:
                        r = gj - Jj.real * l0 - Jj.imag * l1
                        if nc:
                            r -= sum(g[j] * nu_i for g, nu_i in zip(G, nu))
                        gmax = max(gmax, abs(r))
            if gmax <= opts.gtol * scale or step <= opts.xtol:
                status = OK
                break
    viol = max(abs(p.e.real), abs(p.e.imag))
    if status == NO_CONVERGENCE and any(act) and viol > opts.ctol:
        status = CURVATURE_LIMIT
    result = SolveResult(np.array(x), lam, status, it, viol, p.f, tuple(act), p.e)
    if status == OK and tangent and not nc:
        # Solution sensitivity to r_a: differentiate the KKT conditions with the active set
        # fixed. The offset's left part grows with r_a, so d q / d r_a = i exp(i theta) and
        # d J_j / d r_a = i L_j (i exp(i theta)) = -L_j exp(i theta); hence
        # W dk - J^T dlam = (dJ/dr)^T lam on the free rows and J dk = -i exp(i theta).
        h = p.heading
        lam_h = -(lam[0] * h.real + lam[1] * h.imag)
        rows, rhs = [], []
        for j in range(n):
            rows.append(unit[j] if act[j] else W[j])
            rhs.append(0.0 if act[j] else kn.L[j] * lam_h)
        rows.append([v.real for v in p.J] + [-1e-13, 0.0])
        rows.append([v.imag for v in p.J] + [0.0, -1e-13])
        rhs += [p.heading.imag, -p.heading.real]
        sol = kkt_solve(rows, rhs)
        result.dkappa_dr = np.array(sol[:n])
        result.dlam_dr = (sol[n], sol[n + 1])
    return result
