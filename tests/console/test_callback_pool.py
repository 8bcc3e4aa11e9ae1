"""viser's callback threads end when idle (``console.web.callback_pool``).

Upstream viser 1.1.1's callback executor keeps every thread it ever started (up to 32): after a
burst of callbacks the process never gets them back. The same probe runs on a server built with
the patch undone (the threads stay) and with it (they end). The pool itself: results, errors,
its bound, reuse of an idle worker, and shutdown. The waits wait for a state, never time it.
"""

from __future__ import annotations

import threading
import time

import pytest
import viser

from console.web.callback_pool import IdleThreadPool
from fakes import upstream_viser as upstream
from tests.ws_client import wait_for

BURST = 12  # callbacks blocked at once: the executor needs this many threads


def _burst(executor, n: int = BURST) -> None:
    """``n`` tasks that all wait until every one of them runs: ``n`` threads at once."""
    barrier = threading.Barrier(n + 1)
    futures = [executor.submit(barrier.wait, 30) for _ in range(n)]
    barrier.wait(30)
    for f in futures:
        f.result(30)


def _callback_threads(server: viser.ViserServer) -> int:
    executor = server._thread_executor
    return sum(1 for t in threading.enumerate() if t.is_alive() and (
        t.name.startswith("viser-callback") or t.name.startswith(
            getattr(executor, "_thread_name_prefix", "\0") or "\0")))


def _server_burst(monkeypatch: pytest.MonkeyPatch) -> tuple[int, viser.ViserServer]:
    monkeypatch.setattr(IdleThreadPool, "idle_s", 0.2)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    _burst(server._thread_executor)
    return _callback_threads(server), server


def test_upstream_viser_keeps_its_callback_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    with upstream("callback pool"):
        during, server = _server_burst(monkeypatch)
    try:
        assert during >= BURST
        time.sleep(1.0)  # five times the patched pool's idle_s: upstream ends none, ever
        assert _callback_threads(server) == during
    finally:
        server.stop()


def test_a_console_server_gets_its_callback_threads_back(monkeypatch: pytest.MonkeyPatch) -> None:
    during, server = _server_burst(monkeypatch)
    try:
        assert isinstance(server._thread_executor, IdleThreadPool)
        assert during >= BURST
        wait_for(lambda: _callback_threads(server) == 0, timeout=30,
                 what=lambda: f"the callback threads gone ({_callback_threads(server)} left)")
        # ... and the server still runs callbacks afterwards.
        assert server._thread_executor.submit(lambda: 42).result(30) == 42
    finally:
        server.stop()


def test_results_errors_and_arguments_reach_the_futures() -> None:
    pool = IdleThreadPool(max_workers=2, idle_s=5.0)
    try:
        assert pool.submit(lambda a, b: divmod(a, b), 17, b=5).result(10) == (3, 2)
        with pytest.raises(ZeroDivisionError):
            pool.submit(lambda: 1 / 0).result(10)
        assert pool.submit(str.upper, "ok").result(10) == "OK"  # the worker survived
    finally:
        pool.shutdown()


def test_at_most_max_workers_run_and_the_rest_wait_in_order() -> None:
    pool = IdleThreadPool(max_workers=3, idle_s=5.0)
    release = threading.Event()
    started: list[int] = []
    lock = threading.Lock()

    def task(i: int) -> int:
        with lock:
            started.append(i)
        release.wait(30)
        return i

    try:
        futures = [pool.submit(task, i) for i in range(7)]
        wait_for(lambda: len(started) == 3, timeout=30, what="three tasks running")
        time.sleep(0.3)  # a fourth would have started by now if the bound did not hold
        assert sorted(started) == [0, 1, 2] and pool.threads == 3
        release.set()
        assert [f.result(30) for f in futures] == list(range(7))
        assert started[3:] == [3, 4, 5, 6]  # the queued ones, first in first out
        assert pool.threads <= 3
    finally:
        release.set()
        pool.shutdown()


def test_an_idle_worker_is_reused_not_joined_by_a_new_one() -> None:
    pool = IdleThreadPool(max_workers=8, idle_s=30.0)
    try:
        names = [pool.submit(lambda: threading.current_thread().name).result(10)
                 for _ in range(20)]
        assert set(names) == {names[0]} and pool.threads == 1
    finally:
        pool.shutdown()


def test_idle_workers_end_and_a_later_task_starts_one_again() -> None:
    pool = IdleThreadPool(max_workers=4, idle_s=0.1)
    try:
        _burst(pool, 4)
        wait_for(lambda: pool.threads == 0, timeout=30, what="the idle workers gone")
        assert pool.submit(lambda: "again").result(10) == "again"
    finally:
        pool.shutdown()


def test_shutdown_runs_what_was_queued_or_cancels_it_and_refuses_new_work() -> None:
    pool = IdleThreadPool(max_workers=1, idle_s=30.0)
    gate = threading.Event()
    first = pool.submit(gate.wait, 30)
    queued = pool.submit(lambda: "ran")
    gate.set()
    pool.shutdown(wait=True)
    assert first.result(0) is True and queued.result(0) == "ran" and pool.threads == 0
    with pytest.raises(RuntimeError, match="after shutdown"):
        pool.submit(lambda: None)

    pool = IdleThreadPool(max_workers=1, idle_s=30.0)
    gate = threading.Event()
    first = pool.submit(gate.wait, 30)
    wait_for(first.running, timeout=30, what="the first task running")
    queued = pool.submit(lambda: "ran")
    pool.shutdown(wait=False, cancel_futures=True)
    gate.set()
    assert queued.cancelled() and first.result(30) is True
    wait_for(lambda: pool.threads == 0, timeout=30, what="the worker gone")


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="max_workers"):
        IdleThreadPool(max_workers=0)
    with pytest.raises(ValueError, match="idle_s"):
        IdleThreadPool(idle_s=0.0)
