"""``python -m core.planning.grasp``: plan one grasp from the command line.

``python -m core.planning.grasp --object X Y R [--json] [--robot soft-arm] [--kappa K ...]
[--delta-d D] [--obstacle X Y R ...] [--other X Y R ...] [--clearance C]`` prints the plan
(:func:`core.planning.sides.plan_grasp_sided`: Algorithm 1, for the right finger when the
gripper has one and the object lies on the right; around the obstacles and the other objects
on the table, if any: each ``--other`` object is an obstacle of its radius, named "Object 2",
"Object 3", ..., :func:`core.planning.obstacles.with_other_objects`); a refusal goes to stderr
with exit code 2 (1 if planning failed).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from core.planning.feasibility import GraspRefused
from core.planning.obstacles import DEFAULT_CLEARANCE, Obstacle, with_other_objects
from core.planning.plan_types import format_plan
from core.planning.sides import plan_grasp_sided


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    from core import robots

    ap = argparse.ArgumentParser(prog="python -m core.planning.grasp", description=__doc__
                                 .split("\n")[0])
    ap.add_argument("--object", nargs=3, type=float, metavar=("X", "Y", "R"), required=True,
                    help="object centre x, y and radius r_o (m)")
    ap.add_argument("--robot", default="soft-arm", help="robot name or TOML path")
    ap.add_argument("--kappa", nargs="+", type=float, help="measured curvatures (default 0)")
    ap.add_argument("--delta-d", type=float, help="allowable incremental distance (m)")
    ap.add_argument("--obstacle", nargs=3, type=float, action="append", default=[],
                    metavar=("X", "Y", "R"), help="an obstacle disk (m; repeat for more): the "
                    "arm and gripper keep --clearance from it")
    ap.add_argument("--other", nargs=3, type=float, action="append", default=[],
                    metavar=("X", "Y", "R"), help="another object on the table (m; repeat for "
                    "more): an obstacle of its radius, kept --clearance from like one")
    ap.add_argument("--clearance", type=float, default=DEFAULT_CLEARANCE,
                    help="clearance from obstacles and other objects (m, default "
                         f"{DEFAULT_CLEARANCE:g})")
    ap.add_argument("--json", action="store_true", help="print the plan as JSON")
    args = ap.parse_args(argv)
    try:
        robot = robots.load(args.robot)
        km = np.zeros(robot.n_segments) if args.kappa is None else np.array(args.kappa)
        if not isinstance(robot, robots.SoftArm):
            ap.error(f"{args.robot} is not a soft planar arm")
        obstacles = with_other_objects(
            [Obstacle(f"Obstacle {i + 1}", *o) for i, o in enumerate(args.obstacle)],
            [Obstacle(f"Object {i + 2}", *o) for i, o in enumerate(args.other)])
        plan = plan_grasp_sided(robot, km, args.object[:2], args.object[2],
                                delta_d=args.delta_d, obstacles=obstacles,
                                clearance=args.clearance)
    except GraspRefused as exc:
        print(f"refused ({exc.reason}): {exc}", file=sys.stderr)
        return 2
    print(json.dumps(plan.to_dict(), indent=1) if args.json else format_plan(plan))
    if not plan.success:
        print(f"planning failed: {plan.summary()}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
