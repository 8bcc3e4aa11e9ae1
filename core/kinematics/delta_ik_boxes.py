"""Tip IK that keeps the extensible arm's body a set clearance away from box obstacles.

Problem (4) of Hughes 2020 with one more set-based task of the kind eq. (5) gives priority over
the tip task: the arm's body (every point within ``body_radius`` r of the backbone) must stay
``clearance`` away from every box, i.e. every sampled backbone point p_k(L) must satisfy

    min ||x_d - h(L)||   s.t.  L in [rack_min, rack_max]^3n,  |(dx_i, dy_i)| <= d theta_max,
                              sd_b(p_k(L)) - r >= clearance   for every box b and sample k,

where sd_b is the signed distance to box b (:mod:`core.kinematics.box_clearance`). The rack and
bending limits are the paper's set-based tasks; the clearance rows are inequality constraints
of the same kind (only the ones at their bound act, the tip task works in the rest). As a
discrete solver we use an active-set SQP (SLSQP) on the racks, whose QP holds exactly the
active limit and clearance rows in each step:

1. the plain IK (:func:`core.kinematics.delta_ik.solve_tip_ik` without boxes, which calls
   :func:`solve_clear` with its answer) first; its
   posture is kept when a dense check of the whole backbone (every ``DENSE_SPACING``) is clear;
2. otherwise every seed the plain IK uses is iterated to its own solution branch, the clear
   ones are taken as they are, and the SQP starts from the others (the least penetrating
   first) with the clearance rows on ``SAMPLES`` backbone points per segment plus a
   ``margin`` for what lies between them; every answer is checked densely, and a dense
   violation raises the margin by it and solves again (``_MARGIN_TRIES`` times);
3. the first clear posture that reaches the target within tolerance wins, else the clear one
   closest to it; when there is none, or the target itself is in or too near a box, the result
   says why (:attr:`TipIKResult.refusal`, naming the box and the distance).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize as _minimize

from core.kinematics import box_clearance as bc
from core.kinematics import delta as _dk
from core.kinematics import delta_ik_iteration as _it
from core.kinematics.delta_ik_seeds import seeds as _seeds
from core.robot_sections import IKSettings

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]
SAMPLES = 24          # backbone points per segment in the SQP's clearance rows
MARGIN = 0.002        # m added to the clearance in the SQP (the arc between its samples)
SEEDS = 24            # low-discrepancy seeds with boxes (the plain IK's restart_seeds if more)
MAX_STARTS = 10       # SQP starts at most per solve
_MARGIN_TRIES = 3
_FD_STEP = 1e-6       # m, central differences of the backbone samples in the racks
_SCALE = 1.0         # objective in m^2 / 2 (SLSQP starts from an identity Hessian: steps in m)


def _points(robot: ExtensibleArm, pb: _it.Problem, L: Array) -> Array:
    """Backbone samples (K, n * SAMPLES, 3) (the base left out) of rack lengths (K, 3n)."""
    return bc.backbone_points(robot, _it.deltas(pb, L), SAMPLES)[:, 1:]


def _constraints(robot: ExtensibleArm, pb: _it.Problem, boxes: Sequence[bc.Box],
                 need: float) -> tuple:
    n3 = 3 * pb.n
    steps = np.vstack([np.zeros(n3), _FD_STEP * np.eye(n3), -_FD_STEP * np.eye(n3)])

    def both(x: Array) -> tuple[Array, Array]:
        pts = _points(robot, pb, x[None] + steps)                   # (1 + 2 n3, P, 3)
        dp = (pts[1:n3 + 1] - pts[n3 + 1:]) / (2 * _FD_STEP)          # (n3, P, 3)
        vals, jacs = [], []
        for box in boxes:
            d, g = bc.signed_distance_and_gradient(pts[0], box)
            vals.append(d - robot.body_radius - need)
            jacs.append(np.einsum("pi,jpi->pj", g, dp))
        return np.concatenate(vals), np.concatenate(jacs)

    cache: dict[bytes, tuple[Array, Array]] = {}

    def cached(x: Array) -> tuple[Array, Array]:
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = both(x)
        return cache[key]

    return (lambda x: cached(x)[0]), (lambda x: cached(x)[1])


def _sqp(robot: ExtensibleArm, pb: _it.Problem, x0: Array, boxes: Sequence[bc.Box],
         need: float, iterations: int) -> Array:
    """One SLSQP run from rack lengths ``x0`` (3n,); returns its end (moved into the limits)."""
    n, Mb = pb.n, pb.M[:2]

    def f(x: Array) -> tuple[float, Array]:
        e, _, J = _it.evaluate(pb, x[None])
        return 0.5 * _SCALE * float(e[0] @ e[0]), -_SCALE * (J[0].T @ e[0])

    def bend(x: Array) -> Array:
        b = x.reshape(n, 3) @ Mb.T
        return pb.bend_max ** 2 - np.einsum("ij,ij->i", b, b)

    def bend_jac(x: Array) -> Array:
        b = x.reshape(n, 3) @ Mb.T
        return np.kron(np.eye(n), np.ones((1, 3))) * np.tile(-2.0 * b @ Mb, n)

    fun, jac = _constraints(robot, pb, boxes, need)
    try:
        res = _minimize(f, x0, jac=True, method="SLSQP", bounds=[(pb.lo, pb.hi)] * (3 * n),
                        constraints=[{"type": "ineq", "fun": bend, "jac": bend_jac},
                                     {"type": "ineq", "fun": fun, "jac": jac}],
                        options={"ftol": 1e-14, "maxiter": iterations})
        x = res.x if np.all(np.isfinite(res.x)) else x0
    except (ValueError, ArithmeticError):
        x = x0
    return _it.feasible(pb, np.asarray(x, dtype=float)[None])[0]


@dataclasses.dataclass(frozen=True)
class _Candidate:
    L: Array          # (3n,) rack lengths
    error: float      # tip to target (m)
    clear: bc.Clearance


def _candidate(robot: ExtensibleArm, pb: _it.Problem, L: Array,
               boxes: Sequence[bc.Box]) -> _Candidate:
    L = _it.feasible(pb, L[None])[0]
    err = float(_it.evaluate(pb, L[None])[1][0])
    return _Candidate(L, err, bc.clearance_of(robot, _it.deltas(pb, L[None])[0], boxes))


def _mm(x: float) -> str:
    return f"{x * 1e3:.1f} mm"


def solve_clear(robot: ExtensibleArm, target: Array, free: _it.TipIKResult,
                warm: Array | None, boxes: Sequence[bc.Box], clearance: float, restarts: bool,
                s: IKSettings) -> _it.TipIKResult:
    """The collision-free answer, given the plain IK's answer ``free`` (see the module)."""
    n = robot.n_segments
    pb = _it.Problem(target, n, _dk.rack_matrix(robot.phi), robot.phi, robot.L0, robot.d,
                     robot.rack_min, robot.rack_max, robot.bend_max)
    first = _candidate(robot, pb, free.lengths.reshape(-1), boxes)
    if first.clear.clear_of(clearance):
        return _result(robot, pb, first, s, clearance, free.iterations, free.starts, "")
    # The target itself: the tip is a backbone point, with the body around it.
    near = min(boxes, key=lambda b: float(bc.signed_distance(target, b)))
    d_t = float(bc.signed_distance(target, near))
    if d_t - robot.body_radius < clearance:
        body = (f"{_mm(d_t)} from box '{near.name}': the arm's body there "
                f"({_mm(robot.body_radius)} radius)")
        where = (f"inside box '{near.name}'" if d_t < 0 else
                 f"{body} would reach into it" if d_t < robot.body_radius else
                 f"{body} would be {_mm(d_t - robot.body_radius)} from it, closer than the "
                 f"clearance {_mm(clearance)}")
        return _result(robot, pb, first, s, clearance, free.iterations, free.starts,
                       f"the target is {where}")
    starts: list[Array] = [first.L]
    if warm is not None:
        starts.append(_dk.actuators_from_delta(warm, robot.phi, robot.L0).reshape(-1))
    iters, count = free.iterations, free.starts
    if restarts or warm is None:
        seeds = _seeds(pb, max(s.restart_seeds, SEEDS))
        Ls, _, more = _it.iterate(pb, seeds, s, stop_on_first=False)
        iters, count = iters + more, count + len(seeds)
        branches = [_candidate(robot, pb, x, boxes) for x in Ls]
        reached = [c for c in branches if c.error <= s.tolerance]
        done = [c for c in reached if c.clear.clear_of(clearance)]
        if done:
            best = max(done, key=lambda c: c.clear.distance)
            return _result(robot, pb, best, s, clearance, iters, count, "")
        order = sorted(branches, key=lambda c: (c.error > s.tolerance, -c.clear.distance))
        starts += [c.L for c in order]
    best: _Candidate | None = None
    for x0 in starts[:MAX_STARTS]:
        margin = MARGIN
        for _ in range(_MARGIN_TRIES):
            x = _sqp(robot, pb, x0, boxes, clearance + margin, max(s.polish_iterations, 100))
            cand = _candidate(robot, pb, x, boxes)
            short = clearance - cand.clear.distance
            if short <= 0:
                break
            margin += short + 1e-4
            x0 = x
        iters += 1
        if not cand.clear.clear_of(clearance):
            continue
        if best is None or cand.error < best.error:
            best = cand
        if best.error <= s.tolerance:
            break
    if best is None:
        return _result(robot, pb, first, s, clearance, iters, count,
                       f"no collision-free posture was found: {first.clear.describe()} "
                       f"(clearance {_mm(clearance)})")
    if best.error <= s.tolerance:
        return _result(robot, pb, best, s, clearance, iters, count, "")
    why = (f"{'the boxes block it' if free.reachable else 'it is out of reach'}: the closest "
           f"collision-free posture found puts the tip "
           f"{_mm(best.error)} from the target, with the arm {_mm(best.clear.distance)} "
           f"from box '{best.clear.box}'")
    if free.reachable:
        why += f" (without the boxes it is reachable, but {first.clear.describe()})"
    return _result(robot, pb, best, s, clearance, iters, count, why)


