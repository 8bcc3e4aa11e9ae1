"""Tip inverse kinematics of the extensible arm within its rack and bending limits (Hughes 2020,
eq. 4-6).

Problem (4): min ||x_d - h(Delta)|| with every rack length in [rack_min, rack_max], plus a
bending limit the paper leaves implicit: every segment's theta = |(dx, dy)| / d <= theta_max
(robot file ``segments.theta_max``; the racks alone would allow ~8 rad). The paper solves (4) as
the steady state of the task-priority system (5): a set-based limit task (J_set, e_set) with
priority over the tip task, whose (pseudo-inverted) Jacobian acts in the null space of the
active limits. Here that system is integrated as a discrete iteration.

Coordinates. The limits are a box in rack space, L = M^-1 (Delta + Delta_0), so we iterate on L
(Delta = M L - Delta_0 is affine, nothing is lost). In L the rack-limit task's Jacobian rows are
rows of the identity -- the paper's "columns of the identity matrix" -- so

* J_set selects the active racks: those at a limit that the tip task would push further out
  (the set-based activation), plus any rack outside its limits;
* the bending limit is a second set-based task with one row per segment: the gradient of
  |(dx_i, dy_i)| with respect to L (the radial bending direction), active when the segment is at
  theta_max and the tip task would bend it further;
* J_set^+ e_set moves a violating iterate back onto its limits: after every step the racks are
  clipped onto the box and a segment bent beyond theta_max has its bending scaled back
  (:func:`delta.limit_rack_lengths`, which stays in the box), so no iterate ever leaves the
  feasible set (convex: a box intersected with one elliptic cylinder per segment);
* the tip task acts through the damped pseudo-inverse of J_tip P, P = I - J_set^+ J_set (the
  free directions only; column selection when only racks are held), with
  J_tip = dh/dDelta M from :func:`delta.chain_tip_and_jacobian`.

A step is L <- limit(L + (J_tip P)^T (J_tip P (J_tip P)^T + lambda^2 I)^-1 (x_d - h)), i.e. the
Euler step of (5) with unit gain, made safe by Levenberg-Marquardt step control: the step is
kept only if the tip error decreases, otherwise lambda grows (shorter, more gradient-like steps).
Near a solution lambda shrinks to ~0 and the iteration is Gauss-Newton (quadratic convergence).
A fixed point is a KKT point of (4) (free racks: zero gradient; held racks: gradient pointing
out of the box). Using (J P)^+ rather than the literal P J^+ of (5) keeps the same solutions for
reachable targets and makes the fixed points for unreachable targets stationary points of
||x_d - h|| (locally closest feasible configurations); the iteration stops at the goal
tolerance or when it stalls (``stall_step`` / ``stall_ratio``), so those are approximate.
(With the activation tested per limit, a stall may also happen where a bend and a rack limit
interact; the polish below covers it.)
The metric of the pseudo-inverse is the rack space (minimum rack travel per step), which picks
among the redundant solutions; the paper's J^+ in Delta would pick others.

Starts. A warm start (e.g. the current posture) is iterated alone. A cold start first tries the
single-arc guess alone (no iteration when it is exact). A cold start it does not solve, or a
warm start that stalls above the tolerance, iterates a batch of seeds together (vectorised):
the single constant-curvature arc through the target (the exact solution whenever its racks are within
limits), arcs after straight proximal segments, straight postures and a fixed low-discrepancy
set over the rack box (each moved into the feasible set); the first to converge (or the best)
wins (:mod:`core.kinematics.delta_ik_seeds`).

Polish. For a target left out of reach the iteration's Gauss-Newton model (no error-weighted
second derivatives of h) is poor, and on the curved bending limit it only creeps (measured: up
to ~9 mm short of the closest configuration), so the best start is polished by SLSQP on the
same problem (``polish_iterations``) and kept if closer. Reachable targets never get here.

The final rack lengths are moved into the feasible set once more and the error is re-evaluated
by forward kinematics. Solver settings come from the robot file's optional ``[ik]`` table.

Box obstacles. With ``boxes`` the arm's body (every point within the robot file's
``body_radius`` of the backbone) must also keep ``clearance`` from every box:
one more set-based task with priority over the tip, solved in
:mod:`core.kinematics.delta_ik_boxes` (which imports this module, hence the import inside
:func:`solve_tip_ik`); the result then carries the clearance and, when no collision-free
posture reaches the target, the reason (which box, how close).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize as _minimize

from core.kinematics import delta as _dk
from core.kinematics.delta_ik_seeds import arc_seed as _arc_seed, seeds as _seeds
from core.robot_sections import IKSettings

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]

_LAMBDA_MIN = 1e-5  # lambda^2 = 1e-10: keeps J P (J P)^T + lambda^2 I well conditioned
_LAMBDA_MAX = 1e6


@dataclasses.dataclass(frozen=True)
class TipIKResult:
    """Outcome of :func:`solve_tip_ik`.

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
class _Problem:
    target: Array        # (3,)
    n: int
    M: Array             # (3, 3) rack map, Delta_i = M L_i - (0, 0, L0)
    phi: float
    L0: float
    d: float
    lo: float
    hi: float
    bend_max: float      # largest |(dx, dy)| of a segment, d * theta_max


