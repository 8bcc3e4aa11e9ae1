"""serve.py's lifecycle: a busy port is refused (exit 2) unless --next-free-port; SIGTERM while
starting ends it at once; with a browser that never answers, shutdown still takes <= 2 s."""

from __future__ import annotations

import base64
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from console.serve_lifecycle import port_in_use
from test_no_orphans import descendants, free_port, start_console, survivors

pytestmark = pytest.mark.timing

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
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    proc.wait(10)
    took = time.monotonic() - t0
    assert proc.returncode == 128 + signal.SIGTERM and took < 1.0, (proc.returncode, took)
    time.sleep(1.0)
    tree.update({p: v for p, v in descendants(proc.pid).items()})
    left = survivors(tree)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert left == {}
    assert "SIGTERM while starting: exiting now" in proc.stderr.read()


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


def test_shutdown_with_a_browser_that_never_answers_takes_at_most_2_s(tmp_path):
    proc, stderr = start_console(tmp_path, "--robot", "soft-arm")
    try:
        port = int(proc.args[proc.args.index("--port") + 1])
        clients = [_silent_websocket(port) for _ in range(3)]
        time.sleep(3.0)  # the console pushes the scene to them; nobody reads
        tree = descendants(proc.pid)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    for c in clients:
        c.close()
    assert proc.returncode == 0 and took < 2.5, (proc.returncode, took, stderr.read_text()[-800:])
    time.sleep(1.0)
    assert survivors(tree) == {}
