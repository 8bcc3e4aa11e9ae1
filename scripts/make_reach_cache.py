"""Regenerate the shipped reachability map of the default soft arm, so a fresh console says "from cache".

``python scripts/make_reach_cache.py [--robot soft-arm] [--check]`` computes the map the console
asks for at start (the table rectangle of ``ConsoleApp.table_rectangle``, the robot's nominal
object radius, ``console.core.reach_job.REACH_STEP`` and ``DEFAULT_LEVELS``), writes it to
``data/reach_cache/`` under its key and removes the other files there. Run it after a change to
the robot file, the planner or :data:`core.planning.reachability.ALGORITHM_VERSION`. With
``--check`` it only says whether the shipped file is a hit (exit 1 if not).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from console.core.reach_job import REACH_STEP, SHIPPED_CACHE, ReachCache, ReachRequest  # noqa: E402
from core import robots  # noqa: E402
from core.planning.reachability import DEFAULT_LEVELS, reachability_map  # noqa: E402


def console_request(robot: robots.SoftArm) -> ReachRequest:
    """The request the console makes at start for ``robot`` (see ``ConsoleApp.table_rectangle``:
    span = straight arm plus gripper; the table from -span to span across, -0.4 span to
    1.15 span along the base heading)."""
    span = robot.n_segments * robot.segment_length + robot.gripper.length
    return ReachRequest(Path(robot.source), robot.capture.nominal_object_radius,
                        (-1.0 * span, 1.0 * span), (-0.4 * span, 1.15 * span), REACH_STEP,
                        DEFAULT_LEVELS)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--check", action="store_true", help="only check the shipped file")
    a = ap.parse_args(argv)
    robot = robots.load(a.robot)
    request = console_request(robot)
    cache = ReachCache(SHIPPED_CACHE)
    if a.check:
        hit = cache.load(request) is not None
        print(f"{cache.file(request.key())}: {'hit' if hit else 'MISSING'}")
        return 0 if hit else 1
    t0 = time.perf_counter()
    reach = reachability_map(robot, request.radius, request.x_range, request.y_range,
                             request.step, levels=request.levels)
    path = cache.save(request, reach)
    if path is None:
        print("could not write the cache file", file=sys.stderr)
        return 1
    for old in SHIPPED_CACHE.glob("reach-*.json"):
        if old != path:
            old.unlink()
    print(f"wrote {path} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
