"""The extensible arm's worker process ends when the panel drops it, even mid-task: shutdown alone
leaves a stuck plan computing; ``WorkerPool.terminate`` ends it through public API only (the
worker's pid from its first task), where the panel used to read the executor's ``_processes``."""

from __future__ import annotations

import concurrent.futures as cf
import os
import sys
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import pytest

from console.panels.extensible.worker_pool import WorkerPool
from tests.ws_client import wait_for

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")


def alive(pid: int) -> bool:
    """``pid`` runs (exists and is not a zombie)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):  # (ESRCH: reaped while the file was read)
        return False
    return stat.rpartition(")")[2].split()[0] != "Z"


def test_terminate_ends_a_worker_stuck_in_a_task_and_shutdown_alone_does_not() -> None:
    pool = WorkerPool()
    try:
        pid = pool.submit(os.getpid).result(timeout=60)
        assert pid != os.getpid()
        stuck = pool.submit(time.sleep, 600)
        wait_for(stuck.running, timeout=30, what="the task running")
        pool.shutdown(wait=False, cancel_futures=True)
        time.sleep(0.5)
        assert alive(pid)  # shutdown does not end a running task
        pool.terminate()
        wait_for(lambda: not alive(pid), timeout=10, what="the worker gone")
        with pytest.raises((BrokenProcessPool, cf.CancelledError)):
            stuck.result(timeout=10)
    finally:
        pool.terminate()


def test_terminate_of_an_idle_or_new_pool_is_harmless() -> None:
    pool = WorkerPool()
    pool.terminate()  # before the worker answered: shutdown ends it
    pool.terminate()
    with pytest.raises(RuntimeError):
        pool.submit(os.getpid)
