"""Per-test wall time and CPU seconds of the whole process tree, to tell a test that computes
from one that waits (opt-in: ``PYTEST_CPU_TIMES=FILE``).

A browser test's cost is spread over pytest, Chromium's processes and serve.py children, and on
a shared machine its wall time says more about the other load than about the test. This plugin
(registered by tests/conftest.py's ``pytest_plugins``; inert unless the variable is set) reads
``/proc/<pid>/stat`` utime + stime + cutime + cstime (children reaped meanwhile included) of
the pytest process and all its descendants before and after each test (setup, call and
teardown together), appends one tab-separated line per test to ``FILE`` (``nodeid wall_s
cpu_s``; under pytest-xdist each worker appends its own lines) and prints a per-file table in
the terminal summary. ``wait_s = wall_s - cpu_s / cores`` is the time the test left the cores
idle (on a 2-core machine: two tests that wait can share the cores).

A process that ends during a test without being reaped by a process of the tree takes its CPU
seconds out of the sum (the test's figure is too low, even negative): Chromium's renderers of
a closed context, Chromium itself at the session's end (in the last test's teardown), the
orphaned children of a killed serve.py. Compare such tests by wall time.

Linux only (``/proc``); elsewhere the figures are not collected.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections import defaultdict
from pathlib import Path

import pytest

ENV = "PYTEST_CPU_TIMES"
_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, CPU seconds incl. reaped children) of ``pid``, or None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()  # after "pid (comm) "; fields from state on
    ppid = int(fields[1])
    utime, stime, cutime, cstime = (int(f) for f in fields[11:15])
    return ppid, (utime + stime + cutime + cstime) / _TICK


def tree_cpu_s(root: int) -> float:
    """CPU seconds used so far by ``root`` and every live descendant (with their reaped
    children)."""
    stats: dict[int, tuple[int, float]] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            stat = _stat(int(entry.name))
            if stat is not None:
                stats[int(entry.name)] = stat
    children: dict[int, list[int]] = defaultdict(list)
    for pid, (ppid, _) in stats.items():
        children[ppid].append(pid)
    total, todo = 0.0, [root]
    while todo:
        pid = todo.pop()
        if pid in stats:
            total += stats[pid][1]
        todo.extend(children.get(pid, ()))
    return total


@dataclasses.dataclass
class TestCost:
    """One test's wall time and process-tree CPU seconds (setup + call + teardown)."""

    nodeid: str
    wall_s: float
    cpu_s: float


class CpuTimes:
    """The plugin object: measures each test, writes its line, sums per file at the end."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.costs: list[TestCost] = []

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item: pytest.Item):  # type: ignore[no-untyped-def]
        pid = os.getpid()
        wall0, cpu0 = time.monotonic(), tree_cpu_s(pid)
        yield
        cost = TestCost(item.nodeid, time.monotonic() - wall0, tree_cpu_s(pid) - cpu0)
        self.costs.append(cost)
        with self.out.open("a") as f:
            f.write(f"{cost.nodeid}\t{cost.wall_s:.2f}\t{cost.cpu_s:.2f}\n")

    def pytest_terminal_summary(self, terminalreporter: pytest.TerminalReporter) -> None:
        if not self.costs:  # (under xdist the workers measured; the table is in FILE)
            return
        cores = os.cpu_count() or 1
        per_file: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0])
        for cost in self.costs:
            sums = per_file[cost.nodeid.split("::", 1)[0]]
            sums[0] += cost.wall_s
            sums[1] += cost.cpu_s
        tr = terminalreporter
        tr.section(f"wall and CPU seconds per file ({ENV}={self.out})")
        tr.write_line(f"{'wall_s':>8} {'cpu_s':>8} {'wait_s':>8}  file   (wait = wall - cpu/{cores})")
        for path, (wall, cpu) in sorted(per_file.items(), key=lambda kv: -kv[1][0]):
            tr.write_line(f"{wall:8.1f} {cpu:8.1f} {wall - cpu / cores:8.1f}  {path}")


def pytest_configure(config: pytest.Config) -> None:
    """Register the plugin when ``PYTEST_CPU_TIMES`` names a file and /proc is there."""
    out = os.environ.get(ENV)
    if out and Path("/proc/self/stat").exists():
        config.pluginmanager.register(CpuTimes(Path(out)), "cpu_times_recorder")
