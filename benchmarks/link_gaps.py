"""Where the default soft arm's serial link is late: worst gaps per hop, loop to device and back.

The default console runs the soft arm's 100 Hz loop in its own process against the device
emulator on a pty (``serve.py``). This benchmark runs exactly that pair (``ControlProcess``,
``device="emulator"``, the same CPU partition and priorities) without a console or browser, arms
it, moves it between two postures, optionally with CPU hogs beside it, and timestamps every hop:

* **loop**: tick lateness after its deadline, overruns;
* **DEMAND**: host write -> the emulator's pty read -> the device accepting it (its watchdog
  trips after 50 ms without an accepted DEMAND);
* **STATE**: the device making it -> the emulator writing it to the pty -> the host's receive
  thread decoding it (the host calls the link lost after 40 ms without one);
* the emulator's own ticks (interval, plant step) and every link fault.

Timestamps are CLOCK_MONOTONIC in both processes (``time.monotonic`` / ``perf_counter``), so
hops across processes are exact. The tracing is patched in from here (the product code is not
changed for it): the control process's target and the emulator command are wrapped.

``python benchmarks/link_gaps.py [--seconds 60] [--hog N] [--churn N] [--hog-nice 19]
[--rt-cpu auto|none] [--json]``: ``--hog`` N busy loops, ``--churn`` N processes that
allocate, touch and free 64 MB over and over (page faults, munmap: kernel work like a
browser's), both at nice ``--hog-nice`` (0: normal priority), anywhere on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

TRACE_ENV = "LINK_GAPS_DIR"


# -- emulator side (runs inside the emulator process) -------------------------------------------
def emulator_main(argv: list[str]) -> int:
    """``python -m hw_bridge.emulator`` with timestamps of reads, accepts, ticks and writes."""
    from hw_bridge import emulator as cli
    from hw_bridge.pty_emulator import Emulator

    out = os.environ[TRACE_ENV]
    reads: list[float] = []
    accepts: list[tuple[float, int]] = []
    ticks: list[tuple[float, float]] = []
    writes: list[tuple[float, float, int]] = []  # due, written, frame type (COBS byte 1)

    orig_read, orig_deliver, orig_tick = (Emulator._on_readable, Emulator._deliver,
                                          Emulator._tick)
    orig_send_due, orig_run = Emulator._send_due, Emulator.run

    def on_readable(self: Emulator, now: float) -> Any:
        reads.append(now)
        return orig_read(self, now)

    def deliver(self: Emulator, now: float) -> None:
        before = self.core._ack_seq
        orig_deliver(self, now)
        if self.core._ack_seq != before:
            accepts.append((time.monotonic(), self.core._ack_seq))

    def tick(self: Emulator, now: float, *late: float) -> None:
        orig_tick(self, now, *late)
        ticks.append((now, time.monotonic() - now))

    def send_due(self: Emulator, now: float) -> None:
        due = [(d, f[1] if len(f) > 1 else 0) for d, f in self.tx_pending if d <= now]
        orig_send_due(self, now)
        written = time.monotonic()
        writes.extend((d, written, kind) for d, kind in due)

    def run(self: Emulator) -> None:
        try:
            orig_run(self)
        finally:
            np.savez(os.path.join(out, "emu.npz"), t0=self.t0, pid=os.getpid(), reads=np.array(reads),
                     accepts=np.array(accepts).reshape(-1, 2),
                     ticks=np.array(ticks).reshape(-1, 2), writes=np.array(writes).reshape(-1, 3))

    Emulator._on_readable, Emulator._deliver, Emulator._tick = on_readable, deliver, tick
    Emulator._send_due, Emulator.run = send_due, run
    return cli.main(argv)


# -- host side (runs inside the control process) ------------------------------------------------
def traced_child(*args: Any) -> None:
    """The soft arm's control process (``soft_arm_process._child``) with the link traced."""
    from hw_bridge import soft_arm_link, soft_arm_process
    from hw_bridge.interface import SerialHardware
    from hw_bridge.link import Link
    from hw_bridge.loop import LoopRunner

    out = os.environ[TRACE_ENV]
    sends: list[tuple[int, float, float]] = []
    states: list[tuple[float, int, int, int, int]] = []
    ticks: list[tuple[float, ...]] = []  # start, lateness, work, cpu, user, sys, faults, ... (s)
    faults: list[tuple[float, str]] = []
    orig_send, orig_state, orig_tick = Link.send_demand, Link._on_state, LoopRunner.tick
    orig_error = SerialHardware.on_error

    def send_demand(self: Link, counts: Any, mask: int | None = None) -> int:
        t = time.perf_counter()
        seq = orig_send(self, counts, mask)
        sends.append((seq, t, time.perf_counter()))
        return seq

    def on_state(self: Link, m: Any, now: float) -> None:
        states.append((now, m.seq, m.ack_seq, m.mcu_time_us, m.status))
        orig_state(self, m, now)

    def tick(self: LoopRunner) -> None:
        start = time.perf_counter_ns()
        late = 0.0 if self._t0 is None else (start - self._t0 - self._k * self.period_ns) / 1e9
        cpu0, ru0 = time.thread_time(), resource.getrusage(resource.RUSAGE_THREAD)
        orig_tick(self)
        ru1, snap = resource.getrusage(resource.RUSAGE_THREAD), self.snapshot
        ticks.append((start / 1e9, late, time.perf_counter_ns() / 1e9 - start / 1e9,
                      time.thread_time() - cpu0, ru1.ru_utime - ru0.ru_utime,
                      ru1.ru_stime - ru0.ru_stime, ru1.ru_minflt - ru0.ru_minflt,
                      ru1.ru_majflt - ru0.ru_majflt, ru1.ru_nivcsw - ru0.ru_nivcsw,
                      ru1.ru_nvcsw - ru0.ru_nvcsw, snap.read_ms / 1e3, snap.update_ms / 1e3,
                      snap.write_ms / 1e3))

    def on_error(self: SerialHardware, reason: str) -> Any:
        faults.append((time.perf_counter(), reason))
        return orig_error(self, reason)

    gcs: list[tuple[float, float, int, int]] = []  # start, duration, generation, collected
    gc_start: list[float] = [0.0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            gc_start[0] = time.perf_counter()
        else:
            gcs.append((gc_start[0], time.perf_counter() - gc_start[0], info["generation"],
                        info["collected"]))

    import gc
    gc.callbacks.append(on_gc)
    Link.send_demand, Link._on_state, LoopRunner.tick = send_demand, on_state, tick
    SerialHardware.on_error = on_error
    soft_arm_link.EmulatorProcess = _traced_emulator_class()
    try:
        soft_arm_process._child(*args)
    finally:
        np.savez(os.path.join(out, "host.npz"), sends=np.array(sends).reshape(-1, 3),
                 states=np.array(states, dtype=float).reshape(-1, 5),
                 ticks=np.array(ticks).reshape(-1, 13), gcs=np.array(gcs).reshape(-1, 4))
        with open(os.path.join(out, "faults.json"), "w") as f:
            json.dump(faults, f)
        with open(os.path.join(out, "threads.json"), "w") as f:
            json.dump({t.native_id: t.name for t in threading.enumerate()}, f)


def _traced_emulator_class() -> Any:
    from hw_bridge import soft_arm_link

    class Traced(soft_arm_link.EmulatorProcess):
        """EmulatorProcess running this file's :func:`emulator_main`."""

        command = (__file__, "--emulator")

    return Traced


# -- analysis -----------------------------------------------------------------------------------
def _pct(x: np.ndarray) -> dict[str, float | None]:
    x = np.asarray(x, float) * 1000.0
    if x.size == 0:
        return {"n": 0}
    return {"n": int(x.size), "p50": round(float(np.percentile(x, 50)), 3),
            "p99": round(float(np.percentile(x, 99)), 3),
            "p99.9": round(float(np.percentile(x, 99.9)), 3), "max": round(float(x.max()), 3)}


def analyse(trace: Path, skip_s: float = 1.0) -> dict[str, Any]:
    """Worst gaps per hop (ms) from a run's trace directory."""
    emu, host = np.load(trace / "emu.npz"), np.load(trace / "host.npz")
    faults = json.loads((trace / "faults.json").read_text())
    t0 = float(emu["t0"])
    sends, states, lticks = host["sends"], host["states"], host["ticks"]
    start = sends[0, 1] + skip_s if len(sends) else 0.0  # from the first demand (armed) on
    sends = sends[sends[:, 1] >= start]
    states = states[states[:, 0] >= start]
    lticks = lticks[lticks[:, 0] >= start]
    accepts = emu["accepts"]
    accepts = accepts[accepts[:, 0] >= start]
    eticks = emu["ticks"]
    eticks = eticks[eticks[:, 0] >= start]
    writes = emu["writes"]
    writes = writes[(writes[:, 0] >= start) & (writes[:, 2] == 0x11)]
    sent_at = dict(zip(sends[:, 0].astype(int), sends[:, 1]))
    demand_hop = np.array([t - sent_at[int(s)] for t, s in accepts if int(s) in sent_at])
    made = t0 + states[:, 3] / 1e6
    state_hop = states[:, 0] - made
    # each STATE's pty write: the first STATE write whose due time is at or after its making
    idx = np.searchsorted(writes[:, 0], made)
    ok = idx < len(writes)
    write_late = writes[:, 1] - writes[:, 0]
    to_pty = writes[idx[ok], 1] - made[ok]
    pty_to_host = states[ok, 0] - writes[idx[ok], 1]
    return {
        "seconds": round(float(sends[-1, 1] - sends[0, 1]), 1) if len(sends) > 1 else 0.0,
        "faults": [f"{t - start + skip_s:.1f} s: {r}" for t, r in faults],
        "loop_late": _pct(lticks[:, 1]), "loop_work": _pct(lticks[:, 2]),
        "demand_send_gap": _pct(np.diff(sends[:, 1])),
        "demand_write": _pct(sends[:, 2] - sends[:, 1]),
        "demand_to_device": _pct(demand_hop),
        "device_accept_gap": _pct(np.diff(accepts[:, 0])),
        "emu_tick_gap": _pct(np.diff(eticks[:, 0])), "emu_tick_work": _pct(eticks[:, 1]),
        "state_write_late": _pct(write_late),
        "state_made_to_pty": _pct(to_pty), "state_pty_to_host": _pct(pty_to_host),
        "state_made_to_host": _pct(state_hop),
        "host_state_gap": _pct(np.diff(states[:, 0])),
    }


# -- load ---------------------------------------------------------------------------------------
CHURN = ("import numpy as np\nwhile True:\n    a = np.ones(8_000_000)\n    a *= 2\n    del a\n")


def start_hogs(busy: int, churn: int, nice: int) -> list[subprocess.Popen]:
    pre = (lambda: os.nice(nice)) if nice else None
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"], preexec_fn=pre)
             for _ in range(busy)]
    procs += [subprocess.Popen([sys.executable, "-c", CHURN], preexec_fn=pre)
              for _ in range(churn)]
    return procs