def _result(robot: ExtensibleArm, pb: _it.Problem, cand: _Candidate, s: IKSettings,
            clearance: float, iterations: int, starts: int, refusal: str) -> _it.TipIKResult:
    lengths = cand.L.reshape(pb.n, 3)
    delta = _it.deltas(pb, cand.L[None])[0]
    tip = _dk.tip_position(robot, delta)
    error = float(np.linalg.norm(pb.target - tip))
    clear = cand.clear.clear_of(clearance)
    return _it.TipIKResult(delta=delta, lengths=lengths, tip=tip, error=error,
                           iterations=iterations,
                           reachable=error <= s.tolerance and clear and not refusal,
                           starts=starts, clearance=cand.clear.distance,
                           nearest_box=cand.clear.box, clear=clear, refusal=refusal)


def check_boxes(boxes: object, clearance: object) -> tuple[tuple[bc.Box, ...], float]:
    """Boxes (a sequence of :class:`~core.kinematics.box_clearance.Box`, unique names) and
    a clearance, checked; ValueError otherwise."""
    c = bc.check_clearance(clearance)
    items = tuple(boxes or ())  # type: ignore[arg-type]
    if not all(isinstance(b, bc.Box) for b in items):
        raise ValueError("boxes must be core.kinematics.box_clearance.Box objects")
    names = [b.name for b in items]
    if len(set(names)) != len(names):
        raise ValueError("box names must be unique")
    return items, c


__all__ = ["check_boxes", "solve_clear"]
