"""CPU partition: the soft arm's loop and its emulator on the real-time CPU, all else off it
(read back from the kernel's affinity masks of the running processes and threads)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hw_bridge.cpu_partition import (CpuPartition, format_cpus, online_cpus, parse_cpus,
                                     pin_tree, process_cpus)

REPO = Path(__file__).resolve().parents[2]
needs_two_cpus = pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2,
                                    reason="a partition needs two CPUs")


def test_default_keeps_the_highest_cpu_for_real_time() -> None:
    p = CpuPartition.default(frozenset({0, 1, 2, 3}))
    assert p == CpuPartition(frozenset({3}), frozenset({0, 1, 2}))
    assert p.describe() == "real-time CPU 3, others 0,1,2"
    assert CpuPartition.default(frozenset({5})) is None  # one CPU: nothing to split
    with pytest.raises(ValueError, match="overlap"):
        CpuPartition(frozenset({1}), frozenset({0, 1}))
    with pytest.raises(ValueError, match="non-empty"):
        CpuPartition(frozenset(), frozenset({0}))


def test_cpu_lists_round_trip_and_bad_ones_are_refused() -> None:
    cpus = frozenset(os.sched_getaffinity(0))
    assert parse_cpus(format_cpus(cpus)) == cpus
    assert format_cpus(frozenset({3, 0, 1})) == "0,1,3"
    for bad in ("", "x", "0,,1", str(max(online_cpus()) + 1)):
        with pytest.raises(ValueError):
            parse_cpus(bad)


def test_online_cpus_cover_this_process() -> None:
    assert os.sched_getaffinity(0) <= online_cpus()


@needs_two_cpus
def test_pin_process_moves_every_thread_and_later_ones_inherit() -> None:
    code = (
        "import os, sys, threading, time, json\n"
        f"sys.path.insert(0, {str(REPO)!r})\n"
        "from hw_bridge.cpu_partition import pin_process\n"
        "ev = threading.Event()\n"
        "early = threading.Thread(target=ev.wait); early.start()\n"
        "n = pin_process(frozenset({0}))\n"
        "late = threading.Thread(target=ev.wait); late.start()\n"
        "tids = os.listdir('/proc/self/task')\n"
        "cpus = [sorted(os.sched_getaffinity(int(t))) for t in tids]\n"
        "print(json.dumps({'n': n, 'cpus': cpus}))\n"
        "ev.set()\n")
    out = json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                    check=True).stdout)
    assert out["n"] == 2  # the main thread and the early one
    assert out["cpus"] == [[0]] * 3  # the late thread inherited it


@needs_two_cpus
def test_pin_tree_moves_descendants_but_not_the_skipped_subtree() -> None:
    tree = subprocess.Popen(["sh", "-c", "sleep 30 & sleep 30 & wait"])
    try:
        deadline = time.monotonic() + 20
        kids: list[int] = []
        while len(kids) < 2 and time.monotonic() < deadline:
            kids = [int(p) for p in Path(f"/proc/{tree.pid}/task/{tree.pid}/children")
                    .read_text().split()]
            time.sleep(0.05)
        assert len(kids) == 2
        n = pin_tree(tree.pid, frozenset({0}), skip=frozenset({kids[1]}))
        assert n == 2  # sh and the first sleep
        assert process_cpus(tree.pid) == {0} and process_cpus(kids[0]) == {0}
        assert process_cpus(kids[1]) == os.sched_getaffinity(0)  # skipped: as it was
    finally:
        tree.kill()
        subprocess.run(["pkill", "-P", str(tree.pid)], check=False)
        tree.wait()


def test_emulator_refuses_a_bad_cpu_list() -> None:
    from hw_bridge.emulator import parse_args
    for bad in ("x", "999"):
        with pytest.raises(SystemExit):
            parse_args(["--robot", "soft-arm", "--cpus", bad])
    assert parse_args(["--robot", "soft-arm", "--cpus", "0"]).cpus == frozenset({0})


def _children(pid: int) -> list[int]:
    out = []
    for tid in os.listdir(f"/proc/{pid}/task"):
        out += [int(c) for c in Path(f"/proc/{pid}/task/{tid}/children").read_text().split()]
    return out


def _cmdline(pid: int) -> str:
    return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()


@needs_two_cpus
def test_control_process_runs_the_loop_and_emulator_on_the_real_time_cpu() -> None:
    from hw_bridge.soft_arm_process import ControlProcess
    from core.robots import load

    part = CpuPartition.default(frozenset(os.sched_getaffinity(0)))
    assert part is not None
    ctl = ControlProcess(load("soft-arm"), seed=7, device="emulator", cpus=part)
    try:
        deadline = time.monotonic() + 60
        while ctl.view is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert ctl.view is not None, ctl.failure
        pid = ctl._proc.pid
        for tid in os.listdir(f"/proc/{pid}/task"):  # the loop and all its helper threads
            assert os.sched_getaffinity(int(tid)) == part.realtime
        kids = {_cmdline(k): k for k in _children(pid)}
        emulator = [k for c, k in kids.items() if "hw_bridge.emulator" in c]
        planner = [k for c, k in kids.items() if "multiprocessing" in c]
        assert len(emulator) == 1 and len(planner) == 1, kids
        for tid in os.listdir(f"/proc/{emulator[0]}/task"):
            assert os.sched_getaffinity(int(tid)) == part.realtime
        assert process_cpus(planner[0]) == part.other  # planning is ordinary work
        for k in _children(emulator[0]):  # the emulator's pty-worker keeper (root only)
            assert process_cpus(k) == part.other
        if os.geteuid() == 0:  # real-time priorities granted: loop > its helpers > emulator
            emulator_priority = os.sched_getparam(emulator[0]).sched_priority
            assert emulator_priority == 45

            def helpers_ordered() -> bool:
                prios = sorted(os.sched_getparam(int(t)).sched_priority
                               for t in os.listdir(f"/proc/{pid}/task"))
                return prios[-1] == 50 and all(emulator_priority < q < 50 for q in prios[:-1])
            deadline = time.monotonic() + 20  # threads started lazily are promoted each second
            while not helpers_ordered() and time.monotonic() < deadline:
                time.sleep(0.2)
            assert helpers_ordered()
    finally:
        ctl.close()
