"""Real-time helpers: the pty's kernel workers are promoted while a real-time emulator runs and
handed back when it exits (read back from the kernel, not from the helpers' own records)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hw_bridge.realtime import (TtyWorkerKeeper, demote_tty_workers, promote_tty_workers,
                                tty_workers)

REPO = Path(__file__).resolve().parents[2]
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="changing kernel threads needs root")
# The tests that change the kernel's tty workers run one at a time (the ``timing`` part), not
# for a clock: the workers are one per machine, and beside them another of these tests (its
# fixture demotes every worker) or a real-time emulator elsewhere in the suite (it promotes
# them at its own priority) would change what they read back. Nothing here is timed.
machine_wide = pytest.mark.timing


@pytest.fixture
def ordinary_workers() -> None:
    """Start from ordinary workers (an emulator ended by SIGKILL cannot hand its back)."""
    for pid in tty_workers():
        try:
            os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass


def policy(pid: int) -> tuple[int, int]:
    return os.sched_getscheduler(pid), os.sched_getparam(pid).sched_priority


def test_tty_workers_are_the_unbound_kworkers() -> None:
    pids = tty_workers()
    assert pids, "a Linux kernel always has unbound workqueue workers"
    for pid in pids:
        assert Path(f"/proc/{pid}/comm").read_text().startswith("kworker/u")
    assert os.getpid() not in pids


@needs_root
@machine_wide
def test_promote_then_demote_the_workers(ordinary_workers) -> None:
    before = {pid: policy(pid) for pid in tty_workers()}
    promoted = promote_tty_workers(7)
    try:
        assert promoted and set(promoted) <= set(before)
        for pid in promoted:
            assert policy(pid) == (os.SCHED_FIFO, 7)
        # Workers that were already real-time were left as they were.
        for pid, was in before.items():
            if pid not in promoted and was[0] == os.SCHED_FIFO:
                assert policy(pid) == was
    finally:
        demote_tty_workers(promoted, 7)
    for pid in promoted:
        assert policy(pid) == (os.SCHED_OTHER, 0)
    with pytest.raises(ValueError):
        promote_tty_workers(0)


@needs_root
@machine_wide
def test_keeper_promotes_new_workers_and_hands_them_back(ordinary_workers) -> None:
    keeper = TtyWorkerKeeper(6, every=0.05).start()
    try:
        assert keeper.promoted >= 1
        # A worker the kernel starts after the keeper's pass is promoted on a later one.
        deadline = time.monotonic() + 20
        while True:
            workers = tty_workers()
            promoted = [pid for pid in workers if policy(pid) == (os.SCHED_FIFO, 6)]
            if len(promoted) == len(workers):
                break
            assert time.monotonic() < deadline, "new workers were not promoted"
            time.sleep(0.05)
    finally:
        keeper.stop()
    for pid in promoted:
        assert policy(pid) == (os.SCHED_OTHER, 0)


@needs_root
@machine_wide
def test_keeper_hands_the_workers_back_when_its_parent_is_killed(ordinary_workers) -> None:
    code = ("import sys, time; from hw_bridge.realtime import TtyWorkerKeeper; "
            "k = TtyWorkerKeeper(5, every=0.05).start(); print(k.promoted, flush=True); "
            "time.sleep(60)")
    parent = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE,
                              text=True)
    assert int(parent.stdout.readline()) >= 1
    assert any(policy(pid) == (os.SCHED_FIFO, 5) for pid in tty_workers())
    parent.kill()  # SIGKILL: no clean-up in the parent; the keeper sees its stdin close
    parent.wait(timeout=10)
    deadline = time.monotonic() + 10
    while any(policy(pid) == (os.SCHED_FIFO, 5) for pid in tty_workers()):
        assert time.monotonic() < deadline, "workers still real-time after the parent died"
        time.sleep(0.05)


@needs_root
@machine_wide
def test_real_time_emulator_keeps_its_wire_real_time_while_it_runs(ordinary_workers) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot", "extensible",
                             "--sched-priority", "30"], cwd=REPO, stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("/dev/")
        event = json.loads(proc.stdout.readline())
        assert event["event"] == "scheduling" and event["policy"] == "SCHED_FIFO"
        assert event["tty_workers"] >= 1
        assert all(os.sched_getscheduler(pid) == os.SCHED_FIFO for pid in tty_workers())
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    assert all(policy(pid) != (os.SCHED_FIFO, 29) for pid in tty_workers())