def _check_robot(robot: Any) -> None:
    if getattr(robot, "kind", None) != "delta":
        raise ValueError(f"robot must be an extensible (delta) arm, got {type(robot).__name__}")


def _check_target(target_xyz: npt.ArrayLike) -> Array:
    try:
        target = np.asarray(target_xyz, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"target_xyz must be 3 numbers (x, y, z), got {target_xyz!r}") from None
    if target.shape != (3,):
        raise ValueError(f"target_xyz must have shape (3,), got {target.shape}")
    if not np.all(np.isfinite(target)):
        raise ValueError(f"target_xyz must be finite, got {target.tolist()}")
    return target


def _check_delta0(delta0: npt.ArrayLike, n: int) -> Array:
    try:
        arr = np.asarray(delta0, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"delta0 must be an ({n}, 3) array, got {delta0!r}") from None
    if arr.shape == (3 * n,):
        arr = arr.reshape(n, 3)
    if arr.shape != (n, 3):
        raise ValueError(f"delta0 must have shape ({n}, 3) (or ({3 * n},)), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("delta0 must be finite")
    return arr


def _deltas(pb: _Problem, L: Array) -> Array:
    """(K, 3n) rack lengths -> (K, n, 3) deltas."""
    out = L.reshape(L.shape[0], pb.n, 3) @ pb.M.T
    out[..., 2] -= pb.L0
    return out


def _evaluate(pb: _Problem, L: Array) -> tuple[Array, Array, Array]:
    """Tip error vectors (K, 3), errors (K,) and tip Jacobians in L, (K, 3, 3n)."""
    p, J_delta = _dk.chain_tip_and_jacobian(_deltas(pb, L), pb.L0, pb.d)
    J = (J_delta.reshape(-1, 3, pb.n, 3) @ pb.M).reshape(-1, 3, 3 * pb.n)
    e = pb.target - p
    return e, np.sqrt(np.einsum("ki,ki->k", e, e)), J


def _feasible(pb: _Problem, L: Array) -> Array:
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


def _free_jacobian(pb: _Problem, L: Array, J: Array, grad: Array) -> Array:
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


def _iterate(pb: _Problem, L: Array, s: IKSettings, stop_on_first: bool) -> tuple[Array, Array, int]:
    """Projected, damped task-priority iteration of eq. (5) on K starts at once.

    Returns the final rack lengths (K, 3n), errors (K,) and the number of batch iterations.
    """
    L = _feasible(pb, L)
    e, err, J = _evaluate(pb, L)
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
        trial = _feasible(pb, Li + step)  # J_set^+ e_set: back onto the limits
        et, errt, Jt = _evaluate(pb, trial)
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


def _polish(pb: _Problem, L: Array, max_iterations: int) -> tuple[Array, float, int]:
    """SLSQP on problem (4) with the bending constraints, from rack lengths ``L`` (3n,), for a
    target left out of reach (see "Polish" above; its quasi-Newton Hessian does not creep).

    Returns the feasible lengths, their error and SLSQP's iteration count; a failed run returns
    ``L`` (moved into the limits) unchanged.
    """
    n, Mb = pb.n, pb.M[:2]

    def f(x: Array) -> tuple[float, Array]:
        e, _, J = _evaluate(pb, x[None])
        return 0.5 * float(e[0] @ e[0]), -J[0].T @ e[0]

    def bend(x: Array) -> Array:  # >= 0: bend_max^2 - |(dx_i, dy_i)|^2 per segment
        b = x.reshape(n, 3) @ Mb.T
        return pb.bend_max ** 2 - np.einsum("ij,ij->i", b, b)

    def bend_jac(x: Array) -> Array:
        b = x.reshape(n, 3) @ Mb.T
        return np.kron(np.eye(n), np.ones((1, 3))) * np.tile(-2.0 * b @ Mb, n)

    x0 = _feasible(pb, L[None])[0]
    _, err0, _ = _evaluate(pb, x0[None])
    try:
        res = _minimize(f, x0, jac=True, method="SLSQP", bounds=[(pb.lo, pb.hi)] * (3 * n),
                        constraints=[{"type": "ineq", "fun": bend, "jac": bend_jac}],
                        options={"ftol": 1e-12, "maxiter": max_iterations})
    except (ValueError, ArithmeticError):
        return x0, float(err0[0]), 0
    if not np.all(np.isfinite(res.x)):
        return x0, float(err0[0]), int(res.nit)
    x = _feasible(pb, res.x[None])
    err = float(_evaluate(pb, x)[1][0])
    return (x[0], err, int(res.nit)) if err < err0[0] else (x0, float(err0[0]), int(res.nit))


def solve_tip_ik(robot: "ExtensibleArm", target_xyz: npt.ArrayLike,
                 delta0: npt.ArrayLike | None = None, *, restarts: bool = True,
                 settings: IKSettings | None = None, boxes: Sequence[Any] = (),
                 clearance: float = 0.0) -> TipIKResult:
    """Postures that put the tip at ``target_xyz`` with every rack and bend within its limits.

    Args:
        robot: The extensible arm (``core.robots.load("extensible")``).
        target_xyz: (3,) tip target in the base frame (m).
        delta0: (n, 3) warm start (e.g. the current posture); moved into the limits.
            ``None`` iterates the batch of seeds at once, the single-arc guess through the
            target first (exact whenever that arc's racks are within their limits).
        restarts: Iterate the batch of seeds when the warm start stalls above the tolerance.
            Turn off to follow one continuous branch (path tracking).
        settings: Overrides the robot file's ``[ik]`` settings.
        boxes: Box obstacles (:class:`core.kinematics.box_clearance.Box`): the arm's body
            (``body_radius`` around the backbone) must stay ``clearance`` away from each (a
            set-based task with priority over the tip, :mod:`core.kinematics.delta_ik_boxes`).
        clearance: Distance (m) the body's surface keeps from every box.

    Returns:
        The best configuration found; for an unreachable target the closest feasible one found,
        with ``error`` its distance and ``reachable`` False. With boxes, the closest
        collision-free one, and ``refusal`` says why when none reaches the target.

    Raises:
        ValueError: the robot is not a delta arm, or the target / warm start / boxes /
            clearance is bad.
    """
    _check_robot(robot)
    target = _check_target(target_xyz)
    if boxes:
        from core.kinematics.delta_ik_boxes import check_boxes, solve_clear  # it imports us
        box_list, need = check_boxes(boxes, clearance)
        free = solve_tip_ik(robot, target, delta0, restarts=restarts, settings=settings)
        warm_delta = None if delta0 is None else _check_delta0(delta0, robot.n_segments)
        s = settings if settings is not None else IKSettings.from_robot(robot)
        return solve_clear(robot, target, free, warm_delta, box_list, need, restarts, s)
    n = robot.n_segments
    s = settings if settings is not None else IKSettings.from_robot(robot)
    M = _dk.rack_matrix(robot.phi)
    pb = _Problem(target, n, M, robot.phi, robot.L0, robot.d, robot.rack_min, robot.rack_max,
                  robot.bend_max)
    warm = None if delta0 is None else _check_delta0(delta0, n)
    iters, starts = 0, 0
    best_L, best_err = np.zeros(3 * n), math.inf
    if warm is not None:
        start = _dk.actuators_from_delta(warm, robot.phi, robot.L0).reshape(1, 3 * n)
        L, err, iters = _iterate(pb, start, s, stop_on_first=True)
        best_L, best_err, starts = L[0], float(err[0]), 1
    else:  # cold: the single-arc guess alone first (exact whenever its racks and bends fit)
        arc = _feasible(pb, _dk.actuators_from_delta(_arc_seed(pb, target, n), robot.phi,
                                                     robot.L0).reshape(1, 3 * n))
        err = _evaluate(pb, arc)[1]
        if err[0] <= s.goal_tolerance:
            best_L, best_err, starts = arc[0], float(err[0]), 1
    if best_err > s.tolerance and (restarts or warm is None):
        seeds = _seeds(pb, s.restart_seeds) if restarts else _dk.actuators_from_delta(
            _arc_seed(pb, target, n), robot.phi, robot.L0).reshape(1, 3 * n)
        Ls, errs, more = _iterate(pb, seeds, s, stop_on_first=True)
        iters += more
        starts += len(seeds)
        k = int(np.argmin(errs))
        if errs[k] < best_err:
            best_L, best_err = Ls[k], float(errs[k])
    if best_err > s.tolerance and s.polish_iterations:
        L, err, more = _polish(pb, best_L, s.polish_iterations)
        iters += more
        if err < best_err:
            best_L, best_err = L, err
    lengths = _feasible(pb, best_L.reshape(1, -1)).reshape(n, 3)
    delta = _deltas(pb, lengths.reshape(1, -1))[0]
    tip = _dk.tip_position(robot, delta)
    error = float(np.linalg.norm(target - tip))
    return TipIKResult(delta=delta, lengths=lengths, tip=tip, error=error, iterations=iters,
                       reachable=error <= s.tolerance, starts=starts)
