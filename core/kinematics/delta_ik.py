"""Tip inverse kinematics of the extensible arm within its rack limits (Hughes 2020, eq. 4-6).

Problem (4): min ||x_d - h(Delta)|| with every rack length in [rack_min, rack_max]. The paper
solves it as the steady state of the task-priority system (5): a set-based rack-limit task
(J_set, e_set) with priority over the tip task, whose (pseudo-inverted) Jacobian acts in the
null space of the active limits. Here that system is integrated as a discrete iteration.

Coordinates. The limits are a box in rack space, L = M^-1 (Delta + Delta_0), so we iterate on L
(Delta = M L - Delta_0 is affine, nothing is lost). In L the rack-limit task's Jacobian rows are
rows of the identity -- the paper's "columns of the identity matrix" -- so

* J_set selects the active racks: those at a limit that the tip task would push further out
  (the set-based activation), plus any rack outside its limits;
* J_set^+ e_set moves a violating rack back onto its limit: that is exactly the projection of L
  onto the box, applied after every step, so no iterate ever leaves the limits;
* the tip task acts through the damped pseudo-inverse of J_tip P, P = I - J_set^+ J_set (the
  free racks only), with J_tip = dh/dDelta M from :func:`delta.chain_tip_and_jacobian`.

A step is L <- clip(L + (J_tip P)^T (J_tip P (J_tip P)^T + lambda^2 I)^-1 (x_d - h)), i.e. the
Euler step of (5) with unit gain, made safe by Levenberg-Marquardt step control: the step is
kept only if the tip error decreases, otherwise lambda grows (shorter, more gradient-like steps).
Near a solution lambda shrinks to ~0 and the iteration is Gauss-Newton (quadratic convergence).
A fixed point is a KKT point of (4) (free racks: zero gradient; held racks: gradient pointing
out of the box). Using (J P)^+ rather than the literal P J^+ of (5) keeps the same solutions for
reachable targets and makes the fixed points for unreachable targets stationary points of
||x_d - h|| (locally closest feasible configurations); the iteration stops at the goal
tolerance or when it stalls (``stall_step`` / ``stall_ratio``), so those are approximate.
The metric of the pseudo-inverse is the rack space (minimum rack travel per step), which picks
among the redundant solutions; the paper's J^+ in Delta would pick others.

Starts. A warm start (e.g. the current posture) is iterated alone. A cold start, or a warm start
that stalls above the tolerance, iterates a batch of seeds together (vectorised): the single
constant-curvature arc through the target (the exact solution whenever its racks are within
limits), arcs after straight proximal segments, straight postures and a fixed low-discrepancy
set over the rack box; the first to converge (or the best) wins. The final rack lengths are
clipped onto the box once more and the error is re-evaluated by forward kinematics. Solver
settings come from the robot file's optional ``[ik]`` table.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]

_LAMBDA_MIN = 1e-5  # lambda^2 = 1e-10: keeps J P (J P)^T + lambda^2 I well conditioned
_LAMBDA_MAX = 1e6


@dataclasses.dataclass(frozen=True)
class IKSettings:
    """Solver settings (robot file ``[ik]``; every key optional).

    Attributes:
        tolerance: A target is reachable when the final error is <= this (m).
        goal_tolerance: The iteration stops early once the error is <= this (m).
        damping: Initial Levenberg-Marquardt damping lambda.
        max_iterations: Iterations per start.
        restart_seeds: Number of low-discrepancy seeds added to the structured restart seeds
            (0 disables restarts from those).
        stall_step: A start stops when its error improves by less than this per iteration (m).
        stall_ratio: ... or by less than this fraction of its error (a local minimum).
    """

    tolerance: float = 1e-3
    goal_tolerance: float = 1e-6
    damping: float = 1e-3
    max_iterations: int = 60
    restart_seeds: int = 12
    stall_step: float = 1e-9
    stall_ratio: float = 1e-4

    @classmethod
    def from_robot(cls, robot: "ExtensibleArm") -> "IKSettings":
        """Defaults overridden by the robot file's ``[ik]`` table; bad values raise ValueError."""
        table: Mapping[str, Any] = robot.raw.get("ik", {}) if robot.raw else {}
        kwargs: dict[str, Any] = {}
        for field in dataclasses.fields(cls):
            if field.name not in table:
                continue
            value = table[field.name]
            if field.type in ("int", int):
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise ValueError(f"ik.{field.name}: must be an integer >= 0, got {value!r}")
            elif (isinstance(value, bool) or not isinstance(value, (int, float))
                  or not math.isfinite(value) or value <= 0):
                raise ValueError(f"ik.{field.name}: must be a finite number > 0, got {value!r}")
            kwargs[field.name] = value
        unknown = set(table) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"ik: unknown keys {sorted(unknown)}")
        settings = cls(**kwargs)
        if settings.max_iterations < 1:
            raise ValueError("ik.max_iterations: must be >= 1")
        if settings.goal_tolerance > settings.tolerance:
            raise ValueError(f"ik.goal_tolerance: must be <= ik.tolerance ({settings.tolerance:g}), "
                             f"got {settings.goal_tolerance:g}")
        return settings


