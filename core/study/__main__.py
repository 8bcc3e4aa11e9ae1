"""``python -m core.study``: sweep robot-file variants and tabulate their metrics (issue 30).

``python -m core.study --robot NAME|PATH --vary SECTION.KEY=V1,V2,... [--vary ...] --out DIR
[--objects N] [--seeds S] [--jobs J] [--ray ADDRESS|local] [--ik-grid K] [--slip-points P]
[--slip-repeats R]``

The variants run in this process (``--jobs 1``), in a local process pool (``--jobs J``,
``multiprocessing`` spawn) or on Ray (``--ray ADDRESS``; ``--ray local`` starts a local Ray on
``max(J, 2)`` CPUs) through Ray's own ``ray.util.multiprocessing.Pool``: the same jobs, the same
rows. Both pools hand rows back as they complete (``imap_unordered``), so a killed study keeps
every finished variant. Ray and matplotlib come with the ``study`` extra (``pip install
'.[study]'``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import sys
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from core.robot_schema import RobotFileError
from core.study import METRICS, StudySpec, best, parse_vary, run_study, variants

MapFn = Callable[..., Any]


@contextlib.contextmanager
def variant_map(jobs: int, ray: str | None = None) -> Iterator[MapFn]:
    """The ``map_fn`` that runs the variants: builtin ``map`` (``jobs <= 1``, no Ray), a local
    spawn pool's ``imap_unordered``, or Ray's ``Pool.imap_unordered`` (``ray`` an address, or
    ``"local"``: ``ray.init(num_cpus=max(jobs, 2))``). Shuts the pool (and a Ray it started) down.

    Raises:
        ImportError: ``ray`` is given and Ray is not installed.
    """
    if ray is None and jobs <= 1:
        yield map
        return
    if ray is None:
        import multiprocessing as mp
        with mp.get_context("spawn").Pool(jobs) as pool:
            yield pool.imap_unordered
        return
    import ray as ray_mod
    from ray.util.multiprocessing import Pool as RayPool

    if ray == "local":  # workers import this checkout's modules (and what the driver imports)
        path = [str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")]
        ray_mod.init(num_cpus=max(jobs, 2), include_dashboard=False, log_to_driver=False,
                     runtime_env={"env_vars": {"PYTHONPATH": os.pathsep.join(filter(None, path))}})
    else:  # a cluster whose nodes have this project's environment installed
        ray_mod.init(address=ray, log_to_driver=False)
    try:
        pool = RayPool()
        try:
            yield pool.imap_unordered
        finally:
            pool.terminate()
    finally:
        ray_mod.shutdown()


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry; returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m core.study", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--vary", action="append", default=[], required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--objects", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--ray", metavar="ADDRESS|local", default=None,
                    help="run the variants on a Ray cluster (local: start one on this machine)")
    ap.add_argument("--ik-grid", type=int, default=StudySpec.ik_grid,
                    help="extensible arm: tip-IK targets per axis (0: none)")
    ap.add_argument("--slip-points", type=int, default=StudySpec.slip_points,
                    help="extensible arm: targets of the repeatability-under-slip study (0: none)")
    ap.add_argument("--slip-repeats", type=int, default=StudySpec.slip_repeats)
    a = ap.parse_args(argv)
    try:
        if a.objects < 0 or a.seeds < 1:
            raise ValueError("--objects must be >= 0 and --seeds >= 1")
        if a.ik_grid < 0 or a.slip_points < 0 or a.slip_repeats < 1:
            raise ValueError("--ik-grid and --slip-points must be >= 0 and --slip-repeats >= 1")
        if a.ray is not None and importlib.util.find_spec("ray") is None:
            raise ValueError("--ray needs Ray: pip install '.[study]'")
        vary = parse_vary(a.vary)
        variants(a.robot, vary)  # bad key / value -> one line before any work
    except (ValueError, RobotFileError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    plots = importlib.util.find_spec("matplotlib") is not None
    if not plots:
        print("note: no PNG plots: matplotlib is not installed (pip install '.[study]')",
              file=sys.stderr)

    def bar(done: int, total: int) -> None:
        n = 30 * done // max(total, 1)
        print(f"\r[{'#' * n}{'.' * (30 - n)}] {done}/{total} variants", end="",
              file=sys.stderr, flush=True)

    spec = StudySpec(objects=a.objects, seeds=a.seeds, ik_grid=a.ik_grid,
                     slip_points=a.slip_points, slip_repeats=a.slip_repeats)
    with variant_map(a.jobs, a.ray) as map_fn:
        rows = run_study(a.robot, vary, a.out, spec, map_fn=map_fn, progress=bar, plots=plots)
    print(file=sys.stderr)
    for r in rows:
        vals = "  ".join(f"{m}={r[m]:.4g}" for m in METRICS if m in r)
        print(f"{r['variant']}: {vals}  {r['error']}")
    for m, name in best(rows).items():
        print(f"best {m}: {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
