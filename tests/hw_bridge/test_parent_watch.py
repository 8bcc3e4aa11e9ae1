"""hw_bridge.parent_watch: pool workers and waited-for subprocesses end after their parent's
SIGKILL (waited for with a generous deadline; no timing mark), and a worker started from a short-lived thread does not die with that thread
(the reason the pools watch getppid instead of PR_SET_PDEATHSIG)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hw_bridge.parent_watch import exit_reason

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux prctl/proc")

HOST = textwrap.dedent("""
    import concurrent.futures as cf, multiprocessing, os, subprocess, sys, threading, time
    from hw_bridge.parent_watch import death_signal_preexec, pool_initializer

    if __name__ == "__main__":
        box = {}
        def start_pool():  # a short-lived thread starts the pool's worker, then ends
            pool = cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                          initializer=pool_initializer)
            box["pool"] = pool
            box["worker"] = pool.submit(os.getpid).result(60)
        t = threading.Thread(target=start_pool)
        t.start()
        t.join()
        def wait_sleeper():  # this thread waits for its child, like the reachability map's
            p = subprocess.Popen(["sleep", "60"], preexec_fn=death_signal_preexec())
            box["sleeper"] = p.pid
            p.wait()
        threading.Thread(target=wait_sleeper, daemon=True).start()
        while "sleeper" not in box:
            time.sleep(0.01)
        print(box["worker"], box["sleeper"], flush=True)
        time.sleep(60)
""")


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_children_outlive_their_starting_thread_but_not_their_parent(tmp_path):
    script = tmp_path / "host.py"
    script.write_text(HOST)
    host = subprocess.Popen([sys.executable, str(script)], cwd=ROOT, stdout=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert host.stdout is not None
        worker, sleeper = map(int, host.stdout.readline().split())
        time.sleep(0.5)  # the thread that started the worker has ended meanwhile
        assert alive(worker) and alive(sleeper)
    finally:
        os.kill(host.pid, signal.SIGKILL)
        host.wait(5)
    deadline = time.monotonic() + 20.0  # ends well under 1 s when idle; generous under load
    left = [worker, sleeper]
    while left and time.monotonic() < deadline:
        time.sleep(0.05)
        left = [pid for pid in left if alive(pid)]
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert left == []


def test_exit_reason_names_the_signal():
    assert exit_reason(None) is None and exit_reason(0) is None
    assert exit_reason(-9) == "the control process was killed (SIGKILL)"
    assert exit_reason(1) == "the control process exited with code 1"


def test_device_log_reports_each_host_loss_once_and_rotates(tmp_path, monkeypatch):
    import json

    from hw_bridge import device_events

    log = tmp_path / device_events.EVENT_LOG_NAME
    gone = {"event": "host_gone_exit", "wall": "2026-12-03T01:00:00+0000", "armed": True,
            "watchdog_tripped": True, "after_ms": 51.0}
    log.write_text("x" * 100 + "\n" + json.dumps(gone) + "\nnot json\n")
    (ev,) = device_events.unreported_host_losses(log)
    assert device_events.describe_loss(ev) == (
        "At 2026-12-03T01:00:00+0000 the previous console's control process died while the arm "
        "was armed; the device watchdog tripped 51.0 ms later and stopped the motors.")
    assert device_events.unreported_host_losses(log) == []  # told once
    monkeypatch.setattr(device_events, "_ROTATE_BYTES", 10)
    with open(log, "a") as f:
        f.write(json.dumps(gone) + "\n")
    assert len(device_events.unreported_host_losses(log)) == 1
    assert (tmp_path / f"{log.name}.1").exists()
    assert [json.loads(x)["event"] for x in log.read_text().splitlines()] == ["console_start"]
