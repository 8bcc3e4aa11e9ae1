"""The extensible arm's tip-IK step and polish, below the solver, its seeds and its box solver.

:mod:`core.kinematics.delta_ik` describes the method (problem (4) of Hughes 2020 in rack space,
the projected, damped task-priority step of eq. (5), the SLSQP polish) and picks the starts;
:mod:`core.kinematics.delta_ik_seeds` makes them and :mod:`core.kinematics.delta_ik_boxes` adds
box obstacles. The problem, the step, the polish and the result type live here, below all three,
so none of them imports another in a circle.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize as _minimize

from core.kinematics import delta as _dk
from core.robot_sections import IKSettings

Array = npt.NDArray[np.float64]

_LAMBDA_MIN = 1e-5  # lambda^2 = 1e-10: keeps J P (J P)^T + lambda^2 I well conditioned
_LAMBDA_MAX = 1e6


@dataclasses.dataclass(frozen=True)
class TipIKResult:
    """Outcome of :func:`core.kinematics.delta_ik.solve_tip_ik` (which exports it).

    Attributes:
        delta: (n, 3) postures (dx, dy, dL) per segment.
        lengths: (n, 3) rack lengths, always within [rack_min, rack_max], and every segment's
            bend |(dx, dy)| / d within theta_max.
        tip: (3,) tip position reached, h(delta).
        error: Distance from ``tip`` to the target (m).
        iterations: Iterations spent over all starts.
        reachable: ``error <= tolerance``.
        starts: Starts iterated: 1 when the warm start converged, otherwise the warm start (if
            any) plus the batch of seeds.
        clearance: With boxes: the smallest distance from the arm's body surface (the
            backbone, sampled every millimetre, minus ``body_radius``) to a box (m; negative
            when the body reaches into one); ``inf`` without boxes.
        nearest_box: With boxes: the name of the box that distance is to.
        clear: ``clearance`` is at least the clearance asked for (always True without boxes).
        refusal: With boxes: why no collision-free posture reaches the target (which box, how
            close), "" when one does. ``reachable`` is False then.
    """

    delta: Array
    lengths: Array
    tip: Array
    error: float
    iterations: int
    reachable: bool
    starts: int
    clearance: float = math.inf
    nearest_box: str = ""
    clear: bool = True
    refusal: str = ""


@dataclasses.dataclass(frozen=True)
class Problem:
    """One target's IK problem in rack space: the target, the rack map and the limits."""

    target: Array        # (3,)
    n: int
    M: Array             # (3, 3) rack map, Delta_i = M L_i - (0, 0, L0)
    phi: float
    L0: float
    d: float
    lo: float
    hi: float
    bend_max: float      # largest |(dx, dy)| of a segment, d * theta_max


def deltas(pb: Problem, L: Array) -> Array:
    """(K, 3n) rack lengths -> (K, n, 3) deltas."""
    out = L.reshape(L.shape[0], pb.n, 3) @ pb.M.T
    out[..., 2] -= pb.L0
    return out


def evaluate(pb: Problem, L: Array) -> tuple[Array, Array, Array]:
    """Tip error vectors (K, 3), errors (K,) and tip Jacobians in L, (K, 3, 3n)."""
    p, J_delta = _dk.chain_tip_and_jacobian(deltas(pb, L), pb.L0, pb.d)
    J = (J_delta.reshape(-1, 3, pb.n, 3) @ pb.M).reshape(-1, 3, 3 * pb.n)
    e = pb.target - p
    return e, np.sqrt(np.einsum("ki,ki->k", e, e)), J


def feasible(pb: Problem, L: Array) -> Array:
    """(K, 3n) rack lengths moved into the feasible set (see :func:`delta.limit_rack_lengths`)."""
    L = np.clip(L, pb.lo, pb.hi)
    seg = L.reshape(L.shape[0], pb.n, 3)
    bend = np.linalg.norm(seg @ pb.M[:2].T, axis=-1)  # (K, n)
    over = bend > pb.bend_max
    if not over.any():
        return L
    # A hair inside the limit, so theta <= theta_max holds after rounding too.
    scale = np.where(over, pb.bend_max * (1 - 1e-12) / np.where(over, bend, 1.0), 1.0)[..., None]
    mean = seg.mean(axis=-1, keepdims=True)
    return (mean + scale * (seg - mean)).reshape(L.shape)


