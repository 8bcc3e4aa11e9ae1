"""Planar obstacle planner on blocked spots: the planner without the grasp-shape search
(before), with it (after, core.planning.grasp_shapes) and a slow oracle (obstacle_oracle.py),
in the same run.

A blocked spot is an object in the left quadrant (a fixed grid, 33 mm diameter, arm straight)
with a 15 mm obstacle between the straight arm and the object (on the segment from the point
of the straight arm level with the object to the object, at a fixed set of fractions), such
that the plain plan (Algorithm 1 without obstacles) comes closer than the 10 mm clearance to
it, while the object itself and the straight arm keep clear of it. For each spot both planners
run on the same request (core.planning.obstacle_planning.plan_around with shape_search False
and True; the oracle with budgets no user waits for); a plan counts as a success only when checked independently by dense sampling of the
forward kinematics (arm body and gripper >= the clearance along every straight line in kappa).
Prints per planner: successes, median, p90 and max time (CPU s of the planning thread), the
oracle's verdicts (planned / clear grasp shapes but none reached / no clear final approach / no
clear grasp shape sampled), the spots the oracle plans that the planner refuses, and the
refusal reasons after.

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
from obstacle_oracle import oracle  # noqa: E402

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


def run(arm, planner, spots, shape_search: bool) -> tuple[list[bool], list[float], list[str]]:
    ok, times, why = [], [], []
    for center, o in spots:
        t0 = time.thread_time()
        reason = ""
        try:
            plan = plan_around(planner, np.zeros(arm.n_segments), center, R_OBJECT, None, None,
                               (o,), CLEARANCE, shape_search=shape_search)
            good = plan.success and path_gap(arm, plan, o) >= CLEARANCE - 1e-9
        except GraspRefused as exc:
            good, reason = False, str(exc).split(": ", 1)[-1].split(" (")[0]
        times.append(time.thread_time() - t0)
        ok.append(good)
        why.append(reason)
    return ok, times, why


def run_oracle(arm, planner, spots, quick: bool) -> tuple[list[bool], list[float], list[str]]:
    ok, times, verdicts = [], [], []
    for center, o in spots:
        ans = oracle(planner, np.zeros(arm.n_segments), center, R_OBJECT, (o,), CLEARANCE,
                     quick)
        good = ans.plan is not None and path_gap(arm, ans.plan, o) >= CLEARANCE - 1e-9
        ok.append(good)
        times.append(ans.seconds)
        verdicts.append(ans.verdict if good or ans.plan is None else "planned, check failed")
    return ok, times, verdicts


def _spots(spots, idx) -> str:
    return ", ".join(f"object ({spots[i][0][0] * 1e3:.0f}, {spots[i][0][1] * 1e3:.0f}) obstacle "
                     f"({spots[i][1].x * 1e3:.0f}, {spots[i][1].y * 1e3:.0f})" for i in idx)


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
    orc = run_oracle(arm, planner, spots, args.quick)
    print(f"{'planner':<30}{'planned':>10}{'median s':>10}{'p90 s':>9}{'max s':>9}"
          f"{'refusal median s':>18}")
    for name, (ok, t, _) in (("before: main's planner", before),
                             ("after: + grasp-shape search", after),
                             ("oracle (slow, offline)", orc)):
        refused = [x for x, good in zip(t, ok) if not good]
        print(f"{name:<30}{sum(ok):>5} / {len(ok):<3}{np.median(t):>10.2f}"
              f"{np.percentile(t, 90):>9.2f}{max(t):>9.2f}"
              f"{np.median(refused) if refused else float('nan'):>18.2f}")
    verdicts = orc[2]
    print("oracle verdicts: " + ", ".join(f"{v} {verdicts.count(v)}"
                                          for v in dict.fromkeys(verdicts)))
    n = range(len(spots))
    for label, idx in (
            ("only after (not before)", [i for i in n if after[0][i] and not before[0][i]]),
            ("only before (not after)", [i for i in n if before[0][i] and not after[0][i]]),
            ("oracle plans, after refuses", [i for i in n if orc[0][i] and not after[0][i]]),
            ("after plans, oracle does not", [i for i in n if after[0][i] and not orc[0][i]])):
        if idx:
            print(f"{label}: {_spots(spots, idx)}")
    reasons = [r for r in after[2] if r]
    for r in dict.fromkeys(reasons):
        print(f"after refused {reasons.count(r)}x: {r}")


if __name__ == "__main__":
    main()
