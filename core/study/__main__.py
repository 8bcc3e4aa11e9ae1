"""``python -m core.study``: sweep robot-file variants and tabulate their metrics (issue 30).

``python -m core.study --robot NAME|PATH --vary SECTION.KEY=V1,V2,... [--vary ...] --out DIR
[--objects N] [--seeds S] [--jobs J]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from core.robot_schema import RobotFileError
from core.study import METRICS, StudySpec, best, parse_vary, run_study, variants


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry; returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m core.study", description=__doc__)
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--vary", action="append", default=[], required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--objects", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    try:
        if a.objects < 0 or a.seeds < 1:
            raise ValueError("--objects must be >= 0 and --seeds >= 1")
        vary = parse_vary(a.vary)
        variants(a.robot, vary)  # bad key / value -> one line before any work
    except (ValueError, RobotFileError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    def bar(done: int, total: int) -> None:
        n = 30 * done // max(total, 1)
        print(f"\r[{'#' * n}{'.' * (30 - n)}] {done}/{total} variants", end="",
              file=sys.stderr, flush=True)

    spec = StudySpec(objects=a.objects, seeds=a.seeds)
    if a.jobs <= 1:
        rows = run_study(a.robot, vary, a.out, spec, progress=bar)
    else:
        import concurrent.futures as cf
        import multiprocessing as mp
        with cf.ProcessPoolExecutor(a.jobs, mp_context=mp.get_context("spawn")) as pool:
            rows = run_study(a.robot, vary, a.out, spec, map_fn=pool.map, progress=bar)
    print(file=sys.stderr)
    for r in rows:
        vals = "  ".join(f"{m}={r[m]:.4g}" for m in METRICS if m in r)
        print(f"{r['variant']}: {vals}  {r['error']}")
    for m, name in best(rows).items():
        print(f"best {m}: {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
