"""Real-time 100 Hz control loop: period error, overruns and tick work, against baselines.

``python benchmarks/bench_control_loop.py [--seconds 30] [--scenarios ours,naive,gil,process]``

Every scenario runs the full stack (mocap fit, grasp-and-place state machine, trajGen,
curvature controller) on the in-process simulated arm (its physics counts as ``read``) while
grasp-and-place tasks run back to back over the paper's spots A-E, planning in a worker
process (:class:`hw_bridge.planner_process.ProcessPlanner`). Scenarios, each for ``--seconds``:

* ``ours``    - :class:`hw_bridge.loop.LoopRunner` thread: absolute deadlines, sleep + spin,
  overruns skipped;
* ``naive``   - baseline: the same tick then ``time.sleep(0.01)`` (relative, drifts);
* ``gil``     - ours while a CPU-bound *thread* runs in the same process (why heavy work must
  not share the loop's interpreter);
* ``process`` - ours while the same CPU-bound work runs in *another process*;
* ``ours-rt`` - ours with the loop thread under ``SCHED_FIFO`` (priority 50), so other
  processes on the machine cannot delay it (needs the permission; reported).

Goal (issue 3): p99 period error <= 1 ms, zero overruns over 10 minutes (``--seconds 600``),
tick work <= 1 ms p99. The machine has 2 cores; other load on it shows in the figures.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from core import robots  # noqa: E402
from core.control.sim import SoftArmSim  # noqa: E402
from core.control.stack import ControlStack  # noqa: E402
from core.control.trials import paper_locations  # noqa: E402
from hw_bridge.loop import LoopRunner  # noqa: E402
from hw_bridge.loop_devices import SimDevice  # noqa: E402
from hw_bridge.planner_process import ProcessPlanner  # noqa: E402

PERIOD = 0.01


def burn(stop: threading.Event | None = None, seconds: float = 1e9) -> None:
    """Pure-Python CPU work (holds the GIL)."""
    end = time.monotonic() + seconds
    while (stop is None or not stop.is_set()) and time.monotonic() < end:
        sum(i * i for i in range(20000))


def build(arm, planner):
    sim = SoftArmSim(arm, seed=0)
    stack = ControlStack(arm, PERIOD, planner)
    return sim, stack


def task_feeder(runner, sim, arm, stop: threading.Event) -> threading.Thread:
    """Restarts grasp-and-place at the next spot whenever the last one ended (GUI-like thread)."""
    spots = list(paper_locations().values())
    r0 = arm.capture.nominal_object_radius
    state = {"i": 0, "done": 0}

    def begin(s, t):
        x, y = spots[state["i"] % len(spots)]
        state["i"] += 1
        sim.place_object(x, y, r0)
        s.start(t)

    def run():
        runner.submit(begin).result()
        while not stop.is_set():
            time.sleep(0.05)
            c = runner.snapshot.control
            if c is not None and c.phase in ("released", "stopped"):
                state["done"] += 1
                runner.goto(np.zeros(6)).result()
                time.sleep(1.0)
                runner.submit(begin).result()

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.state = state  # type: ignore[attr-defined]
    return th


def run_ours(arm, planner, seconds: float, hog: str | None, rt: int | None = None) -> dict:
    sim, stack = build(arm, planner)
    runner = LoopRunner(SimDevice(sim), stack, PERIOD)
    stop = threading.Event()
    hog_obj = None
    if hog == "thread":
        hog_obj = threading.Thread(target=burn, args=(stop,), daemon=True)
        hog_obj.start()
    elif hog == "process":
        hog_obj = multiprocessing.get_context("spawn").Process(target=burn, args=(None, seconds + 5))
        hog_obj.start()
    runner.start(sched_priority=rt)
    runner.arm().result()
    feeder = task_feeder(runner, sim, arm, stop)
    time.sleep(seconds)
    stop.set()
    runner.stop()
    if rt:
        print(f"  ours-rt scheduling: {runner.scheduling}")
    if hog == "process":
        hog_obj.terminate()
    st = runner.stats()
    return {"ticks": st.ticks, "overruns": st.overruns, "p50": st.period_error_ms_p50,
            "p99": st.period_error_ms_p99, "max": st.period_error_ms_max,
            "work_p50": st.work_ms_p50, "work_p99": st.work_ms_p99, "read_p99": st.read_ms_p99,
            "update_p99": st.update_ms_p99, "tasks": feeder.state["done"],  # type: ignore
            "drift_ms": float("nan")}


def run_naive(arm, planner, seconds: float) -> dict:
    """Baseline: tick, then sleep(period) - relative timing, no deadlines."""
    sim, stack = build(arm, planner)
    runner = LoopRunner(SimDevice(sim), stack, PERIOD)
    stop = threading.Event()
    starts: list[int] = []

    def loop():
        while not stop.is_set():
            starts.append(time.perf_counter_ns())
            runner.tick()
            time.sleep(PERIOD)

    th = threading.Thread(target=loop, daemon=True)
    th.start()
    runner.arm().result()
    feeder = task_feeder(runner, sim, arm, stop)
    time.sleep(seconds)
    stop.set()
    th.join()
    s = np.array(starts, dtype=np.int64)
    err = np.abs(np.diff(s) / 1e6 - PERIOD * 1e3)
    st = runner.stats()
    drift = (s[-1] - s[0]) / 1e6 - (len(s) - 1) * PERIOD * 1e3
    return {"ticks": len(s), "overruns": int(np.sum(err > PERIOD * 1e3)), "p50": float(np.percentile(err, 50)),
            "p99": float(np.percentile(err, 99)), "max": float(err.max()), "work_p50": st.work_ms_p50,
            "work_p99": st.work_ms_p99, "read_p99": st.read_ms_p99, "update_p99": st.update_ms_p99,
            "tasks": feeder.state["done"], "drift_ms": drift}  # type: ignore


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--scenarios", default="ours,ours-rt,naive,gil,process")
    a = ap.parse_args()
    arm = robots.load("soft-arm")
    planner = ProcessPlanner(arm.source)
    print(f"100 Hz loop, {a.seconds:g} s per scenario, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f} at start")
    rows = []
    for name in a.scenarios.split(","):
        if name == "ours":
            r = run_ours(arm, planner, a.seconds, None)
        elif name == "naive":
            r = run_naive(arm, planner, a.seconds)
        elif name == "gil":
            r = run_ours(arm, planner, a.seconds, "thread")
        elif name == "process":
            r = run_ours(arm, planner, a.seconds, "process")
        elif name == "ours-rt":
            r = run_ours(arm, planner, a.seconds, None, rt=50)
        else:
            ap.error(f"unknown scenario {name!r}")
        rows.append((name, r))
    planner.close()
    hdr = (f"{'scenario':<9} {'ticks':>6} {'overruns':>8} {'err p50':>8} {'err p99':>8} {'err max':>8} "
           f"{'work p50':>8} {'work p99':>8} {'read p99':>8} {'upd p99':>8} {'drift':>8} {'tasks':>5}")
    print(hdr)
    print(" " * 34 + "(period error and work in ms; drift = elapsed - ticks x 10 ms)")
    for name, r in rows:
        print(f"{name:<9} {r['ticks']:>6d} {r['overruns']:>8d} {r['p50']:>8.3f} {r['p99']:>8.3f} "
              f"{r['max']:>8.3f} {r['work_p50']:>8.3f} {r['work_p99']:>8.3f} {r['read_p99']:>8.3f} "
              f"{r['update_p99']:>8.3f} {r['drift_ms']:>8.1f} {r['tasks']:>5d}")
    print(f"load average {os.getloadavg()[0]:.2f} at end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
