"""What this machine gives a 100 Hz real-time loop: the baseline the console's loop is held to.

A reference sleeper is the smallest possible loop: one thread, no GIL to share, no work, at the
console loop's ``SCHED_FIFO`` priority on the same CPU (:mod:`hw_bridge.cpu_partition`),
sleeping to absolute 10 ms deadlines like :class:`hw_bridge.loop.LoopRunner`. Its wake-up
lateness is the floor for the console loop's period error: what the kernel (and, in a virtual
machine, the hypervisor) adds on its own. Benchmarks run it beside the console and print both.

``python benchmarks/rt_reference.py SECONDS [--priority 50] [--cpus 1]`` prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent


def sleep_loop(seconds: float, period_s: float = 0.01) -> dict[str, Any]:
    """Sleep to ``t0 + k period`` for ``seconds``; lateness percentiles (ms) and misses."""
    import numpy as np  # (imported by main() before it turns real-time)
    period = round(period_s * 1e9)
    clock = time.perf_counter_ns
    t0 = clock()
    n = int(seconds / period_s)
    late = np.empty(n)
    k = 0
    try:
        for k in range(1, n + 1):
            deadline = t0 + k * period
            remaining = deadline - clock()
            if remaining > 0:
                time.sleep(remaining / 1e9)
            late[k - 1] = (clock() - deadline) / 1e6
    except KeyboardInterrupt:  # ReferenceSleeper.stop(): report what was measured
        n = max(1, k - 1)
        late = late[:n]
    return {"ticks": n, "p50_ms": float(np.percentile(late, 50)),
            "p99_ms": float(np.percentile(late, 99)), "max_ms": float(late.max()),
            "over_1ms": int((late > 1.0).sum()), "missed": int((late > period_s * 1e3).sum())}


class ReferenceSleeper:
    """A :func:`sleep_loop` in its own process for ``seconds``; :meth:`result` waits for it."""

    def __init__(self, seconds: float, priority: int | None, cpus: frozenset[int] | None):
        cmd = [sys.executable, __file__, str(seconds)]
        if priority:
            cmd += ["--priority", str(priority)]
        if cpus:
            from hw_bridge.cpu_partition import format_cpus
            cmd += ["--cpus", format_cpus(cpus)]
        self.proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, text=True)

    def stop(self) -> dict[str, Any] | None:
        """End it now (SIGINT); the figures of the time it ran."""
        import signal
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.result(10.0)

    def result(self, timeout: float = 60.0) -> dict[str, Any] | None:
        try:
            out, _ = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return None
        lines = [line for line in out.splitlines() if line.startswith("{")]
        return json.loads(lines[-1]) if lines else None


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("seconds", type=float)
    p.add_argument("--priority", type=int, default=0, help="SCHED_FIFO priority (0: ordinary)")
    p.add_argument("--cpus", default="", help="comma-separated CPUs to run on")
    a = p.parse_args()
    sys.path.insert(0, str(REPO))
    import numpy  # noqa: F401 - import before turning real-time: an import at the loop's
    # priority on its CPU would hold it off for tens of ms (equal FIFO priorities do not preempt)
    from hw_bridge.cpu_partition import parse_cpus, pin_process
    from hw_bridge.realtime import set_fifo
    if a.cpus:
        try:
            pin_process(parse_cpus(a.cpus))
        except ValueError as exc:
            p.error(f"--cpus: {exc}")
    scheduling = set_fifo(a.priority) if a.priority else "default (SCHED_OTHER)"
    out = sleep_loop(a.seconds)
    out["scheduling"] = scheduling
    out["cpus"] = sorted(os.sched_getaffinity(0))
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