def _free_jacobian(pb: Problem, L: Array, J: Array, grad: Array) -> Array:
    """J_tip P: the tip Jacobians (K, 3, 3n) restricted to the directions no active limit holds.

    A rack is held at a limit the descent direction -grad pushes it through; a segment at its
    bending limit is held when -grad would bend it further (its radial bending row a_i, the
    gradient of |(dx_i, dy_i)| in L, has a_i . grad < 0).
    """
    held = ((L <= pb.lo) & (grad > 0)) | ((L >= pb.hi) & (grad < 0))
    K, n = L.shape[0], pb.n
    b = L.reshape(K, n, 3) @ pb.M[:2].T  # (K, n, 2) = (dx, dy) per segment
    bend = np.linalg.norm(b, axis=-1)
    at_limit = bend >= pb.bend_max * (1.0 - 1e-9)
    if not at_limit.any():
        return np.where(held[:, None, :], 0.0, J)
    rows = (b / np.maximum(bend, 1e-300)[..., None]) @ pb.M[:2]  # (K, n, 3): d|b_i| / dL_i
    pushed = at_limit & (np.einsum("kij,kij->ki", rows, grad.reshape(K, n, 3)) < 0)
    if not pushed.any():
        return np.where(held[:, None, :], 0.0, J)
    C = np.zeros((K, 3 * n + n, 3 * n))
    idx = np.arange(3 * n)
    C[:, idx, idx] = held
    for i in range(n):
        C[:, 3 * n + i, 3 * i:3 * i + 3] = np.where(pushed[:, i, None], rows[:, i], 0.0)
    P = np.eye(3 * n) - np.linalg.pinv(C) @ C
    return J @ P


def iterate(pb: Problem, L: Array, s: IKSettings, stop_on_first: bool) -> tuple[Array, Array, int]:
    """Projected, damped task-priority iteration of eq. (5) on K starts at once.

    Returns the final rack lengths (K, 3n), errors (K,) and the number of batch iterations.
    """
    L = feasible(pb, L)
    e, err, J = evaluate(pb, L)
    lam = np.full(L.shape[0], s.damping)
    live = err > s.goal_tolerance
    eye = np.eye(3)
    it = 0
    while it < s.max_iterations and live.any():
        if stop_on_first and (~live & (err <= s.goal_tolerance)).any():
            break
        it += 1
        idx = np.flatnonzero(live)
        Li, ei, Ji = L[idx], e[idx], J[idx]
        grad = -np.einsum("kij,ki->kj", Ji, ei)  # gradient of ||e||^2 / 2
        # Set-based limit tasks: racks and bends at a limit the tip task pushes outward are held.
        Jf = _free_jacobian(pb, Li, Ji, grad)  # J_tip P
        A = Jf @ Jf.transpose(0, 2, 1) + (lam[idx] ** 2)[:, None, None] * eye
        step = np.einsum("kij,ki->kj", Jf, np.linalg.solve(A, ei[..., None])[..., 0])
        trial = feasible(pb, Li + step)  # J_set^+ e_set: back onto the limits
        et, errt, Jt = evaluate(pb, trial)
        better = errt < err[idx]
        gain = err[idx] - errt
        acc = idx[better]
        L[acc], e[acc], J[acc] = trial[better], et[better], Jt[better]
        lam[acc] = np.maximum(lam[acc] / 5.0, _LAMBDA_MIN)
        rej = idx[~better]
        lam[rej] = lam[rej] * 10.0
        err[acc] = errt[better]
        slow = gain < np.maximum(s.stall_step, s.stall_ratio * err[idx])
        stalled = (better & slow) | (lam[idx] > _LAMBDA_MAX)
        live[idx] = ~(stalled | (err[idx] <= s.goal_tolerance))
    return L, err, it


def polish(pb: Problem, L: Array, max_iterations: int) -> tuple[Array, float, int]:
    """SLSQP on problem (4) with the bending constraints, from rack lengths ``L`` (3n,), for a
    target left out of reach ("Polish" in :mod:`core.kinematics.delta_ik`; its quasi-Newton
    Hessian does not creep).

    Returns the feasible lengths, their error and SLSQP's iteration count; a failed run returns
    ``L`` (moved into the limits) unchanged.
    """
    n, Mb = pb.n, pb.M[:2]

    def f(x: Array) -> tuple[float, Array]:
        e, _, J = evaluate(pb, x[None])
        return 0.5 * float(e[0] @ e[0]), -J[0].T @ e[0]

    def bend(x: Array) -> Array:  # >= 0: bend_max^2 - |(dx_i, dy_i)|^2 per segment
        b = x.reshape(n, 3) @ Mb.T
        return pb.bend_max ** 2 - np.einsum("ij,ij->i", b, b)

    def bend_jac(x: Array) -> Array:
        b = x.reshape(n, 3) @ Mb.T
        return np.kron(np.eye(n), np.ones((1, 3))) * np.tile(-2.0 * b @ Mb, n)

    x0 = feasible(pb, L[None])[0]
    _, err0, _ = evaluate(pb, x0[None])
    try:
        res = _minimize(f, x0, jac=True, method="SLSQP", bounds=[(pb.lo, pb.hi)] * (3 * n),
                        constraints=[{"type": "ineq", "fun": bend, "jac": bend_jac}],
                        options={"ftol": 1e-12, "maxiter": max_iterations})
    except (ValueError, ArithmeticError):
        return x0, float(err0[0]), 0
    if not np.all(np.isfinite(res.x)):
        return x0, float(err0[0]), int(res.nit)
    x = feasible(pb, res.x[None])
    err = float(evaluate(pb, x)[1][0])
    return (x[0], err, int(res.nit)) if err < err0[0] else (x0, float(err0[0]), int(res.nit))

