"""``python -m core.planning.reachability``: a reachability map as JSON on stdout.

``python -m core.planning.reachability --robot soft-arm --radius 0.0165 [--x LO HI] [--y LO HI]
[--step S] [--levels L] [--nice N] [--parent PID] [--progress]``: the console runs it in a
low-priority child process (:func:`core.planning.reachability.reachability_map`,
:func:`core.planning.reachability.to_json`); with ``--parent`` it stops (exit 3) as soon as that
process is gone; with ``--progress`` it writes ``progress F`` lines (F from 0 to 1, at most one
per percent) to stderr while it computes.
"""

from __future__ import annotations

import argparse
import os
import sys

from core.planning.reachability import DEFAULT_LEVELS, reachability_map, to_json


def main(argv: list[str] | None = None) -> int:
    """``python -m core.planning.reachability --robot soft-arm --radius 0.0165``: map as JSON."""
    from core import robots

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--radius", type=float, required=True)
    ap.add_argument("--x", type=float, nargs=2, default=(-0.5, 0.5))
    ap.add_argument("--y", type=float, nargs=2, default=(-0.26, 0.5))
    ap.add_argument("--step", type=float, default=0.02)
    ap.add_argument("--levels", type=int, default=DEFAULT_LEVELS,
                    help="coarse-to-fine levels (0 plans every cell)")
    ap.add_argument("--progress", action="store_true",
                    help="write 'progress F' lines to stderr while computing")
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
    shown = [-1]

    def report(fraction: float) -> None:
        percent = int(100 * fraction)
        if percent != shown[0]:
            shown[0] = percent
            sys.stderr.write(f"progress {fraction:.3f}\n")
            sys.stderr.flush()

    reach = reachability_map(robots.load(args.robot), args.radius, tuple(args.x), tuple(args.y),
                             args.step, levels=args.levels, should_stop=orphaned,
                             progress=report if args.progress else None)
    if orphaned is not None and orphaned():
        return 3
    sys.stdout.write(to_json(reach) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
