"""Real-time scheduling for a control process, so its loop never waits on a descheduled thread.

A ``SCHED_FIFO`` loop thread is not enough in CPython: every other thread of the same process
(the publisher, the command reader, ``multiprocessing`` feeder threads) takes the GIL too. If
one of them holds it and is preempted by an ordinary process (a browser on the same machine),
the loop thread waits for the GIL until that thread runs again — measured: period error p99
~5 ms (one GIL switch interval) and 26 ms worst case with 20 headless browsers on 2 cores.

:func:`promote_threads` therefore gives every thread of the process ``SCHED_FIFO`` at a
priority *below* the loop's (a GIL holder then always gets a core back before any ordinary
process), with ``SCHED_RESET_ON_FORK`` so processes started later (the planner worker, an
emulator) do not inherit real-time priority; :func:`shorten_gil_wait` lowers the interpreter's
switch interval so the loop asks for the GIL back after 0.5 ms instead of 5 ms.

Bytes written to a pseudo-terminal do not reach the other side in the writer's system call:
Linux queues the tty flip buffer's work on its unbound workqueue, and an ordinary-priority
kernel worker (``kworker/u*``) moves them. When other work keeps both cores busy that worker
waits, and with it every DEMAND and STATE (measured with 20 headless browsers on 2 cores:
round trip p99 20.7 ms with both ends real-time, 2.0 ms once the workers were too).
:func:`promote_tty_workers` gives those workers ``SCHED_FIFO`` (root only); the device emulator
does so while it runs real-time, since they are its wire.
"""

from __future__ import annotations

import os
import sys
import threading
from typing import Any


def set_fifo(priority: int, tid: int = 0) -> str:
    """Put thread ``tid`` (0: the calling thread) under ``SCHED_FIFO`` at ``priority``.

    Returns:
        What the thread got: ``"SCHED_FIFO <p>"`` or ``"default (SCHED_FIFO refused: ...)"``
        (without the permission, e.g. unprivileged users outside a real-time group).
    """
    if not 1 <= priority <= 99:
        raise ValueError(f"SCHED_FIFO priority must be in 1..99, got {priority}")
    try:
        policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
        os.sched_setscheduler(tid, policy, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"default (SCHED_FIFO refused: {exc})"
    return f"SCHED_FIFO {priority}"


def helper_priority(loop_priority: int | None) -> int:
    """Priority of a control process's other threads: just below its loop (0: no loop priority).

    Just below, not further: on the one real-time CPU (:mod:`hw_bridge.cpu_partition`) the
    device emulator runs too (at 45 under a loop at 50); a helper that holds the GIL must not
    wait for it while the loop waits for the helper.
    """
    return max(1, loop_priority - 1) if loop_priority else 0


def thread_policy(tid: int = 0) -> int:
    """The scheduling policy of thread ``tid`` without the reset-on-fork flag."""
    return os.sched_getscheduler(tid) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)


def promote_threads(priority: int) -> list[str]:
    """Give every running thread of this process that is not yet real-time ``SCHED_FIFO``.

    Threads already under ``SCHED_FIFO`` (the loop thread, at its own higher priority) keep
    theirs. Call it again after new threads start (``multiprocessing`` starts its queue feeder
    threads lazily); it is cheap (one syscall per thread).

    Returns:
        The names of the threads promoted now.
    """
    promoted = []
    for thread in threading.enumerate():
        tid = thread.native_id
        if tid is None:
            continue
        try:
            if thread_policy(tid) == os.SCHED_FIFO:
                continue
        except OSError:  # the thread just ended
            continue
        if set_fifo(priority, tid).startswith("SCHED_FIFO"):
            promoted.append(thread.name)
    return promoted


def shorten_gil_wait(seconds: float = 0.0005) -> None:
    """Make a thread that waits for the GIL ask the holder to drop it after ``seconds``."""
    sys.setswitchinterval(seconds)


def tty_workers() -> list[int]:
    """PIDs of the kernel's unbound workqueue workers (``kworker/u*``), which carry pty bytes."""
    pids = []
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/comm") as f:
                comm = f.read()
        except OSError:  # ended meanwhile
            continue
        if comm.startswith("kworker/u"):
            pids.append(int(entry.name))
    return pids


def promote_tty_workers(priority: int) -> list[int]:
    """Give every ``kworker/u*`` not yet real-time ``SCHED_FIFO`` at ``priority``.

    The pool starts new workers as it needs them: call it again from time to time. Without
    the permission (not root) nothing changes.

    Returns:
        The PIDs promoted now.
    """
    if not 1 <= priority <= 99:
        raise ValueError(f"SCHED_FIFO priority must be in 1..99, got {priority}")
    promoted = []
    for pid in tty_workers():
        try:
            if os.sched_getscheduler(pid) == os.SCHED_FIFO:
                continue
            os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(priority))
        except OSError:  # ended meanwhile, or no permission
            continue
        promoted.append(pid)
    return promoted


def demote_tty_workers(pids: list[int], priority: int) -> None:
    """Return workers that :func:`promote_tty_workers` promoted (and that are still at
    ``priority``) to ordinary scheduling."""
    for pid in pids:
        try:
            if (os.sched_getscheduler(pid) == os.SCHED_FIFO
                    and os.sched_getparam(pid).sched_priority == priority):
                os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            continue


def promote_new_threads() -> None:
    """Loop thread, after a (re)configure started a new receive thread: make it real-time like
    the loop's other helper threads (just below the loop), or a
    descheduled GIL holder stalls the loop past the link timeout on a loaded machine."""
    try:
        if thread_policy() == os.SCHED_FIFO:
            promote_threads(helper_priority(os.sched_getparam(0).sched_priority))
    except (OSError, AttributeError):  # no real-time scheduling here: nothing to match
        pass


class TtyWorkerKeeper:
    """Keeps the ``kworker/u*`` workers real-time while a real-time pty user runs.

    The keeping runs in a small process of its own (``python -m hw_bridge.tty_keeper``) at
    ordinary priority: a thread of ordinary priority inside a real-time process would hold that
    process's GIL while it scans /proc, and if it were preempted there the real-time threads
    would wait for it. The keeper promotes new workers every ``every`` s and, when told to stop
    or when its parent goes away (its stdin closes, also after a SIGKILL), returns the workers
    it promoted to ordinary scheduling.
    """

    def __init__(self, priority: int, every: float = 2.0) -> None:
        if not 1 <= priority <= 99:
            raise ValueError(f"SCHED_FIFO priority must be in 1..99, got {priority}")
        self.priority = priority
        self.every = every
        self.promoted = 0  # how many the first pass promoted
        self._proc: Any = None

    def start(self) -> "TtyWorkerKeeper":
        import subprocess
        if os.geteuid() != 0:  # only root may change kernel threads: nothing to keep
            return self
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "hw_bridge.tty_keeper", str(self.priority), str(self.every)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)  # ordinary priority:
        # the real-time threads calling this were set with SCHED_RESET_ON_FORK (set_fifo)
        line = self._proc.stdout.readline()  # the first pass's count, once it is done
        self.promoted = int(line) if line.strip().isdigit() else 0
        return self

    def stop(self, timeout: float = 5.0) -> None:
        if self._proc is None:
            return
        self._proc.stdin.close()  # the keeper hands the workers back and exits
        try:
            self._proc.wait(timeout)
        except Exception:  # noqa: BLE001 - never leave it behind
            self._proc.kill()
        self._proc = None
