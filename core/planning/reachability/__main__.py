"""``python -m core.planning.reachability``: a reachability map as JSON on stdout.

``python -m core.planning.reachability --robot soft-arm --radius 0.0165 [--x LO HI] [--y LO HI]
[--step S] [--nice N] [--parent PID]``: the console runs it in a low-priority child process
(:func:`core.planning.reachability.reachability_map`, :func:`core.planning.reachability.to_json`);
with ``--parent`` it stops (exit 3) as soon as that process is gone.
"""

from __future__ import annotations

import argparse
import os
import sys

from core.planning.reachability import reachability_map, to_json


def main(argv: list[str] | None = None) -> int:
    """``python -m core.planning.reachability --robot soft-arm --radius 0.0165``: map as JSON."""
    from core import robots

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--radius", type=float, required=True)
    ap.add_argument("--x", type=float, nargs=2, default=(-0.5, 0.5))
    ap.add_argument("--y", type=float, nargs=2, default=(-0.26, 0.5))
    ap.add_argument("--step", type=float, default=0.02)
    ap.add_argument("--nice", type=int, default=0, help="lower this process's priority")
    ap.add_argument("--parent", type=int, default=0,
                    help="stop (exit 3) as soon as the process with this pid is gone")
    args = ap.parse_args(argv)
    if args.nice:
        try:
            os.nice(args.nice)
        except OSError:
            pass
    orphaned = (lambda: os.getppid() != args.parent) if args.parent else None
    reach = reachability_map(robots.load(args.robot), args.radius, tuple(args.x), tuple(args.y),
                             args.step, should_stop=orphaned)
    if orphaned is not None and orphaned():
        return 3
    sys.stdout.write(to_json(reach) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