@dataclasses.dataclass(frozen=True)
class TipIKResult:
    """Outcome of :func:`solve_tip_ik`.

    Attributes:
        delta: (n, 3) postures (dx, dy, dL) per segment.
        lengths: (n, 3) rack lengths, always within [rack_min, rack_max].
        tip: (3,) tip position reached, h(delta).
        error: Distance from ``tip`` to the target (m).
        iterations: Iterations spent over all starts.
        reachable: ``error <= tolerance``.
        starts: Starts iterated: 1 when the warm start converged, otherwise the warm start (if
            any) plus the batch of seeds.
    """

    delta: Array
    lengths: Array
    tip: Array
    error: float
    iterations: int
    reachable: bool
    starts: int


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


def _iterate(pb: _Problem, L: Array, s: IKSettings, stop_on_first: bool) -> tuple[Array, Array, int]:
    """Projected, damped task-priority iteration of eq. (5) on K starts at once.

    Returns the final rack lengths (K, 3n), errors (K,) and the number of batch iterations.
    """
    L = np.clip(L, pb.lo, pb.hi)
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
        # Set-based rack-limit task: racks at a limit that the tip task pushes outward are held.
        held = ((Li <= pb.lo) & (grad > 0)) | ((Li >= pb.hi) & (grad < 0))
        Jf = np.where(held[:, None, :], 0.0, Ji)  # J_tip P
        A = Jf @ Jf.transpose(0, 2, 1) + (lam[idx] ** 2)[:, None, None] * eye
        step = np.einsum("kij,ki->kj", Jf, np.linalg.solve(A, ei[..., None])[..., 0])
        trial = np.clip(Li + step, pb.lo, pb.hi)  # J_set^+ e_set: back onto the limits
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


def _arc_seed(pb: _Problem, rel: Array, n_arc: int) -> Array:
    """Deltas (n_arc, 3) bending one constant-curvature arc from the origin through ``rel``."""
    x, y, z = rel
    r = math.hypot(x, y)
    az = math.atan2(y, x)
    big_theta = 2.0 * math.atan2(r, z)  # total bend of the arc, [0, 2 pi]
    chord = math.hypot(r, z)
    half = 0.5 * big_theta
    s = chord if half < 1e-6 else chord * half / max(math.sin(half), 1e-3)
    theta_i, len_i = big_theta / n_arc, s / n_arc
    seg = np.array([theta_i * pb.d * math.cos(az), theta_i * pb.d * math.sin(az), len_i - pb.L0])
    return np.tile(seg, (n_arc, 1))


def _halton(count: int, dim: int) -> Array:
    """First ``count`` points (skipping 0) of the Halton sequence in [0, 1)^dim (deterministic)."""
    primes = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61]
    if dim > len(primes):  # more than 6 segments: a fixed pseudo-random set instead
        return np.random.default_rng(dim).uniform(size=(count, dim))
    out = np.zeros((count, dim))
    for k in range(count):
        for j in range(dim):
            f, i, x = 1.0, k + 1, 0.0
            while i:
                f /= primes[j]
                x += f * (i % primes[j])
                i //= primes[j]
            out[k, j] = x
    return out


