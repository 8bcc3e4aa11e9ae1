"""Trials speed vs real time: simulated seconds per wall second, 1 worker vs all workers.

``python benchmarks/bench_trials.py [--repeats 2] [--seed 0]``

Runs the paper's experiment (spots A-E x repeats) headless on the simulated clock (core.control.sim_loop), once with one process and once with
``--workers`` processes, and prints the
speed-up over real time (the baseline: a real-time run takes exactly the simulated time, 1x)
next to the per-tick cost. Goal (issue 3): >= 20x real time.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from core import robots  # noqa: E402
from core.control.trials import paper_locations, run_trials, summary  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    a = ap.parse_args()
    arm = robots.load("soft-arm")
    r0 = arm.capture.nominal_object_radius
    objects = [(k, (x, y, r0)) for k, (x, y) in paper_locations().items()]
    print(f"paper experiment, {len(objects)} spots x {a.repeats} repeats, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'run':<22} {'trials':>6} {'ok':>4} {'sim s':>8} {'wall s':>7} {'x real time':>11} "
          f"{'us / tick':>9}")
    print(f"{'real time (baseline)':<22} {'':>6} {'':>4} {'':>8} {'':>7} {1.0:>11.1f} {'':>9}")
    for workers in sorted({1, a.workers}):
        wall = time.perf_counter()
        with cf.ProcessPoolExecutor(workers) as pool:
            res = run_trials("soft-arm", objects, a.repeats, a.seed, map_fn=pool.map)
        s = summary(res, time.perf_counter() - wall, workers)
        per_tick = 1e6 * sum(r.wall_s for r in res) / max(1, s["ticks"])
        print(f"{f'sim clock, {workers} worker(s)':<22} {s['trials']:>6d} {s['successes']:>4d} "
              f"{s['sim_s']:>8.1f} {s['wall_s']:>7.1f} {s['speedup_vs_real_time']:>11.1f} "
              f"{per_tick:>9.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
