"""What a connection flood costs the console, beside a bare viser server under the same flood.

``python benchmarks/connection_flood.py [--cycles 1000] [--held 300] [--settle 10] [--robot R]
[--sources 20]``

Starts ``serve.py --robot R --hardware emulator --lab --no-token`` (limits raised so that every
socket is admitted: this measures what an admitted client costs and leaves behind) and, in the
same run, a bare viser server with one button; floods each from this machine: ``--cycles``
websockets opened (with the browser's subprotocol and a camera hello, as a viewer) and closed
one after another from ``--sources`` local addresses (127.0.0.2 ...), then ``--held`` opened
and held idle for ``--settle`` s, then all closed. Prints for each server its RSS (MB), threads
and CPU (% of one core, from /proc of the server and its children) before, right after the
cycles and ``--settle`` s after them, while the connections are held (CPU over the idle hold),
and ``--settle`` s after they closed; each row's RSS beside the first row's;
then the log lines each printed during the flood (tracebacks, warnings), counted
(``--keep-log DIR`` keeps them). The console hands freed memory back 2 s after the last browser
of a batch left (``console.web.connection_gate.release_free_memory``).
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "benchmarks"))

from proc_figures import cpu_seconds, descendants, end_process, rss_mb, threads  # noqa: E402
from ws_client import drain  # noqa: E402
from ws_client import viewer_socket as viewer  # noqa: E402

BARE = """
import sys, time, viser
server = viser.ViserServer(host="127.0.0.1", port=int(sys.argv[1]), verbose=False)
server.gui.add_button("STOP (Esc)")
print("ready", flush=True)
while True:
    time.sleep(1)
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def figures(pid: int) -> tuple[float, int, float]:
    """(RSS MB of ``pid``, its threads, CPU seconds of it and its children so far)."""
    cpu = 0.0
    for p in descendants(pid):
        try:
            cpu += cpu_seconds(p)
        except OSError:  # ended meanwhile
            continue
    return rss_mb(pid), threads(pid), cpu


def flood(pid: int, port: int, cycles: int, held: int, settle: float, sources: int
          ) -> list[tuple[str, float, int, float]]:
    rows = []
    time.sleep(2.0)
    r0, t0, c0 = figures(pid)
    w0 = time.monotonic()
    time.sleep(5.0)
    r, t, c = figures(pid)
    rows.append(("before (idle 5 s)", r, t, 100 * (c - c0) / (time.monotonic() - w0)))
    w0, c0 = time.monotonic(), c
    for k in range(cycles):
        ws = viewer(port, f"127.0.0.{2 + k % sources}")
        ws.close()
    r, t, c = figures(pid)
    rows.append((f"after {cycles} open/close", r, t, 100 * (c - c0) / (time.monotonic() - w0)))
    w0, c0 = time.monotonic(), c
    time.sleep(settle)
    r, t, c = figures(pid)
    rows.append((f"{settle:g} s after them", r, t, 100 * (c - c0) / (time.monotonic() - w0)))
    conns = [viewer(port, f"127.0.0.{2 + k % sources}") for k in range(held)]
    time.sleep(3.0)
    for ws in conns:
        drain(ws)
    r, t, c0 = figures(pid)
    w0 = time.monotonic()
    end = w0 + settle
    while time.monotonic() < end:
        time.sleep(0.5)
        for ws in conns:
            drain(ws)
    r, t, c = figures(pid)
    rows.append((f"{held} held idle ({settle:g} s)", r, t, 100 * (c - c0) / (time.monotonic() - w0)))
    for ws in conns:
        ws.close()
    time.sleep(settle)
    r, t, c1 = figures(pid)
    w0 = time.monotonic()
    time.sleep(5.0)
    r, t, c2 = figures(pid)
    rows.append((f"{settle:g} s after all closed", r, t, 100 * (c2 - c1) / (time.monotonic() - w0)))
    return rows


def wait_served(port: int, proc: subprocess.Popen[bytes]) -> None:
    import urllib.request
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"server exited with {proc.returncode}")
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1.0):
                return
        except OSError:
            time.sleep(0.3)
    raise SystemExit("server did not serve")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cycles", type=int, default=1000)
    p.add_argument("--held", type=int, default=300)
    p.add_argument("--settle", type=float, default=10.0)
    p.add_argument("--robot", default="soft-arm")
    p.add_argument("--sources", type=int, default=20, help="local addresses to connect from")
    p.add_argument("--keep-log", type=Path, default=None, metavar="DIR",
                   help="write each server's log during the flood to DIR")
    a = p.parse_args()
    # This process's own held sockets: a server that answers no ping or close frame in time
    # (bare viser's held ones at the end) made websockets log a traceback per socket.
    logging.getLogger("websockets").setLevel(logging.CRITICAL)
    results = {}
    for name in ("bare viser", "console"):
        port = _free_port()
        with tempfile.TemporaryDirectory() as tmp:
            log_path = Path(tmp) / "server.log"
            with log_path.open("wb") as log_file:
                if name == "console":
                    cmd = [sys.executable, str(REPO / "serve.py"), "--robot", a.robot,
                           "--port", str(port), "--lab", "--no-token", "--rt-cpu", "none",
                           "--data-dir", tmp, "--max-connections", "100000",
                           "--max-connections-per-address", "100000"]
                else:
                    cmd = [sys.executable, "-c", BARE, str(port)]
                proc = subprocess.Popen(cmd, cwd=REPO, stdout=log_file, stderr=subprocess.STDOUT,
                                        env={**os.environ, "PYTHONPATH": str(REPO)})
                try:
                    wait_served(port, proc)
                    start = log_path.stat().st_size
                    results[name] = flood(proc.pid, port, a.cycles, a.held, a.settle, a.sources)
                finally:
                    end_process(proc, 15.0)
            text = log_path.read_bytes()[start:].decode(errors="replace")
            if a.keep_log is not None:
                a.keep_log.mkdir(parents=True, exist_ok=True)
                (a.keep_log / f"{name.replace(' ', '-')}.log").write_text(text)
        lines = [x for x in text.splitlines() if x.strip()]
        tracebacks = sum(1 for x in lines if x.startswith("Traceback"))
        queued = sum(1 for x in lines if "on a closed connection" in x)
        kinds = {}
        for x in lines:
            m = re.search(r"(\w+Error|\w+Exception|Warning)\b", x)
            if m:
                kinds[m.group(1)] = kinds.get(m.group(1), 0) + 1
        print(f"== {name}: {len(lines)} log lines during the flood, {tracebacks} tracebacks, "
              f"{queued} 'on a closed connection' warnings; by kind {kinds}")
        print(f"   {'when':30s} {'RSS MB':>8s} {'vs start':>8s} {'threads':>8s} {'CPU %':>7s}")
        rss0 = results[name][0][1]
        for when, rss, threads, cpu in results[name]:
            print(f"   {when:30s} {rss:8.1f} {100 * (rss / rss0 - 1):+7.1f}% {threads:8d} "
                  f"{cpu:7.1f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
