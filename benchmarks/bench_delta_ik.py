"""Speed and success of the extensible arm's tip IK, side by side with baselines in the same run.

Goal (issue 5): median <= 5 ms to 1 mm for the two-segment arm, 100 % of reachable targets.
Targets are reachable by construction: tips of random rack lengths within the rack limits whose
segments bend no more than theta_max (rejection sampling). Every answer must be within the rack
and bending limits (asserted).

Rows:
  solve_tip_ik cold        delta0=None (seed batch, single-arc guess first)
  solve_tip_ik warm        delta0 = the generating posture with every rack moved by up to 1 cm
  solve_tip_ik retracted   delta0 = 0 (straight, retracted arm; restarts when it stalls)
  eq.(5) Euler h=...       the literal eq. (5) (Moore-Penrose J^+, J_set / e_set of the violated
                           racks and, as one more row per segment, of a violated bending limit)
                           integrated by explicit Euler from the retracted arm, then projected
                           onto the limits ("numerically evaluated through simulations")
  SLSQP (L, bend constr.)  scipy.optimize.minimize on ||x_d - h||^2 / 2 with analytic gradient,
                           rack bounds and dx^2 + dy^2 <= (d theta_max)^2 per segment, from the
                           retracted arm

Columns for solve_tip_ik: median iterations (summed over starts), share solved with no
iteration (the start was already within the goal tolerance: for cold starts, the single-arc
guess is exact), share that iterated the seed batch (cold start, or a warm start that stalled).

Run: .venv/bin/python benchmarks/bench_delta_ik.py [--targets 200] [--baseline-targets 50]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from core import robots  # noqa: E402
from core.kinematics import delta as dk  # noqa: E402
from core.kinematics.delta_ik import solve_tip_ik  # noqa: E402

TOL = 1e-3


def literal_eq5(robot, target, h: float, max_steps: int) -> tuple[np.ndarray, int]:
    """Eq. (5) as printed, explicit Euler with step h, from the retracted arm; rack lengths.

    The bending limit is one more set-based row per segment: d|(dx, dy)| / dDelta with error
    bend_max - |(dx, dy)| while violated.
    """
    n = robot.n_segments
    Minv = np.kron(np.eye(n), dk.rack_matrix_inverse(robot.phi))  # dL / dDelta
    offset = np.tile([0.0, 0.0, robot.L0], n)
    delta = np.zeros(3 * n)
    steps = 0
    for steps in range(1, max_steps + 1):
        L = Minv @ (delta + offset)
        low, high = L < robot.rack_min, L > robot.rack_max
        b = delta.reshape(n, 3)[:, :2]
        size = np.linalg.norm(b, axis=1)
        bent = size > robot.bend_max
        p, J = dk.chain_tip_and_jacobian(delta.reshape(n, 3), robot.L0, robot.d)
        e = target - p
        if np.linalg.norm(e) <= TOL and not (low.any() or high.any() or bent.any()):
            break
        task = np.linalg.pinv(J) @ e
        active = low | high
        rows = list(Minv[active])
        errs = list(np.where(low, robot.rack_min - L, robot.rack_max - L)[active])
        for i in np.flatnonzero(bent):
            row = np.zeros(3 * n)
            row[3 * i:3 * i + 2] = b[i] / size[i]
            rows.append(row)
            errs.append(robot.bend_max - size[i])
        if rows:
            Jset, eset = np.array(rows), np.array(errs)
            Jset_pinv = np.linalg.pinv(Jset)
            rate = Jset_pinv @ eset + (np.eye(3 * n) - Jset_pinv @ Jset) @ task
        else:
            rate = task
        delta = delta + h * rate
    L = dk.limit_rack_lengths(robot, (Minv @ (delta + offset)).reshape(n, 3))
    return L, steps


def slsqp(robot, target) -> np.ndarray:
    n = robot.n_segments
    M = dk.rack_matrix(robot.phi)

    def f(flat):
        p, J = dk.chain_tip_and_jacobian(
            dk.delta_from_actuators(flat.reshape(n, 3), robot.phi, robot.L0), robot.L0, robot.d)
        e = target - p
        JL = (J.reshape(3, n, 3) @ M).reshape(3, 3 * n)
        return 0.5 * e @ e, -JL.T @ e

    def slack(flat):  # >= 0: bending within the limit, per segment
        b = flat.reshape(n, 3) @ M[:2].T
        return robot.bend_max ** 2 - (b ** 2).sum(axis=1)

    res = minimize(f, np.full(3 * n, robot.rack_min), jac=True, method="SLSQP",
                   bounds=[(robot.rack_min, robot.rack_max)] * (3 * n),
                   constraints=[{"type": "ineq", "fun": slack}],
                   options={"ftol": 1e-14, "maxiter": 500})
    return dk.limit_rack_lengths(robot, res.x.reshape(n, 3))


def run(name: str, targets: np.ndarray, solve: Callable[[int, np.ndarray], object], robot):
    """Time ``solve`` per target; it returns rack lengths (n, 3) or a TipIKResult."""
    times, errors, iters, seeded = [], [], [], []
    for i, target in enumerate(targets):
        t0 = time.perf_counter()
        out = solve(i, target)
        times.append(time.perf_counter() - t0)
        lengths = getattr(out, "lengths", out)
        if hasattr(out, "iterations"):
            iters.append(out.iterations)
            seeded.append(out.starts > 1)
        assert np.all(lengths >= robot.rack_min) and np.all(lengths <= robot.rack_max), name
        delta = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
        assert np.all(dk.bend_angles(delta, robot.d) <= robot.theta_max), name
        tip = dk.tip_position(robot, delta)
        errors.append(np.linalg.norm(target - tip))
    ms, errors = 1e3 * np.array(times), np.array(errors)
    ok = errors <= TOL
    extra = (f" {np.median(iters):>6.0f} {100 * np.mean(np.array(iters) == 0):>7.0f} %"
             f" {100 * np.mean(seeded):>7.0f} %") if iters else ""
    print(f"{name:<28} {len(targets):>5} {np.median(ms):>9.2f} {np.percentile(ms, 90):>8.2f} "
          f"{ms.max():>8.1f} {100 * ok.mean():>8.1f} % {np.median(errors) * 1e3:>10.4f}{extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--targets", type=int, default=200)
    ap.add_argument("--baseline-targets", type=int, default=50)
    ap.add_argument("--euler-step", type=float, default=0.1)
    ap.add_argument("--euler-max-steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=2020)
    args = ap.parse_args()

    robot = robots.load("extensible")
    rng = np.random.default_rng(args.seed)
    lengths = np.zeros((0, robot.n_segments, 3))
    while len(lengths) < args.targets:  # rejection sampling within the bending limit
        draw = rng.uniform(robot.rack_min, robot.rack_max, (20 * args.targets, robot.n_segments, 3))
        theta = dk.bend_angles(dk.delta_from_actuators(draw, robot.phi, robot.L0), robot.d)
        lengths = np.concatenate([lengths, draw[(theta <= robot.theta_max).all(axis=1)]])
    lengths = lengths[:args.targets]
    deltas = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
    targets = dk.tip_position(robot, deltas)
    near = np.clip(lengths + rng.uniform(-0.01, 0.01, lengths.shape), robot.rack_min, robot.rack_max)
    near_deltas = dk.delta_from_actuators(near, robot.phi, robot.L0)
    retracted = np.zeros((robot.n_segments, 3))
    solve_tip_ik(robot, targets[0])  # warm up imports / caches
    nb = min(args.baseline_targets, args.targets)

    print(f"extensible arm, {robot.n_segments} segments; reachable targets from random rack lengths "
          f"in [{robot.rack_min}, {robot.rack_max}] m with every bend <= "
          f"{np.degrees(robot.theta_max):.0f} deg; success = error <= {TOL * 1e3:g} mm")
    print(f"{'method':<28} {'n':>5} {'median ms':>9} {'p90 ms':>8} {'max ms':>8} {'success':>10} "
          f"{'median err mm':>13} {'iters':>6} {'0 iters':>9} {'batch':>9}")
    run("solve_tip_ik cold", targets, lambda i, t: solve_tip_ik(robot, t), robot)
    run("solve_tip_ik warm (1 cm)", targets,
        lambda i, t: solve_tip_ik(robot, t, near_deltas[i]), robot)
    run("solve_tip_ik retracted", targets,
        lambda i, t: solve_tip_ik(robot, t, retracted), robot)
    run(f"eq.(5) Euler h={args.euler_step:g}", targets[:nb],
        lambda i, t: literal_eq5(robot, t, args.euler_step, args.euler_max_steps)[0], robot)
    run("SLSQP (L, bend constr.)", targets[:nb], lambda i, t: slsqp(robot, t), robot)
    run(f"(ours retracted, first {nb})", targets[:nb],
        lambda i, t: solve_tip_ik(robot, t, retracted), robot)


if __name__ == "__main__":
    main()
