"""Compiled fast path of the grasp SQP: the plain Newton-KKT iterations, when numba is installed.

Most waypoint solves of Algorithm 1 never meet a bound or a clearance row: every iteration is
one Newton step on the KKT system, accepted in full by the l1 merit test. In Python each such
iteration costs tens of microseconds of interpreter work (the kernel in
:mod:`core.planning.solver_kernel`); compiled with numba (optional, ``pip install numba``,
wheels for Python 3.10-3.13 on x86_64 and aarch64) the whole solve takes a few microseconds.
:func:`newton_free` runs exactly the iterations of :func:`core.planning.grasp_solver.solve`'s
plain branch (same formulas, same tests, same tangent) and hands the state back at the start of
the first iteration that branch would not take (a bound or negative curvature along the step,
a step the merit test refuses, a singular KKT matrix); ``solve`` then goes on in Python from
there. This module imports numba. ``grasp_solver`` uses it when numba is installed and the
compiled kernel is in numba's disk cache (``core/planning/__pycache__``), or when
``GRASP_SOLVER_JIT=1`` asks for it (compiling it on first use, several seconds, then cached);
``GRASP_SOLVER_JIT=0`` turns it off. Otherwise everything runs in Python, with the same results
up to rounding. So a plan never waits for a compiler unless the environment asked for one.
"""

from __future__ import annotations

import math

import numba
import numpy as np

DONE, HANDOVER = 0, 1

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _point(x, L, c1, c2, xo, w, E0, offset, bmc, J, M, T, D1, c2E):
    """PointEval (solver_kernel) into the arrays J, M, T, D1, c2E; returns (e, f, viol, heading)."""
    n = x.shape[0]
    E = E0
    tc = 0j
    f = 0.0
    for j in range(n):
        xj = x[j]
        Lj = L[j]
        u = 0.5 * xj * Lj
        su = math.sin(u)
        cu = math.cos(u)
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
        E = E * r
        t = (Lj * s0) * E
        M[j] = tc + 0.5 * t
        tc = tc + t
        T[j] = t
        D1[j] = (c1[j] * s1) * E
        c2E[j] = (c2[j] * s2) * E
        E = E * r
        d = xj - xo[j]
        f += w[j] * d * d
    q_rel = tc + offset * E
    for j in range(n):
        J[j] = D1[j] + complex(0.0, L[j]) * (q_rel - M[j])
    e = q_rel + bmc
    return e, f, abs(e.real) + abs(e.imag), E


@_jit
def _kkt(J, M, T, D1, c2E, lam0, lam1, L, LL, L2q, w2, K):
    """kkt_rows (solver_kernel) into the first n rows of K ((n+2) x (n+2))."""
    n = J.shape[0]
    lb = complex(lam0, -lam1)
    a = np.empty(n)
    b = np.empty(n)
    mm = np.empty(n)
    for j in range(n):
        a[j] = (lb * D1[j]).imag
        b[j] = (lb * (J[j] - D1[j])).imag
        mm[j] = (lb * M[j]).real
    for j in range(n):
        K[j, n] = -J[j].real
        K[j, n + 1] = -J[j].imag
        Lj = L[j]
        for k in range(j):
            v = L[k] * a[j] + Lj * b[k] - LL[j, k] * (mm[j] - mm[k])
            K[j, k] = v
            K[k, j] = v
        K[j, j] = w2[j] - ((lb * c2E[j]).real - Lj * (lb * J[j]).imag + L2q[j] * (lb * T[j]).real)


@_jit
def _lu_solve(A, rhs, out):
    """Solve A out = rhs by Gaussian elimination with partial pivoting (A, rhs are copied);
    False when A is singular."""
    m = A.shape[0]
    U = A.copy()
    y = rhs.copy()
    for k in range(m):
        p = k
        big = abs(U[k, k])
        for i in range(k + 1, m):
            if abs(U[i, k]) > big:
                big = abs(U[i, k])
                p = i
        if big == 0.0:
            return False
        if p != k:
            for c in range(m):
                tmp = U[k, c]
                U[k, c] = U[p, c]
                U[p, c] = tmp
            tmp = y[k]
            y[k] = y[p]
            y[p] = tmp
        for i in range(k + 1, m):
            fct = U[i, k] / U[k, k]
            if fct != 0.0:
                for c in range(k, m):
                    U[i, c] -= fct * U[k, c]
                y[i] -= fct * y[k]
    for i in range(m - 1, -1, -1):
        s = y[i]
        for c in range(i + 1, m):
            s -= U[i, c] * out[c]
        out[i] = s / U[i, i]
    return True


