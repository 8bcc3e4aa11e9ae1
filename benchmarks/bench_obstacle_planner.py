"""Planar obstacle planner on blocked spots: the local search alone (before) against the local
search plus the long way round (after, core.planning.global_approach), in the same run.

A blocked spot is an object in the left quadrant (a fixed grid, 33 mm diameter, arm straight)
with a 15 mm obstacle between the straight arm and the object (on the segment from the point
of the straight arm level with the object to the object, at a fixed set of fractions), such
that the plain plan (Algorithm 1 without obstacles) comes closer than the 10 mm clearance to
it, while the object itself and the straight arm keep clear of it. For each spot both planners
run on the same request (core.planning.obstacle_planning.plan_around with global_search False
and True); a plan counts as a success only when checked independently by dense sampling of the
forward kinematics (arm body and gripper >= the clearance along every straight line in kappa).
Prints per planner: successes, median and p90 plan time (wall clock), the spots only one
planner solved.

    python benchmarks/bench_obstacle_planner.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core import robots  # noqa: E402
from core.kinematics import planar  # noqa: E402
from core.planning.grasp import GraspPlanner, GraspRefused, Obstacle  # noqa: E402
from core.planning.obstacle_planning import SEARCH_BUDGET_S, plan_around  # noqa: E402

R_OBJECT = 0.0165
R_OBSTACLE = 0.015
CLEARANCE = 0.010


def dense_gap(arm, kappas: np.ndarray, o: Obstacle) -> np.ndarray:
    """Arm (backbone +- half-width) and straight gripper to the obstacle disk, densely."""
    bb = planar.sample_backbone(kappas, arm.lengths, 64, arm.base_pose)
    d_body = np.hypot(bb[..., 0] - o.x, bb[..., 1] - o.y).min(axis=-1)
    tip = bb[..., -1, :]
    s = np.linspace(0.0, arm.gripper.length, 65)
    gx = tip[..., 0:1] + s * np.cos(tip[..., 2:3])
    gy = tip[..., 1:2] + s * np.sin(tip[..., 2:3])
    d_grip = np.hypot(gx - o.x, gy - o.y).min(axis=-1)
    return np.minimum(d_body - arm.half_width, d_grip - arm.gripper.half_width) - o.r


def path_gap(arm, plan, o: Obstacle) -> float:
    chain = np.vstack([plan.kappa_meas, plan.kappas])
    tau = np.linspace(0.0, 1.0, 201)[:, None, None]
    ks = chain[:-1] + tau * (chain[1:] - chain[:-1])
    return float(dense_gap(arm, ks.reshape(-1, chain.shape[1]), o).min())


def blocked_spots(arm, planner: GraspPlanner, quick: bool) -> list[tuple[tuple, Obstacle]]:
    spots = []
    xs = np.arange(-0.28, -0.079, 0.04 if not quick else 0.08)
    ys = np.arange(0.12, 0.361, 0.04 if not quick else 0.08)
    for x in xs:
        for y in ys:
            try:
                plain = planner.plan(np.zeros(arm.n_segments), (x, y), R_OBJECT)
            except GraspRefused:
                continue
            if not plain.success:
                continue
            for f in (0.35, 0.55, 0.75):
                o = Obstacle("Obstacle 1", round(float(x * f), 4), round(float(y), 4),
                             R_OBSTACLE)
                if abs(complex(x, y) - o.center) - o.r - R_OBJECT < 0.005:
                    continue
                if dense_gap(arm, np.zeros((1, arm.n_segments)), o).min() < CLEARANCE:
                    continue        # the straight arm itself is too close: refused up front
                if path_gap(arm, plain, o) < CLEARANCE:
                    spots.append(((float(x), float(y)), o))
    return spots


def run(arm, planner, spots, global_search: bool) -> tuple[list[bool], list[float]]:
    ok, times = [], []
    for center, o in spots:
        t0 = time.perf_counter()
        try:
            plan = plan_around(planner, np.zeros(arm.n_segments), center, R_OBJECT, None, None,
                               (o,), CLEARANCE, global_search=global_search)
            good = plan.success and path_gap(arm, plan, o) >= CLEARANCE - 1e-9
        except GraspRefused:
            good = False
        times.append(time.perf_counter() - t0)
        ok.append(good)
    return ok, times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a coarser grid of spots")
    args = ap.parse_args()
    arm = robots.load("soft-arm")
    planner = GraspPlanner(arm)
    spots = blocked_spots(arm, planner, args.quick)
    print(f"{len(spots)} blocked spots (15 mm obstacle between the straight arm and a 33 mm "
          f"object, clearance 10 mm); search budget {SEARCH_BUDGET_S:g} s")
    before = run(arm, planner, spots, False)
    after = run(arm, planner, spots, True)
    print(f"{'planner':<28}{'planned':>10}{'median s':>10}{'p90 s':>9}{'max s':>9}")
    for name, (ok, t) in (("before: local search", before),
                          ("after: + long way round", after)):
        print(f"{name:<28}{sum(ok):>5} / {len(ok):<3}{np.median(t):>10.2f}"
              f"{np.percentile(t, 90):>9.2f}{max(t):>9.2f}")
    for label, a, b in (("only after", after[0], before[0]), ("only before", before[0],
                                                               after[0])):
        only = [spots[i] for i in range(len(spots)) if a[i] and not b[i]]
        if only:
            print(f"{label}: " + ", ".join(f"object ({c[0] * 1e3:.0f}, {c[1] * 1e3:.0f}) "
                                           f"obstacle ({o.x * 1e3:.0f}, {o.y * 1e3:.0f})"
                                           for c, o in only))


if __name__ == "__main__":
    main()
