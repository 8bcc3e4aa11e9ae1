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
:mod:`core.kinematics.delta_ik_boxes`; the result then carries the clearance and, when no
collision-free posture reaches the target, the reason (which box, how close).

The iteration, the polish and :class:`TipIKResult` live in
:mod:`core.kinematics.delta_ik_iteration`, which the seeds and the box solver share without
importing this module (no import circle).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as _dk
from core.kinematics import delta_ik_iteration as _it
from core.kinematics.delta_ik_boxes import check_boxes, solve_clear
from core.kinematics.delta_ik_iteration import TipIKResult
from core.kinematics.delta_ik_seeds import arc_seed as _arc_seed, seeds as _seeds
from core.robot_sections import IKSettings

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]

__all__ = ["TipIKResult", "solve_tip_ik"]


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
        box_list, need = check_boxes(boxes, clearance)
        free = solve_tip_ik(robot, target, delta0, restarts=restarts, settings=settings)
        warm_delta = None if delta0 is None else _check_delta0(delta0, robot.n_segments)
        s = settings if settings is not None else IKSettings.from_robot(robot)
        return solve_clear(robot, target, free, warm_delta, box_list, need, restarts, s)
    n = robot.n_segments
    s = settings if settings is not None else IKSettings.from_robot(robot)
    M = _dk.rack_matrix(robot.phi)
    pb = _it.Problem(target, n, M, robot.phi, robot.L0, robot.d, robot.rack_min,
                     robot.rack_max, robot.bend_max)
    warm = None if delta0 is None else _check_delta0(delta0, n)
    iters, starts = 0, 0
    best_L, best_err = np.zeros(3 * n), math.inf
    if warm is not None:
        start = _dk.actuators_from_delta(warm, robot.phi, robot.L0).reshape(1, 3 * n)
        L, err, iters = _it.iterate(pb, start, s, stop_on_first=True)
        best_L, best_err, starts = L[0], float(err[0]), 1
    else:  # cold: the single-arc guess alone first (exact whenever its racks and bends fit)
        arc = _it.feasible(pb, _dk.actuators_from_delta(_arc_seed(pb, target, n), robot.phi,
                                                        robot.L0).reshape(1, 3 * n))
        err = _it.evaluate(pb, arc)[1]
        if err[0] <= s.goal_tolerance:
            best_L, best_err, starts = arc[0], float(err[0]), 1
    if best_err > s.tolerance and (restarts or warm is None):
        seeds = _seeds(pb, s.restart_seeds) if restarts else _dk.actuators_from_delta(
            _arc_seed(pb, target, n), robot.phi, robot.L0).reshape(1, 3 * n)
        Ls, errs, more = _it.iterate(pb, seeds, s, stop_on_first=True)
        iters += more
        starts += len(seeds)
        k = int(np.argmin(errs))
        if errs[k] < best_err:
            best_L, best_err = Ls[k], float(errs[k])
    if best_err > s.tolerance and s.polish_iterations:
        L, err, more = _it.polish(pb, best_L, s.polish_iterations)
        iters += more
        if err < best_err:
            best_L, best_err = L, err
    lengths = _it.feasible(pb, best_L.reshape(1, -1)).reshape(n, 3)
    delta = _it.deltas(pb, lengths.reshape(1, -1))[0]
    tip = _dk.tip_position(robot, delta)
    error = float(np.linalg.norm(target - tip))
    return TipIKResult(delta=delta, lengths=lengths, tip=tip, error=error, iterations=iters,
                       reachable=error <= s.tolerance, starts=starts)