def _seeds(pb: _Problem, s: IKSettings) -> Array:
    """Restart seeds as rack lengths (K, 3n)."""
    n = pb.n
    deltas = [_arc_seed(pb, pb.target, n)]
    straight = np.zeros((n, 3))
    for frac in (0.25, 0.75):
        # Proximal segments straight at a fraction of their range, the rest as one arc.
        for k in range(1, n):
            head = np.zeros((k, 3))
            head[:, 2] = pb.lo + frac * (pb.hi - pb.lo) - pb.L0
            rel = pb.target - np.array([0.0, 0.0, k * (pb.lo + frac * (pb.hi - pb.lo))])
            deltas.append(np.vstack([head, _arc_seed(pb, rel, n - k)]))
    for frac in (0.0, 0.5):
        straight[:, 2] = pb.lo + frac * (pb.hi - pb.lo) - pb.L0
        deltas.append(straight.copy())
    L = _dk.actuators_from_delta(np.stack(deltas), pb.phi, pb.L0).reshape(len(deltas), 3 * n)
    if s.restart_seeds:
        L = np.vstack([L, pb.lo + (pb.hi - pb.lo) * _halton(s.restart_seeds, 3 * n)])
    return L


def solve_tip_ik(robot: "ExtensibleArm", target_xyz: npt.ArrayLike,
                 delta0: npt.ArrayLike | None = None, *, restarts: bool = True,
                 settings: IKSettings | None = None) -> TipIKResult:
    """Postures that put the tip at ``target_xyz`` with every rack within its limits.

    Args:
        robot: The extensible arm (``core.robots.load("extensible")``).
        target_xyz: (3,) tip target in the base frame (m).
        delta0: (n, 3) warm start (e.g. the current posture); projected onto the rack limits.
            ``None`` iterates the batch of seeds at once, the single-arc guess through the
            target first (exact whenever that arc's racks are within their limits).
        restarts: Iterate the batch of seeds when the warm start stalls above the tolerance.
            Turn off to follow one continuous branch (path tracking).
        settings: Overrides the robot file's ``[ik]`` settings.

    Returns:
        The best configuration found; for an unreachable target the closest feasible one found,
        with ``error`` its distance and ``reachable`` False.

    Raises:
        ValueError: the robot is not a delta arm, or the target / warm start has the wrong
            shape or is not finite.
    """
    _check_robot(robot)
    target = _check_target(target_xyz)
    n = robot.n_segments
    s = settings if settings is not None else IKSettings.from_robot(robot)
    M = _dk.rack_matrix(robot.phi)
    pb = _Problem(target, n, M, robot.phi, robot.L0, robot.d, robot.rack_min, robot.rack_max)
    warm = None if delta0 is None else _check_delta0(delta0, n)
    iters, starts = 0, 0
    best_L, best_err = np.zeros(3 * n), math.inf
    if warm is not None:
        start = _dk.actuators_from_delta(warm, robot.phi, robot.L0).reshape(1, 3 * n)
        L, err, iters = _iterate(pb, start, s, stop_on_first=True)
        best_L, best_err, starts = L[0], float(err[0]), 1
    if best_err > s.tolerance and (restarts or warm is None):
        seeds = _seeds(pb, s) if restarts else _dk.actuators_from_delta(
            _arc_seed(pb, target, n), robot.phi, robot.L0).reshape(1, 3 * n)
        Ls, errs, more = _iterate(pb, seeds, s, stop_on_first=True)
        iters += more
        starts += len(seeds)
        k = int(np.argmin(errs))
        if errs[k] < best_err:
            best_L, best_err = Ls[k], float(errs[k])
    lengths = np.clip(best_L, robot.rack_min, robot.rack_max).reshape(n, 3)
    delta = _deltas(pb, lengths.reshape(1, -1))[0]
    tip = _dk.tip_position(robot, delta)
    error = float(np.linalg.norm(target - tip))
    return TipIKResult(delta=delta, lengths=lengths, tip=tip, error=error, iterations=iters,
                       reachable=error <= s.tolerance, starts=starts)


# Imported last: core.kinematics.delta re-exports solve_tip_ik from here at its end, so either
# module may be imported first without a partially initialised import.
from core.kinematics import delta as _dk  # noqa: E402