@_jit
def newton_free(x0, lam0, lam1, L, c1, c2, LL, L2q, lo, hi, E0, xo, w, w2, offset, bmc,
                max_iter, ctol, xtol, gtol, max_step, armijo, tangent):
    """The plain Newton-KKT iterations of ``grasp_solver.solve`` from ``x0`` (inside the bounds,
    no clearance rows). ``L`` .. ``E0`` are the model's ``jit_consts``; ``xo``, ``w``, ``w2``
    kappa_off, the weights and twice the weights; ``bmc`` base minus object centre.

    Returns:
        ``(code, it, x, lam0, lam1, mu, status_ok, e, f, dk, dl0, dl1, has_tangent)``: with
        ``code == DONE`` the solve ended after ``it`` iterations (converged when ``status_ok``)
        at x; with ``HANDOVER`` iteration ``it + 1`` needs the general active-set loop, from
        ``x``, ``lam`` and the merit weight ``mu``.
    """
    n = x0.shape[0]
    nk = n + 2
    wmax = w2.max()
    x = x0.copy()
    xt = np.empty(n)
    J = np.empty(n, np.complex128)
    M = np.empty(n, np.complex128)
    T = np.empty(n, np.complex128)
    D1 = np.empty(n, np.complex128)
    c2E = np.empty(n, np.complex128)
    Jt = np.empty(n, np.complex128)
    Mt = np.empty(n, np.complex128)
    Tt = np.empty(n, np.complex128)
    D1t = np.empty(n, np.complex128)
    c2Et = np.empty(n, np.complex128)
    K = np.zeros((nk, nk))
    rhs = np.empty(nk)
    sol = np.empty(nk)
    grad = np.empty(n)
    dk = np.zeros(n)
    e, f, viol, heading = _point(x, L, c1, c2, xo, w, E0, offset, bmc, J, M, T, D1, c2E)
    for j in range(n):
        grad[j] = w2[j] * (x[j] - xo[j])
    mu = 0.0
    ok = False
    it = 0
    for it in range(1, max_iter + 1):
        ex = e.real
        ey = e.imag
        _kkt(J, M, T, D1, c2E, lam0, lam1, L, LL, L2q, w2, K)
        for j in range(n):
            K[n, j] = J[j].real
            K[n + 1, j] = J[j].imag
            rhs[j] = -grad[j]
        K[n, n] = -1e-13
        K[n, n + 1] = 0.0
        K[n + 1, n] = 0.0
        K[n + 1, n + 1] = -1e-13
        rhs[n] = -ex
        rhs[n + 1] = -ey
        if not _lu_solve(K, rhs, sol):
            return (HANDOVER, it - 1, x, lam0, lam1, mu, False, e, f, dk, 0.0, 0.0, False)
        l0 = sol[n]
        l1 = sol[n + 1]
        gd = 0.0
        jxd = 0.0
        jyd = 0.0
        dd = 0.0
        for j in range(n):
            dj = sol[j]
            gd += grad[j] * dj
            jxd += J[j].real * dj
            jyd += J[j].imag * dj
            dd += dj * dj
        free = dd <= 1e-30 or l0 * jxd + l1 * jyd - gd > 1e-12 * wmax * dd
        big = 0.0
        for j in range(n):
            xu = x[j] + sol[j]
            if xu - lo[j] < -1e-12 or xu - hi[j] > 1e-12:
                free = False
            big = max(big, abs(sol[j]))
        if not free:
            return (HANDOVER, it - 1, x, lam0, lam1, mu, False, e, f, dk, 0.0, 0.0, False)
        scale = max_step / big if big > max_step else 1.0
        for j in range(n):
            dj = sol[j] * scale if scale < 1.0 else sol[j]
            xt[j] = min(max(x[j] + dj, lo[j]), hi[j])
        vlin = abs(ex + scale * jxd) + abs(ey + scale * jyd)
        mult = max(abs(l0), abs(l1))
        mu_new = max(mu, 1.5 * mult + 1e-8)
        phi0 = f + mu_new * viol
        D = min(scale * gd - mu_new * (viol - vlin), 0.0)
        et, ft, violt, headt = _point(xt, L, c1, c2, xo, w, E0, offset, bmc, Jt, Mt, Tt, D1t,
                                      c2Et)
        if not ft + mu_new * violt <= phi0 + armijo * D:
            return (HANDOVER, it - 1, x, lam0, lam1, mu, False, e, f, dk, 0.0, 0.0, False)
        step = 0.0
        for j in range(n):
            step = max(step, abs(xt[j] - x[j]))
            x[j] = xt[j]
            grad[j] = w2[j] * (x[j] - xo[j])
        J, Jt = Jt, J
        M, Mt = Mt, M
        T, Tt = Tt, T
        D1, D1t = D1t, D1
        c2E, c2Et = c2Et, c2E
        e, f, viol, heading = et, ft, violt, headt
        lam0, lam1, mu = l0, l1, mu_new
        if abs(e.real) <= ctol and abs(e.imag) <= ctol:
            sc = 1.0
            for j in range(n):
                sc = max(sc, abs(grad[j]))
            lbc = complex(l0, -l1)
            gmax = 0.0
            for j in range(n):
                gmax = max(gmax, abs(grad[j] - (J[j] * lbc).real))
            if gmax <= gtol * sc or step <= xtol:
                ok = True
                break
    has_tangent = False
    dl0 = dl1 = 0.0
    if ok and tangent:
        # The sensitivity d kappa / d r_a (grasp_solver.solve): the last iteration's Hessian
        # rows (K[:n], with its -J^T columns), J at the solution in the last two rows.
        h = heading
        lam_h = -(lam0 * h.real + lam1 * h.imag)
        for j in range(n):
            K[n, j] = J[j].real
            K[n + 1, j] = J[j].imag
            rhs[j] = L[j] * lam_h
        rhs[n] = h.imag
        rhs[n + 1] = -h.real
        if _lu_solve(K, rhs, sol):
            for j in range(n):
                dk[j] = sol[j]
            dl0 = sol[n]
            dl1 = sol[n + 1]
            has_tangent = True
    return (DONE, it, x, lam0, lam1, mu, ok, e, f, dk, dl0, dl1, has_tangent)


def compiled_on_disk() -> bool:
    """Whether numba's on-disk cache holds :func:`newton_free` compiled from this source (so
    the first call loads it in about a second instead of compiling for several)."""
    try:
        return bool(newton_free._cache._cache_file._load_index())
    except Exception:  # numba internals differ, or the JIT is disabled: treat as not built
        return False
