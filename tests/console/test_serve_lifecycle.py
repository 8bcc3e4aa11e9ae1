"""serve.py's lifecycle: a busy port is refused (exit 2) unless --next-free-port; SIGTERM while
starting ends it at once (exit 128 + SIGTERM, before it serves); with a browser that never
answers, shutdown still ends (exit 0) and leaves no children.

How long these take (SIGTERM while starting: about 0.01 s, goal 1 s; shutdown with a silent
browser: goal 2 s) is measured by ``benchmarks/bench_process_lifecycle.py`` beside a baseline,
never asserted here: the suite runs these tests beside another on two busy cores. The deadlines
here only end a test that hangs."""

from __future__ import annotations

import base64
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from console import serve_lifecycle
from console.serve_lifecycle import Lifecycle, port_in_use
from test_no_orphans import descendants, free_port, start_console, wait_gone

ROOT = Path(__file__).resolve().parents[2]


def test_port_in_use_names_the_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert port_in_use("127.0.0.1", port) == (
            f"port {port} on 127.0.0.1 is already in use (another console running?)")
    assert port_in_use("127.0.0.1", port) is None  # released: free again


def test_busy_port_exits_2_and_next_free_port_says_where_it_went(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        busy = subprocess.run([sys.executable, "serve.py", "--port", str(port), "--data-dir",
                               str(tmp_path / "runs")], cwd=ROOT, capture_output=True,
                              text=True, timeout=60)
        assert busy.returncode == 2
        assert f"port {port} on 127.0.0.1 is already in use" in busy.stderr
        assert "--next-free-port" in busy.stderr and "Console for" not in busy.stdout
        proc = subprocess.Popen([sys.executable, "serve.py", "--port", str(port),
                                 "--next-free-port", "--hardware", "mock", "--data-dir",
                                 str(tmp_path / "runs")], cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            while line and not line.startswith("Console for"):
                line = proc.stdout.readline()
            assert "Console for" in line and f":{port}/" not in line
        finally:
            proc.terminate()
            _, err = proc.communicate(timeout=30)
        assert f"PORT {port} IS BUSY: serving on" in err and proc.returncode == 0


def test_sigterm_while_starting_exits_at_once_and_leaves_no_children(tmp_path):
    proc = subprocess.Popen([sys.executable, "serve.py", "--port", str(free_port()), "--data-dir",
                             str(tmp_path / "runs")], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    line = proc.stderr.readline()
    while line and "hardware:" not in line:
        line = proc.stderr.readline()
    tree = descendants(proc.pid)  # now building: importing viser, the panels, the children
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    # The start-up path's exit (a console that had started would shut down and exit 0), and it
    # never served.
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err[-800:])
    assert "Console for" not in out
    tree.update({p: v for p, v in descendants(proc.pid).items()})
    left = wait_gone(tree)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert left == {}
    assert "SIGTERM while starting: exiting now" in err


class _Exited(Exception):
    """What the patched ``os._exit`` raises instead of ending the test's process."""


def _raise_exited(code: int) -> None:
    raise _Exited(code)


def test_shutdown_runs_every_step_in_order_within_its_budget(monkeypatch):
    said: list[str] = []
    ran: list[str] = []

    def boom() -> None:
        ran.append("boom")
        raise RuntimeError("gone")

    steps = [("a", lambda: ran.append("a")), ("boom", boom), ("c", lambda: ran.append("c"))]
    monkeypatch.setattr(serve_lifecycle.os, "_exit", _raise_exited)
    assert Lifecycle(said.append).shutdown(steps, budget=60.0) is True
    assert ran == ["a", "boom", "c"]  # a failing step does not stop the rest
    assert said == ["shutdown: boom failed: gone"]


def test_shutdown_past_its_budget_names_the_hung_step_and_exits_0(monkeypatch):
    """A step that never returns (a browser holding viser's close handshake): the shutdown
    exits after its budget, without waiting for that step. The step here blocks until the test
    ends, so the outcome does not depend on how long anything takes."""
    said: list[str] = []
    release = threading.Event()
    ran: list[str] = []

    def hang() -> None:
        release.wait()
        ran.append("hang returned")

    monkeypatch.setattr(serve_lifecycle.os, "_exit", _raise_exited)
    try:
        with pytest.raises(_Exited) as exited:
            Lifecycle(said.append).shutdown([("STOP", lambda: None), ("hardware", lambda: None),
                                             ("web server", hang),
                                             ("after", lambda: ran.append("after"))],
                                            budget=0.05)
        assert exited.value.args == (0,)
        assert len(said) == 1 and said[0].startswith("shutdown: 'web server' still running")
        assert ran == []
    finally:
        release.set()


def test_shutdown_waits_for_the_arms_stop_beyond_the_budget_of_the_rest(monkeypatch):
    """The first two steps, the arm's STOP and closing the hardware, get their own allowance (on
    a loaded machine each took past the 2 s budget, and the console exited before the hardware
    was closed): steps longer than ``budget`` still finish and the later steps run."""
    said: list[str] = []
    ran: list[str] = []

    def slow_stop() -> None:
        time.sleep(0.2)  # 20 budgets: never within one, however the machine is loaded
        ran.append("STOP")

    monkeypatch.setattr(serve_lifecycle.os, "_exit", _raise_exited)
    def slow_hardware() -> None:
        time.sleep(0.2)
        ran.append("hardware")

    steps = [("STOP", slow_stop), ("hardware", slow_hardware),
             ("web server", lambda: ran.append("web server"))]
    assert Lifecycle(said.append).shutdown(steps, budget=0.01, first_budget=60.0) is True
    assert ran == ["STOP", "hardware", "web server"] and said == []


def _silent_websocket(port: int) -> socket.socket:
    """A browser that opens the websocket and then never reads nor answers anything."""
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
               f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
               "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: viser-v1.1.1\r\n\r\n"
               ).encode())
    return s


def test_shutdown_with_a_browser_that_never_answers_ends_and_leaves_no_children(tmp_path):
    proc, stderr = start_console(tmp_path, "--robot", "soft-arm")
    try:
        port = int(proc.args[proc.args.index("--port") + 1])
        clients = [_silent_websocket(port) for _ in range(3)]
        time.sleep(3.0)  # the console pushes the scene to them; nobody reads
        tree = descendants(proc.pid)
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)  # (a bounded shutdown takes <= 2 s: bench_process_lifecycle.py)
    finally:
        if proc.poll() is None:
            proc.kill()
    for c in clients:
        c.close()
    assert proc.returncode == 0, (proc.returncode, stderr.read_text()[-800:])
    assert wait_gone(tree) == {}
