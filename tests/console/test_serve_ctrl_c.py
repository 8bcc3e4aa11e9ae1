"""Ctrl-C in the terminal running serve.py ends it quietly: the terminal sends SIGINT to the
whole foreground process group (serve.py and its children: the control process, the planner's
workers, the device emulator); serve.py says one line and stops the children itself, and no
child prints a KeyboardInterrupt traceback, nor nanobind a leak report (ruckig's objects in the
control process), on the simulated soft arm."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

from test_no_orphans import free_port, survivors, wait_tree

ROOT = Path(__file__).resolve().parents[2]


def _answers_http(port: int, timeout: float = 90.0) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as r:
                assert r.status == 200
                return
        except OSError:
            assert time.monotonic() < deadline, "serve.py never answered HTTP"
            time.sleep(0.3)


def test_ctrl_c_ends_serve_quietly_in_one_line(tmp_path):
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "serve.py", "--robot", "soft-arm", "--port", str(port), "--data-dir",
         str(tmp_path / "runs"), "--no-token"], cwd=ROOT, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True)  # its own group, as a shell
    lines: list[str] = []
    ready = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("Console for"):
                ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert ready.wait(120), "".join(lines)
        _answers_http(port)
        tree = wait_tree(proc, ["hw_bridge.emulator"])
        time.sleep(3.0)  # the control process's planner worker warms up (not a timing check)
        before = len(lines)
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C does: the whole foreground group
        code = proc.wait(30)
        reader.join(10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    after = "".join(lines[before:])
    assert code == 0, after
    for noise in ("Traceback", "KeyboardInterrupt", "nanobind", "leaked", "still running"):
        assert noise not in after, after
    ours = [line for line in lines[before:] if line.startswith("serve.py")]
    assert ours == ["serve.py: SIGINT: shutting down\n"], after
    # Besides it at most viser's own "(viser) Server stopped".
    assert all(line in ours or "Server stopped" in line for line in lines[before:]), after
    time.sleep(1.0)
    assert survivors(tree) == {}
