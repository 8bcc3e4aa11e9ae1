"""Every child the console starts ends within 1 s of its parent's death, whatever killed it.

A child that outlives the console is dangerous: the soft arm's control process runs
``SCHED_FIFO`` on the real-time CPU and, once nobody reads its queue, blocks for ever writing
a full pipe (its own copy of the pipe's read end keeps the write from failing). So every child
watches its parent:

* :func:`watch_parent` (in the child): a daemon thread compares ``os.getppid()`` with the pid
  of the parent that started it every ``period`` s; once it differs (the parent died and the
  child was re-parented to init or a subreaper) it runs ``on_gone`` - by default SIGKILL to
  itself, which also ends threads blocked in a write. ``getppid`` (not ``PR_SET_PDEATHSIG``)
  because the kernel sends the parent-death signal when the *thread* that forked the child
  exits: pool workers started from a short-lived callback thread would die with that thread.
  The expected pid is passed in, so a parent that died before the watch started is seen too.
* :func:`death_signal_preexec`: ``PR_SET_PDEATHSIG`` for a subprocess whose forking thread
  waits for it (the reachability map's): the kernel delivers it even if no Python thread runs.
* :func:`child_env` / :func:`parent_pid_from_env`: a plain subprocess (the device emulator)
  learns its parent's pid from ``HW_BRIDGE_PARENT_PID`` and polls it in its own loop.
* :func:`pool_initializer`: for ``ProcessPoolExecutor(initializer=...)`` workers.
* :func:`run_reporting` / :func:`exit_reason`: a child's start-up failure, or its death, in
  words for the console.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading
from typing import Any, Callable

PARENT_PID_ENV = "HW_BRIDGE_PARENT_PID"
_PR_SET_PDEATHSIG = 1


def parent_gone(expected_ppid: int) -> bool:
    """Whether the process that started this one has died (this one was re-parented)."""
    return os.getppid() != expected_ppid


def _kill_self() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def watch_parent(expected_ppid: int | None = None, on_gone: Callable[[], Any] | None = None,
                 period: float = 0.1) -> threading.Thread | None:
    """Start a daemon thread that runs ``on_gone`` (default: SIGKILL to this process) once the
    parent process is gone.

    Args:
        expected_ppid: The parent's pid (default: ``multiprocessing.parent_process()``'s, else
            the current ``os.getppid()``). Pass it when known so a parent that died before this
            call is noticed.
        on_gone: Called once, in the watch thread; if it returns, this process is killed.
        period: Poll interval in seconds.

    Returns:
        The thread, or None when there is no parent to watch (pid 1 started us).
    """
    if expected_ppid is None:
        parent = multiprocessing.parent_process()
        expected_ppid = parent.pid if parent is not None and parent.pid else os.getppid()
    if expected_ppid <= 1:
        return None

    def run() -> None:
        stop = threading.Event()
        while not parent_gone(expected_ppid):
            stop.wait(period)
        try:
            if on_gone is not None:
                on_gone()
        finally:
            _kill_self()

    t = threading.Thread(target=run, name="parent-watch", daemon=True)
    t.start()
    return t


def child_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """Environment for a subprocess that should watch this process (``HW_BRIDGE_PARENT_PID``)."""
    out = dict(os.environ if env is None else env)
    out[PARENT_PID_ENV] = str(os.getpid())
    return out


def parent_pid_from_env() -> int | None:
    """The parent pid :func:`child_env` passed, or None (started by hand: nothing to watch)."""
    raw = os.environ.get(PARENT_PID_ENV, "")
    return int(raw) if raw.isdigit() and int(raw) > 1 else None


def pool_initializer(init: Callable[..., Any] | None = None, *args: Any) -> None:
    """Worker initializer: watch the parent, then run ``init(*args)`` (picklable by name).

    Use as ``ProcessPoolExecutor(initializer=pool_initializer, initargs=(init, *args))``.
    """
    watch_parent()
    if init is not None:
        init(*args)


def exit_reason(exitcode: int | None) -> str | None:
    """Why a child process ended, for the operator (None: still running or a clean exit)."""
    if exitcode is None or exitcode == 0:
        return None
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"the control process was killed ({name})"
    return f"the control process exited with code {exitcode}"


def death_signal_preexec(sig: int = signal.SIGKILL) -> Callable[[], None] | None:
    """A ``Popen(preexec_fn=...)`` that sets ``PR_SET_PDEATHSIG`` in the child (None off Linux).

    Only for a child whose forking thread lives as long as the child is wanted, e.g. a thread
    that waits for it. libc is loaded here, in the parent, so the child calls no ``dlopen``
    between fork and exec.
    """
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    ppid = os.getpid()

    def preexec() -> None:
        prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
        if os.getppid() != ppid:  # the parent died between fork and prctl
            os._exit(1)
    return preexec


def run_reporting(target: Callable[..., Any], replies: Any, *args: Any) -> Any:
    """Run a child process's ``target(*args)``; if it raises, put ``("failed", reason)`` on
    ``replies`` first, so the console shows the reason (not only the terminal's traceback).

    Use as ``ctx.Process(target=run_reporting, args=(target, replies, *args))``.
    """
    try:
        return target(*args)
    except BaseException as exc:
        try:
            replies.put(("failed", f"{type(exc).__name__}: {exc}"[:500]))
        except Exception:  # noqa: BLE001 - the queue itself is broken: the traceback remains
            pass
        raise


def quiesce_blas_on_fork() -> None:
    """``Popen(preexec_fn=...)`` for children of a real-time process (does nothing itself).

    Any ``preexec_fn`` makes Python start the child with ``fork()`` instead of ``vfork()``, and
    OpenBLAS's fork handler then ends its idle worker thread in the parent. That thread was
    started at numpy's import with ordinary scheduling; left in the soft arm's ``SCHED_FIFO``
    control process it would be the one thread the loop could wait for at normal priority
    (``tests/test_cpu_partition.py`` checks every thread's priority).
    """
