"""Design-study throughput: variants per minute serially, in a local process pool and on a local Ray.

``python benchmarks/bench_study.py [--robot extensible] [--variants 8] [--workers 2] [--no-ray]``

Runs the same study (``--variants`` values of ``segments.rack_max`` on the extensible arm, or of
``segments.length`` on the soft arm; the shipped metrics, small grids) three times into fresh
directories: in this process (the baseline), through a spawn pool of ``--workers`` processes and
through ``ray.util.multiprocessing.Pool`` on a local Ray of ``--workers`` CPUs (Ray's start-up
is timed separately and included in its figure), checks that the three tables are identical and
prints variants/minute beside the serial baseline. Ray comes with the ``study`` extra.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from core.study import StudySpec, run_study  # noqa: E402
from core.study.__main__ import variant_map  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robot", default="extensible", choices=["extensible", "soft-arm"])
    ap.add_argument("--variants", type=int, default=8)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--no-ray", action="store_true")
    a = ap.parse_args()
    if a.robot == "extensible":
        lo, hi, key = 0.25, 0.45, "segments.rack_max"
        spec = StudySpec(objects=0, ik_grid=3, slip_points=2, slip_repeats=3)
    else:
        lo, hi, key = 0.05, 0.07, "segments.length"
        spec = StudySpec(objects=2, seeds=1, reach_step=0.03, capture_spacing=0.02)
    values = [round(lo + (hi - lo) * i / max(a.variants - 1, 1), 4) for i in range(a.variants)]
    vary = {key: values}
    runs: list[tuple[str, int, str | None]] = [("serial (baseline)", 1, None),
                                               (f"process pool, {a.workers}", a.workers, None)]
    if not a.no_ray:
        if importlib.util.find_spec("ray") is None:
            print("ray is not installed (pip install '.[study]'): no Ray figure")
        else:
            runs.append((f"local Ray, {a.workers} CPUs", a.workers, "local"))
    print(f"{a.robot}: {a.variants} variants of {key} in [{lo}, {hi}], {spec}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    print(f"{'run':<24} {'start s':>8} {'run s':>8} {'variants/min':>13} {'x serial':>9}")
    tables = []
    base = None
    with tempfile.TemporaryDirectory() as tmp:
        for label, jobs, ray in runs:
            t0 = time.perf_counter()
            with variant_map(jobs, ray) as map_fn:
                t1 = time.perf_counter()
                rows = run_study(a.robot, vary, Path(tmp) / label.split()[0], spec,
                                 map_fn=map_fn, plots=False)
                t2 = time.perf_counter()
            wall = t2 - t0
            rate = 60.0 * a.variants / wall
            base = base or rate
            tables.append(rows)
            print(f"{label:<24} {t1 - t0:>8.2f} {t2 - t1:>8.2f} {rate:>13.1f} {rate / base:>9.2f}")
    same = all(t == tables[0] for t in tables)
    print(f"identical tables: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
