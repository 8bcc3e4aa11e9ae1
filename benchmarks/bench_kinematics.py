"""Batched planar forward-kinematics throughput against the paper's per-segment forwKin.

Prints segment evaluations per second for: the batched numpy FK (one thread, and split over
all cores with a thread pool, since numpy releases the GIL), and, in the same run, the literal
recursive forwKin of Algorithm 1 in Python as the baseline. Goal: >= 10 M segment evals/s.

Usage: python benchmarks/bench_kinematics.py [--batch 200000] [--seconds 2]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from core import robots  # noqa: E402
from core.kinematics import planar  # noqa: E402


def paper_forwkin(kappa, lengths, i, s, base=(0.0, 0.0, math.pi / 2)):
    """Algorithm 1's recursive forwKin(kappa, L, i, s), literally (1-based segment i)."""
    if i == 0:
        return base
    x0, y0, th0 = paper_forwkin(kappa, lengths, i - 1, lengths[i - 2], base) if i > 1 else base
    k = kappa[i - 1]
    th = th0 + k * s
    if k == 0.0:
        return x0 + s * math.cos(th0), y0 + s * math.sin(th0), th
    return x0 + math.sin(th) / k - math.sin(th0) / k, y0 - math.cos(th) / k + math.cos(th0) / k, th


def rate(fn, seconds: float) -> float:
    fn()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=200_000)
    ap.add_argument("--seconds", type=float, default=2.0)
    args = ap.parse_args()
    arm = robots.load("soft-arm")
    lengths = arm.lengths
    n_seg = arm.n_segments
    rng = np.random.default_rng(0)
    kappa = rng.uniform(-arm.kappa_max, arm.kappa_max, (args.batch, n_seg))

    one = rate(lambda: planar.forward_kinematics(kappa, lengths), args.seconds)
    workers = os.cpu_count() or 1
    chunks = np.array_split(kappa, workers * 4)
    with ThreadPoolExecutor(workers) as pool:
        many = rate(lambda: list(pool.map(lambda c: planar.forward_kinematics(c, lengths), chunks)),
                    args.seconds)

    small = kappa[:2000]
    lst = [list(map(float, row)) for row in small]
    lens = list(map(float, lengths))
    base = rate(lambda: [paper_forwkin(r, lens, n_seg, lens[-1]) for r in lst], args.seconds)

    # Check the two agree before quoting figures.
    ours = planar.forward_kinematics(small[:50], lengths)[:, -1]
    ref = np.array([paper_forwkin(r, lens, n_seg, lens[-1]) for r in lst[:50]])
    assert np.allclose(ours, ref, atol=1e-12), "batched FK disagrees with the paper's forwKin"

    rows = [
        ("paper forwKin (recursive Python)", base, len(lst)),
        ("batched numpy FK, 1 thread", one, args.batch),
        (f"batched numpy FK, {workers} threads", many, args.batch),
    ]
    print(f"planar FK, {n_seg} segments, batch {args.batch:,}")
    print(f"{'implementation':40s} {'M seg/s':>10s} {'x baseline':>11s}")
    base_rate = len(lst) * n_seg / base
    for name, dt, count in rows:
        r = count * n_seg / dt
        print(f"{name:40s} {r / 1e6:10.2f} {r / base_rate:11.0f}")
    print("goal: >= 10 M segment evaluations/s")


if __name__ == "__main__":
    main()
