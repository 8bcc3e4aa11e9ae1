"""serve.py: bad arguments fail fast with a clear message; the hardware flag is noted."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(REPO / "serve.py"), *args], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


def test_unknown_robot_exits_2_and_lists_the_shipped_robots() -> None:
    result = run("--robot", "no-such-arm")
    assert result.returncode == 2
    assert "unknown robot 'no-such-arm'" in result.stderr
    assert "extensible" in result.stderr and "soft-arm" in result.stderr


def test_out_of_range_port_exits_2() -> None:
    result = run("--port", "70000")
    assert result.returncode == 2 and "--port" in result.stderr


def test_unknown_hardware_choice_is_refused_by_argparse() -> None:
    result = run("--hardware", "arduino")
    assert result.returncode == 2 and "invalid choice" in result.stderr


def test_unusable_port_path_is_reported_and_the_console_still_serves() -> None:
    """A controller path that cannot be opened is a fault on the console, not a crash."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, str(REPO / "serve.py"), "--robot", "extensible", "--port", str(port),
         "--port-path", "/dev/null"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stderr is not None
        line = proc.stdout.readline()
        while line and "Console for" not in line:
            line = proc.stdout.readline()
        assert f"http://127.0.0.1:{port}/" in line
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=60)  # (its time: a benchmark)
    assert "controller on /dev/null" in err
    assert proc.returncode == 0  # SIGTERM is a clean shutdown
