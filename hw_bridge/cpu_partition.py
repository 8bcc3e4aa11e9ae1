"""One CPU kept for the real-time side, so ordinary work never shares a core with the 100 Hz loop.

``SCHED_FIFO`` alone does not keep a loop on time when ordinary processes saturate every core:
Linux still gives ordinary tasks a share of each CPU (the fair server / real-time throttling)
and then runs them ahead of real-time threads for milliseconds at a time. Measured on the
2-core machine this was built on, a single-threaded ``SCHED_FIFO`` process sleeping to 10 ms
deadlines: with 4 CPU-bound ordinary processes anywhere, wake-ups up to 8.3 ms late; with the
same 4 confined to the other core, at most 0.68 ms late in 60 s. With a real-time thread busy
for long on a core, ordinary tasks there get 50 ms at once, which is longer than the soft
arm's 40 ms link timeout.

:class:`CpuPartition` therefore splits the online CPUs: the highest-numbered one runs the
control process (loop, its helper threads) and the device emulator it starts; the others run
the console, the planner worker and everything else this project starts (the load
benchmark's browsers too). Other programs on the machine can still land on the real-time CPU;
for a hard guarantee boot with ``isolcpus=<cpu>`` (docs/real-time.md).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path


def online_cpus() -> frozenset[int]:
    """The machine's online CPUs (not this process's affinity, which a parent may have narrowed)."""
    try:
        text = Path("/sys/devices/system/cpu/online").read_text().strip()
    except OSError:
        return frozenset(os.sched_getaffinity(0))
    cpus: set[int] = set()
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        cpus.update(range(int(lo), int(hi or lo) + 1))
    return frozenset(cpus)


@dataclasses.dataclass(frozen=True)
class CpuPartition:
    """The real-time CPUs and the CPUs for everything else (disjoint, both non-empty)."""

    realtime: frozenset[int]
    other: frozenset[int]

    def __post_init__(self) -> None:
        if not self.realtime or not self.other:
            raise ValueError("both CPU sets must be non-empty")
        if self.realtime & self.other:
            raise ValueError(f"CPU sets overlap: {sorted(self.realtime & self.other)}")

    @classmethod
    def default(cls, cpus: frozenset[int] | None = None) -> CpuPartition | None:
        """The highest CPU for real time, the rest for others; None on a one-CPU machine."""
        cpus = online_cpus() if cpus is None else frozenset(cpus)
        if len(cpus) < 2:
            return None
        top = max(cpus)
        return cls(frozenset({top}), cpus - {top})

    def describe(self) -> str:
        return f"real-time CPU {format_cpus(self.realtime)}, others {format_cpus(self.other)}"


def format_cpus(cpus: frozenset[int]) -> str:
    """``{1, 0}`` -> ``"0,1"`` (what :func:`parse_cpus` and the ``--cpus`` flags read)."""
    return ",".join(str(c) for c in sorted(cpus))


def parse_cpus(text: str) -> frozenset[int]:
    """``"0,1"`` -> ``{0, 1}``: online CPUs only.

    Raises:
        ValueError: not comma-separated numbers, empty, or a CPU that is not online.
    """
    try:
        cpus = frozenset(int(c) for c in text.split(","))
    except ValueError:
        raise ValueError(f"CPUs must be comma-separated numbers, got {text!r}") from None
    if not cpus or not cpus <= online_cpus():
        raise ValueError(f"CPUs {sorted(cpus)}: no such CPU (online: "
                         f"{format_cpus(online_cpus())})")
    return cpus


def _pin_tasks(pid: int | str, cpus: frozenset[int]) -> int:
    """Confine every thread of process ``pid`` (``"self"``: this one); returns how many."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:  # the process ended meanwhile
        return 0
    n = 0
    for tid in tasks:
        try:
            os.sched_setaffinity(int(tid), cpus)
        except OSError:  # the thread ended meanwhile
            continue
        n += 1
    return n


def pin_process(cpus: frozenset[int]) -> int:
    """Confine every thread of this process to ``cpus`` (threads started later inherit it).

    Returns:
        How many threads were pinned (a thread that ended meanwhile is skipped).
    """
    return _pin_tasks("self", cpus)


def pin_tree(pid: int, cpus: frozenset[int], skip: frozenset[int] = frozenset()) -> int:
    """Confine every thread of process ``pid`` and of its descendants to ``cpus``, except
    the processes in ``skip`` and their descendants.

    Returns:
        How many threads were pinned.
    """
    children: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                with open(f"/proc/{entry.name}/stat") as f:
                    stat = f.read()
            except OSError:
                continue
            ppid = int(stat[stat.rindex(")") + 2:].split()[1])
            children.setdefault(ppid, []).append(int(entry.name))
    n, todo = 0, [pid]
    while todo:
        p = todo.pop()
        if p in skip:
            continue
        todo.extend(children.get(p, []))
        n += _pin_tasks(p, cpus)
    return n


def process_cpus(pid: int = 0) -> frozenset[int]:
    """The CPUs process (main thread) ``pid`` may run on (0: this one)."""
    return frozenset(os.sched_getaffinity(pid))
