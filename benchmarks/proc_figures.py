"""Process and machine figures from /proc for the benchmarks: CPU time, resident memory."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

TICK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """utime + stime of ``pid`` and its threads, seconds (fields 14, 15 of /proc/pid/stat)."""
    text = Path(f"/proc/{pid}/stat").read_text()
    fields = text[text.rindex(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def memory_mb() -> tuple[float, float]:
    """(MemAvailable, MemTotal) of the machine, MB."""
    fields = dict(line.split(":", 1) for line in Path("/proc/meminfo").read_text().splitlines())
    return (int(fields["MemAvailable"].split()[0]) / 1024.0,
            int(fields["MemTotal"].split()[0]) / 1024.0)


def largest_process() -> str:
    """The process with the most resident memory, as ``name (pid) N MB``."""
    best = (0, "?", 0)
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                r = rss_mb(int(entry.name))
                name = Path(f"/proc/{entry.name}/comm").read_text().strip()
            except (OSError, ValueError):
                continue
            if r > best[0]:
                best = (r, name, int(entry.name))
    return f"{best[1]} ({best[2]}) {best[0]:.0f} MB"


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def descendants(pid: int) -> list[int]:
    """``pid`` and every process under it (from each process's parent in /proc/N/stat)."""
    parents: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(parents.get(p, []))
    return out


def threads(pid: int) -> int:
    """Threads of ``pid`` now."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("Threads:"):
            return int(line.split()[1])
    return 0


def end_process(proc: subprocess.Popen[bytes], timeout: float = 10.0) -> None:
    """SIGTERM ``proc``, then SIGKILL if it has not ended within ``timeout`` s."""
    proc.terminate()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
