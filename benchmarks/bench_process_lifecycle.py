"""How long serve.py takes to end, side by side with baselines in the same run.

The tests (tests/console/test_serve_lifecycle.py, test_no_orphans.py) check that these things
happen (the exit code, no process left); the figures live here, since the suite runs its tests
beside one another on two busy cores. Goals (console.serve_lifecycle, hw_bridge.parent_watch):

Rows (``--runs`` each; median and max, seconds):
  SIGTERM while starting   SIGTERM once serve.py says ``hardware:`` (building the console) ->
                           its exit. Goal <= 1 s.
     baseline              SIGTERM -> exit of a Python process that only sleeps (default handler)
  shutdown, 3 silent tabs  SIGTERM of a serving soft-arm console with three websocket clients
                           that never read -> its exit: the shutdown's 5 s budget, then it exits.
     baseline              the same console without any client
  SIGKILL -> children gone SIGKILL of a serving soft-arm console -> every one of its descendants
                           (control process, planner worker, device emulator) ended. Goal <= 1 s.
     baseline              SIGKILL -> the console itself reaped (the floor: nothing to notice)

Run: .venv/bin/python benchmarks/bench_process_lifecycle.py [--runs 3] [--robot soft-arm]
"""

from __future__ import annotations

import argparse
import base64
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parent.parent
START_TIMEOUT_S = 120.0


def _stat(pid: int) -> tuple[int, str, int] | None:
    """(ppid, state, start time) of ``pid``, or None when gone."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = raw[raw.rindex(")") + 2:].split()
    return int(fields[1]), fields[0], int(fields[19])


def descendants(root: int) -> dict[int, int]:
    """pid -> start time of every live descendant of ``root``."""
    children: dict[int, list[int]] = {}
    starts: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit() and (st := _stat(int(entry))) is not None and st[1] != "Z":
            children.setdefault(st[0], []).append(int(entry))
            starts[int(entry)] = st[2]
    out: dict[int, int] = {}
    todo = list(children.get(root, []))
    while todo:
        pid = todo.pop()
        out[pid] = starts[pid]
        todo.extend(children.get(pid, []))
    return out


def alive(tree: dict[int, int]) -> list[int]:
    """Those of ``tree`` still running (same pid and start time, not a zombie)."""
    return [pid for pid, start in tree.items()
            if (st := _stat(pid)) is not None and st[1] != "Z" and st[2] == start]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve(data: Path, robot: str, port: int, stderr: int = subprocess.DEVNULL
          ) -> subprocess.Popen:
    """``serve.py --robot robot`` on ``port`` with its default hardware; stdout piped."""
    return subprocess.Popen([sys.executable, "serve.py", "--robot", robot, "--port", str(port),
                             "--no-token", "--data-dir", str(data)], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=stderr, text=True)


def wait_line(stream, start: str) -> None:
    """Read ``stream`` until a line containing ``start``; fail on EOF."""
    while True:
        line = stream.readline()
        if not line:
            raise RuntimeError(f"serve.py ended before printing {start!r}")
        if start in line:
            return


def silent_websocket(port: int) -> socket.socket:
    """A browser that opens the websocket and then never reads nor answers anything."""
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
               f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
               "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: viser-v1.1.1\r\n\r\n"
               ).encode())
    return s


def sigterm_while_starting(data: Path, robot: str) -> float:
    proc = serve(data, robot, free_port(), stderr=subprocess.PIPE)
    try:
        wait_line(proc.stderr, "hardware:")
        t0 = time.perf_counter()
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
        return time.perf_counter() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def sigterm_sleeper() -> float:
    proc = subprocess.Popen([sys.executable, "-c", "import time; print(1, flush=True); "
                             "time.sleep(600)"], stdout=subprocess.PIPE, text=True)
    proc.stdout.readline()
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGTERM)
    proc.wait(60)
    return time.perf_counter() - t0


def shutdown(data: Path, robot: str, clients: int) -> float:
    port = free_port()
    proc = serve(data, robot, port)
    tabs: list[socket.socket] = []
    try:
        wait_line(proc.stdout, "Console for")
        tabs = [silent_websocket(port) for _ in range(clients)]
        time.sleep(3.0)  # the console pushes the scene to them; nobody reads
        t0 = time.perf_counter()
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
        return time.perf_counter() - t0
    finally:
        for tab in tabs:
            tab.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def sigkill(data: Path, robot: str) -> tuple[float, float]:
    """(s until the console is reaped, s until every descendant has ended)."""
    proc = serve(data, robot, free_port())
    try:
        wait_line(proc.stdout, "Console for")
        time.sleep(3.0)  # the control process's planner worker and the emulator are up
        tree = descendants(proc.pid)
        t0 = time.perf_counter()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(60)
        reaped = time.perf_counter() - t0
        deadline = time.monotonic() + 60
        while alive(tree) and time.monotonic() < deadline:
            time.sleep(0.005)
        left = alive(tree)
        for pid in left:
            os.kill(pid, signal.SIGKILL)
        gone = time.perf_counter() - t0 if not left else float("inf")
        return reaped, gone
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def row(name: str, values: list[float], goal: str = "") -> None:
    print(f"  {name:<28} median {statistics.median(values):7.3f} s   max {max(values):7.3f} s"
          f"   {goal}")


def repeat(runs: int, fn: Callable[[], float]) -> list[float]:
    return [fn() for _ in range(runs)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--robot", default="soft-arm")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "runs"
        print(f"serve.py --robot {args.robot}, {args.runs} runs each")
        row("SIGTERM while starting", repeat(args.runs, lambda: sigterm_while_starting(
            data, args.robot)), "goal <= 1 s")
        row("   baseline: a sleeper", repeat(args.runs, sigterm_sleeper))
        row("shutdown, 3 silent tabs", repeat(args.runs, lambda: shutdown(
            data, args.robot, 3)), "budget 5 s (after STOP and hardware)")
        row("   baseline: no tab", repeat(args.runs, lambda: shutdown(data, args.robot, 0)))
        kills = [sigkill(data, args.robot) for _ in range(args.runs)]
        row("SIGKILL -> children gone", [k[1] for k in kills], "goal <= 1 s")
        row("   baseline: console reaped", [k[0] for k in kills])
    return 0


if __name__ == "__main__":
    sys.exit(main())