def run(seconds: float, rt_cpu: str, trace: Path) -> dict[str, Any]:
    """Arm the default soft arm on the emulator and move it for ``seconds``; re-arm after a
    fault (counted)."""
    from core.robots import load
    from hw_bridge import soft_arm_process
    from hw_bridge.soft_arm_process import ControlProcess

    os.environ[TRACE_ENV] = str(trace)
    soft_arm_process._child = traced_child
    robot = load("soft-arm")
    ctl = ControlProcess(robot, device="emulator", cpus="auto" if rt_cpu == "auto" else None)
    rearms = 0
    samples: list[list[float]] = []
    sampling = threading.Event()

    def sample_cpu_stat() -> None:  # per-CPU user, system, idle, steal (USER_HZ ticks)
        while not sampling.wait(0.005):
            with open("/proc/stat") as f:
                rows = [line.split() for line in f if line.startswith("cpu") and line[3] != " "]
            samples.append([time.perf_counter()] + [float(r[k]) for r in rows for k in (1, 3, 4, 8)])

    threading.Thread(target=sample_cpu_stat, daemon=True).start()
    try:
        end = time.monotonic() + 60
        while ctl.view is None and time.monotonic() < end:
            time.sleep(0.1)
        ctl.arm().result(30)
        k = robot.kappa_max * 0.5
        poses = [np.full(robot.n_segments, k), np.full(robot.n_segments, -k)]
        end = time.monotonic() + seconds
        i = 0
        while time.monotonic() < end:
            try:
                ctl.goto(poses[i % 2]).result(10)
            except RuntimeError:  # a fault disarmed it: arm again
                rearms += 1
                ctl.arm().result(30)
            i += 1
            time.sleep(1.5)
        view = ctl.view
        sched = view.scheduling if view else "?"
    finally:
        ctl.close()
        sampling.set()
        np.save(trace / "cpu_stat.npy", np.array(samples))
    return {"rearms": rearms, "scheduling": sched}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--emulator"]:
        return emulator_main(argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--hog", type=int, default=0)
    ap.add_argument("--churn", type=int, default=0)
    ap.add_argument("--hog-nice", type=int, default=19)
    ap.add_argument("--rt-cpu", choices=("auto", "none"), default="auto")
    ap.add_argument("--keep", default=None, help="keep the trace in this directory")
    args = ap.parse_args(argv)
    trace = Path(args.keep or tempfile.mkdtemp(prefix="link_gaps_"))
    trace.mkdir(parents=True, exist_ok=True)
    hogs = start_hogs(args.hog, args.churn, args.hog_nice)
    try:
        info = run(args.seconds, args.rt_cpu, trace)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    result = {"hog": args.hog, "churn": args.churn, "hog_nice": args.hog_nice,
              "rt_cpu": args.rt_cpu, **info, **analyse(trace)}
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
