"""Console under load: N headless Chromium clients watching while the arm moves.

``python benchmarks/bench_load.py [--clients 5] [--seconds 60] [--robot soft-arm]``
(goal run: ``--clients 20 --seconds 600``; soak: ``--seconds 3600``, memory growth <= 10 %).

Each phase runs the whole console in its own child process (``serve.build``: every panel, lab
mode, the hardware ``serve.py`` attaches, a port on 127.0.0.1) with the arm moving:

* soft arm (``--motion loop``, default): grasp-and-place trials back to back over the paper's
  spots on the console's control process (``app.services.soft_control``: the 100 Hz loop in its
  own process, planning in another); the Control panel draws what it measures. Otherwise (or with
  ``--motion demo``) the demo motion in the console process.
* baseline phase: the same for ``--baseline-seconds`` with 0 clients; load phase: N clients --
  Playwright contexts of one headless Chromium (``--client-kind browser``), or websocket-only
  viewers that receive the stream without rendering (``--client-kind ws``: the console's own
  serving cost, without 2 cores' worth of software WebGL competing with it).

Reported side by side: console process CPU (% of one core, from /proc/<pid>/stat) and memory
(VmRSS from /proc/<pid>/status; growth from the first sample after warm-up to the last, and an
RSS trace), frames drawn per second, the control process's CPU and memory, and its loop p99
period error (worst 10 s window it published), max and overruns over the phase. The browsers
share this machine's cores with the console; on the lab network they would not, so by default
they run in Linux's idle scheduling class (``--browser-sched idle``, the default: they get only
the CPU nothing else wants; ``nice 19`` is not enough because Chromium re-nices its renderers
itself, to 0 and -8), or ``--browser-sched normal`` to compete at equal priority.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hw_bridge.cpu_partition import CpuPartition, pin_process, pin_tree  # noqa: E402
from load_clients import CHROMIUM_ARGS, chromium_path, ws_viewer  # noqa: E402
from load_trials import TrialTally, start_trials, trials_in, trials_text  # noqa: E402
from proc_figures import cpu_seconds, largest_process, memory_mb, rss_mb  # noqa: E402
from rt_reference import ReferenceSleeper  # noqa: E402

LOOP_PRIORITY = 50  # the control process's loop thread (ControlProcess's sched_priority)
MEMORY_FLOOR = 0.05  # a phase ends when the machine has less than this share of memory left


# -- the console child ---------------------------------------------------------------------------

def _serve_module() -> Any:
    spec = importlib.util.spec_from_file_location("serve", REPO / "serve.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


def child(a: argparse.Namespace) -> int:
    """Serve the console (``serve.build``) and answer ``mark`` / ``stats`` / ``quit``."""
    from core.robots import load

    serve = _serve_module()
    robot = load(a.robot)
    argv = ["--robot", a.robot, "--port", str(a.port), "--lab", "--no-token",
            "--data-dir", a.data_dir]
    if a.hardware:
        argv += ["--hardware", a.hardware]
    argv += ["--rt-cpu", a.rt_cpu]
    if a.motion != "loop":
        argv += ["--demo"]  # the demo motion is a service: the console core stops it on STOP
    args = serve.parse_args(argv)
    server, app, _ = serve.build(args, robot, "load benchmark")
    print(f"bench_load child: {serve.pin_console(app.services)}", file=sys.stderr, flush=True)
    app.start()
    stop = threading.Event()
    ctl, tally = start_trials(app, robot, stop) if a.motion == "loop" else (None, TrialTally())
    demo = None
    if ctl is None:
        demo = app.services.demo
        assert demo is not None
        demo.start()
    loop_pid = (ctl.pid or 0) if ctl is not None else 0
    print(f"READY http://127.0.0.1:{server.get_port()}/ {'loop' if ctl else 'demo'} {loop_pid}",
          flush=True)
    base_overruns = 0
    for line in sys.stdin:
        cmd = line.strip()
        view = None if ctl is None else ctl.view
        if cmd == "mark" and view is not None:  # start of the measured window
            base_overruns = view.stats.overruns
        elif cmd == "stats":
            out: dict[str, Any] = {"clients": len(server.get_clients()),
                                   "frames_drawn": app.frames_drawn, "loop": None,
                                   "trials": dataclasses.asdict(tally)}
            if view is not None:  # the control process publishes stats of its last 1000 ticks
                st = view.stats
                out["loop"] = {"overruns": st.overruns - base_overruns,
                               "p99_ms": st.period_error_ms_p99, "max_ms": st.period_error_ms_max,
                               "work_p99_ms": st.work_ms_p99, "scheduling": view.scheduling,
                               "slow": [dataclasses.asdict(x) for x in view.slow_ticks]}
            print(json.dumps(out), flush=True)
        elif cmd == "quit":
            break
    stop.set()
    if demo is not None:
        demo.stop()
    app.stop()
    app.services.close()
    server.stop()
    return 0


# -- the measuring parent ------------------------------------------------------------------------

class Console:
    """A console child process."""

    def __init__(self, a: argparse.Namespace) -> None:
        cmd = [sys.executable, __file__, "--child", "--robot", a.robot, "--motion", a.motion,
               "--data-dir", a.data_dir, "--rt-cpu", a.rt_cpu]
        if a.hardware:
            cmd += ["--hardware", a.hardware]
        log = Path(a.data_dir) / "console-child.log"  # the console's stderr, for a post-mortem
        log.parent.mkdir(parents=True, exist_ok=True)
        self._log = log.open("w")
        self.proc = subprocess.Popen(cmd, cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self._log, text=True)
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("READY "):
                _, self.url, self.motion, loop_pid = line.split()
                self.loop_pid = int(loop_pid)
                break
        else:
            raise RuntimeError("console child did not start")

    def mark(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write("mark\n")
        self.proc.stdin.flush()

    def stats(self) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write("stats\n")
        self.proc.stdin.flush()
        while True:
            line = self.proc.stdout.readline()
            if line.startswith("{"):
                return json.loads(line)

    def close(self) -> None:
        try:
            assert self.proc.stdin is not None
            self.proc.stdin.write("quit\n")
            self.proc.stdin.flush()
            self.proc.wait(timeout=15)
        except (BrokenPipeError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()


def measure(console: Console, seconds: float, warmup: float, sample_every: float,
            progress_every: float = 0.0, cpus: Any = None) -> dict[str, Any]:
    """CPU, memory and loop figures of the console over ``seconds`` after ``warmup``.

    The control process publishes loop stats of its last 1000 ticks (10 s); they are sampled
    every ``sample_every`` s (<= 10 s) and the worst window is reported. A reference sleeper
    (:mod:`rt_reference`) runs beside the loop for the same time: the machine's own floor.
    """
    pid, lpid = console.proc.pid, console.loop_pid
    time.sleep(warmup)
    console.mark()
    ref = ReferenceSleeper(seconds, LOOP_PRIORITY, None if cpus is None else cpus.realtime)
    s0, c0, t0 = console.stats(), cpu_seconds(pid), time.monotonic()
    l0 = cpu_seconds(lpid) if lpid else 0.0
    rss, loops = [rss_mb(pid)], []
    loop_rss = [rss_mb(lpid)] if lpid else []
    end = t0 + seconds
    next_report = t0 + progress_every if progress_every > 0 else float("inf")
    ended_early = None
    while time.monotonic() < end:
        time.sleep(min(sample_every, max(0.0, end - time.monotonic())))
        avail, total = memory_mb()
        if avail < MEMORY_FLOOR * total:  # the clients, not the console: stop measuring
            ended_early = (f"after {time.monotonic() - t0:.0f} s: the machine's memory ran out "
                           f"({avail:.0f} of {total:.0f} MB available; largest process "
                           f"{largest_process()}); later figures would measure thrashing")
            print(f"  ** phase ended {ended_early}", flush=True)
            break
        rss.append(rss_mb(pid))
        if lpid:
            loop_rss.append(rss_mb(lpid))
        st = console.stats()
        loops.append(st["loop"])
        now = time.monotonic()
        if now >= next_report:  # running figures, so a long soak shows its first 10 min too
            next_report += progress_every
            w = [x for x in loops if x]
            loop_txt = (f"loop p99 worst {max(x['p99_ms'] for x in w):.3f} ms, max "
                        f"{max(x['max_ms'] for x in w):.3f} ms, overruns {w[-1]['overruns']}, "
                        f"work p99 worst {max(x['work_p99_ms'] for x in w):.3f} ms"
                        if w else "loop n/a")
            print(f"  [{now - t0:6.0f} s] console CPU "
                  f"{100.0 * (cpu_seconds(pid) - c0) / (now - t0):.1f} %, RSS {rss[-1]:.1f} MB "
                  f"({100.0 * (rss[-1] - rss[0]) / rss[0]:+.1f} %), {loop_txt}, "
                  f"{trials_text(s0['trials'], st['trials'])}, machine memory available "
                  f"{avail:.0f} MB", flush=True)
    s1, c1, t1 = console.stats(), cpu_seconds(pid), time.monotonic()
    out = {"cpu_pct": 100.0 * (c1 - c0) / (t1 - t0), "rss_mb": rss[-1], "rss_trace": rss,
           "rss_growth_pct": 100.0 * (rss[-1] - rss[0]) / rss[0], "rss_peak_mb": max(rss),
           "fps": (s1["frames_drawn"] - s0["frames_drawn"]) / (t1 - t0),
           "clients": s1["clients"], "loop": None, "loop_cpu_pct": None, "loop_rss_mb": None,
           "trials": trials_in(s0["trials"], s1["trials"]), "ended_early": ended_early,
           "reference": ref.stop() if ended_early else ref.result()}
    windows = [w for w in loops + [s1["loop"]] if w]
    if windows:
        out["loop"] = {"p99_ms": max(w["p99_ms"] for w in windows),
                       "max_ms": max(w["max_ms"] for w in windows),
                       "work_p99_ms": max(w["work_p99_ms"] for w in windows),
                       "overruns": s1["loop"]["overruns"], "scheduling": s1["loop"]["scheduling"],
                       "slow": s1["loop"]["slow"]}
    if lpid:
        out["loop_cpu_pct"] = 100.0 * (cpu_seconds(lpid) - l0) / (t1 - t0)
        out["loop_rss_mb"] = rss_mb(lpid)
        out["loop_rss_trace"] = loop_rss + [out["loop_rss_mb"]]
    return out


def run_phase(a: argparse.Namespace, n_clients: int, seconds: float) -> dict[str, Any]:
    console = Console(a)
    pages: list[Any] = []
    try:
        if n_clients == 0:
            return measure(console, seconds, a.warmup, a.sample_every, cpus=a.cpus)
        if a.client_kind == "ws":
            if a.cpus is not None:  # the viewers started from here inherit it
                pin_process(a.cpus.other)
            stop = threading.Event()
            received = [0] * n_clients
            threads = [threading.Thread(target=ws_viewer, args=(console.url, stop, received, i),
                                        daemon=True) for i in range(n_clients)]
            for th in threads:
                th.start()
            try:
                result = measure(console, seconds, a.warmup, a.sample_every, a.progress_every, a.cpus)
            finally:
                stop.set()
                for th in threads:
                    th.join(2.0)
            result["mb_per_client_s"] = sum(received) / n_clients / 1e6 / (seconds + a.warmup)
            return result
        from playwright.sync_api import sync_playwright

        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium_path(a), headless=True,
                                         args=CHROMIUM_ARGS)
            deadline = time.monotonic() + a.connect_timeout
            for _ in range(n_clients):  # one after the other: each page loads on a calmer CPU
                ctx = browser.new_context(viewport={"width": a.width, "height": a.height})
                page = ctx.new_page()
                page.goto(console.url, timeout=max(1_000.0, 1000.0 * (deadline - time.monotonic())))
                left_ms = max(1_000.0, 1000.0 * (deadline - time.monotonic()))
                page.get_by_text("Session", exact=True).wait_for(timeout=left_ms)
                pages.append(page)
            print(f"  {n_clients} pages loaded in "
                  f"{a.connect_timeout - (deadline - time.monotonic()):.0f} s", flush=True)
            if a.cpus is not None:  # loaded on every core, measured off the real-time one
                print(f"  {pin_tree(os.getpid(), a.cpus.other, frozenset({console.proc.pid}))} browser and benchmark threads "
                      f"moved to CPUs {sorted(a.cpus.other)}", flush=True)
            result = measure(console, seconds, a.warmup, a.sample_every, a.progress_every, a.cpus)
            browser.close()
        return result
    finally:
        console.close()


def evenly(trace: list[float], n: int = 10) -> list[float]:
    """``n`` samples of ``trace`` evenly over it (all of it when shorter)."""
    return [trace[round(i * (len(trace) - 1) / (n - 1))] for i in range(n)] if len(trace) > n \
        else trace


def fmt(v: Any, spec: str) -> str:
    return "n/a" if v is None else format(v, spec)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--clients", type=int, default=5)
    p.add_argument("--seconds", type=float, default=60.0, help="load phase length")
    p.add_argument("--baseline-seconds", type=float, default=None,
                   help="0-client phase length (default: min(--seconds, 60))")
    p.add_argument("--robot", default="soft-arm")
    p.add_argument("--motion", choices=("loop", "demo"), default="loop",
                   help="loop: grasp-and-place trials on the console's control process; demo: "
                        "the demo motion in the console process")
    p.add_argument("--hardware", choices=("emulator", "mock"), default=None,
                   help="passed to serve.py (default: serve.py's default)")
    p.add_argument("--warmup", type=float, default=10.0)
    p.add_argument("--sample-every", type=float, default=5.0)
    p.add_argument("--client-kind", choices=("browser", "ws"), default="browser",
                   help="browser: headless Chromium pages; ws: websocket-only viewers (the "
                        "console's own serving cost, without rendering on this machine)")
    p.add_argument("--browser-sched", choices=("idle", "normal"), default="idle",
                   help="scheduling class of the Chromium processes (normal: same as the console)")
    p.add_argument("--connect-timeout", type=float, default=600.0,
                   help="seconds for all browser pages to show the console")
    p.add_argument("--progress-every", type=float, default=60.0,
                   help="print running figures of the load phase this often (s; 0: never)")
    p.add_argument("--width", type=int, default=800)
    p.add_argument("--height", type=int, default=500)
    p.add_argument("--data-dir", default=str(REPO / "artifacts" / "bench_load_runs"))
    p.add_argument("--rt-cpu", choices=("auto", "none"), default="auto",
                   help="serve.py's --rt-cpu; auto also keeps the clients off the real-time CPU "
                        "(on the lab network they run on other machines)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.child:
        return child(a)
    if a.clients < 0 or a.seconds <= 0:
        p.error("--clients must be >= 0 and --seconds > 0")
    base_s = a.baseline_seconds if a.baseline_seconds is not None else min(a.seconds, 60.0)
    a.cpus = CpuPartition.default() if a.rt_cpu == "auto" else None
    print(f"console under load: {a.robot}, motion={a.motion}, {a.clients} {a.client_kind} "
          f"clients for "
          f"{a.seconds:g} s (baseline 0 clients for {base_s:g} s), {os.cpu_count()} cores, "
          f"browsers in the {a.browser_sched} scheduling class; "
          f"{'no CPU pinning' if a.cpus is None else a.cpus.describe()}",
          flush=True)
    base = run_phase(a, 0, base_s)
    load = run_phase(a, a.clients, a.seconds)
    rows = [
        ("clients connected", "d", base["clients"], load["clients"]),
        ("console CPU, % of one core", ".1f", base["cpu_pct"], load["cpu_pct"]),
        ("console RSS at end, MB", ".1f", base["rss_mb"], load["rss_mb"]),
        ("RSS growth over the phase, %", "+.1f", base["rss_growth_pct"], load["rss_growth_pct"]),
        ("frames drawn per s", ".1f", base["fps"], load["fps"]),
        ("control process CPU, % of one core", ".1f", base["loop_cpu_pct"],
         load["loop_cpu_pct"]),
        ("control process RSS, MB", ".1f", base["loop_rss_mb"], load["loop_rss_mb"]),
        ("loop p99 period error (worst 10 s), ms", ".3f", (base["loop"] or {}).get("p99_ms"),
         (load["loop"] or {}).get("p99_ms")),
        ("loop max period error, ms", ".3f", (base["loop"] or {}).get("max_ms"),
         (load["loop"] or {}).get("max_ms")),
        ("loop overruns in the phase", "d", (base["loop"] or {}).get("overruns"),
         (load["loop"] or {}).get("overruns")),
        ("loop tick work p99 (worst 10 s), ms", ".3f", (base["loop"] or {}).get("work_p99_ms"),
         (load["loop"] or {}).get("work_p99_ms")),
    ]
    for key, name, spec in (("p99_ms", "reference sleeper p99 lateness, ms", ".3f"),
                            ("max_ms", "reference sleeper max lateness, ms", ".3f"),
                            ("missed", "reference sleeper deadlines missed", "d")):
        rows.append((name, spec, (base["reference"] or {}).get(key),
                     (load["reference"] or {}).get(key)))
    if "mb_per_client_s" in load:
        rows.append(("MB/s streamed to each client", ".2f", None, load["mb_per_client_s"]))
    print(f"\n{'figure':40s} {'0 clients':>12s} {f'{a.clients} clients':>12s}")
    for name, spec, b, l in rows:
        print(f"{name:40s} {fmt(b, spec):>12s} {fmt(l, spec):>12s}")
    if load["loop"]:
        print(f"loop thread scheduling: {load['loop']['scheduling']}")
        for x in sorted(load["loop"]["slow"], key=lambda x: -x["late_ms"] - x["read_ms"]
                        - x["update_ms"] - x["write_ms"])[:5]:
            print(f"  slow tick at t = {x['t']:.2f} s: late {x['late_ms']:.2f}, drain "
                  f"{x['drain_ms']:.2f}, read {x['read_ms']:.2f}, update {x['update_ms']:.2f}, "
                  f"write {x['write_ms']:.2f} ms, {x['missed']} deadlines skipped")
    if load["ended_early"]:
        print(f"** the load phase ended {load['ended_early']}")
    for name, phase in (("0 clients", base), (f"{a.clients} clients", load)):
        t = phase["trials"]
        print(f"{name}: {trials_text({k: 0 for k in t} | {'last_stop': ''}, t)}")
    trace = load["rss_trace"]
    picks = evenly(trace)
    half = trace[len(trace) // 2]
    print(f"\nRSS under load, MB, evenly over the phase: {' '.join(f'{v:.1f}' for v in picks)}")
    ltrace = load.get("loop_rss_trace") or []
    if ltrace:
        lp = evenly(ltrace)
        print(f"control process RSS, MB, evenly over the phase: {' '.join(f'{v:.1f}' for v in lp)}")
    print(f"growth over the second half: {100.0 * (trace[-1] - half) / half:+.1f} %")
    growth = load["rss_growth_pct"]
    print(f"memory growth under load: {growth:+.1f} % over {a.seconds:g} s "
          f"(soak goal: <= 10 % over 3600 s){'' if growth <= 10 else '  ** above goal **'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
