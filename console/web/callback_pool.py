"""viser's callback threads leave when idle, so a burst of browsers does not keep 32 threads.

Upstream viser 1.1.1 builds one ``concurrent.futures.ThreadPoolExecutor(max_workers=32)`` per
server (``ViserServer.__init__``) and runs every GUI / scene callback and every client's connect
and disconnect handlers in it. That executor starts a thread per submission until it has 32 and
never ends one: after a flood of connections (or a lab's worth of browsers opening at once) the
console keeps 32 idle threads, their stacks and their malloc arenas for the rest of its life.

:func:`install` makes ``ViserServer`` build an :class:`IdleThreadPool` instead (the module name
``viser._viser.ThreadPoolExecutor`` is what ``__init__`` calls): the same interface viser uses
(``submit``, ``shutdown``) and the same bound of 32 workers, but a worker that has had nothing to
do for :attr:`IdleThreadPool.idle_s` seconds ends. Only servers built after :func:`install` get
it; :func:`uninstall` puts viser's own name back (tests observe upstream behaviour with it).
"""

from __future__ import annotations

import concurrent.futures as cf
import itertools
import queue
import threading
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")

_Work = tuple[cf.Future[Any], Callable[..., Any], tuple[Any, ...], dict[str, Any]]
_MARK = "_console_idle_thread_pool"  # on viser._viser: the executor class it replaced


class IdleThreadPool(cf.Executor):
    """A bounded thread pool whose workers end after ``idle_s`` seconds without work.

    A submission is taken by an idle worker if there is one; otherwise a new worker starts,
    up to ``max_workers`` (then it waits in the queue, first in, first out).

    Args:
        max_workers: At most this many threads at once.
        idle_s: A worker with nothing to do for this long ends (> 0).
        thread_name_prefix: Names of the workers' threads (``prefix-N``).
    """

    idle_s: float = 5.0

    def __init__(self, max_workers: int = 32, idle_s: float | None = None,
                 thread_name_prefix: str = "viser-callback") -> None:
        if max_workers < 1:
            raise ValueError(f"max_workers must be >= 1, got {max_workers}")
        if idle_s is not None:
            if not idle_s > 0:
                raise ValueError(f"idle_s must be > 0, got {idle_s}")
            self.idle_s = idle_s
        self.max_workers = max_workers
        self._prefix = thread_name_prefix
        self._numbers = itertools.count(1)
        self._queue: queue.SimpleQueue[_Work | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._threads: set[threading.Thread] = set()
        self._idle = 0  # workers waiting for work (under _lock)
        self._queued = 0  # submissions no worker has taken yet (under _lock)
        self._shutdown = False

    @property
    def threads(self) -> int:
        """How many workers are alive now."""
        with self._lock:
            return len(self._threads)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> cf.Future[T]:
        """Run ``fn(*args, **kwargs)`` on a worker.

        Raises:
            RuntimeError: after :meth:`shutdown`.
        """
        future: cf.Future[T] = cf.Future()
        with self._lock:
            if self._shutdown:
                raise RuntimeError("cannot schedule new futures after shutdown")
            self._queued += 1
            self._queue.put((future, fn, args, kwargs))
            if self._queued > self._idle and len(self._threads) < self.max_workers:
                thread = threading.Thread(target=self._work,
                                          name=f"{self._prefix}-{next(self._numbers)}",
                                          daemon=True)
                self._threads.add(thread)
                thread.start()
        return future

    def _work(self) -> None:
        me = threading.current_thread()
        while True:
            with self._lock:
                self._idle += 1
            try:
                item = self._queue.get(timeout=self.idle_s)
            except queue.Empty:
                with self._lock:
                    self._idle -= 1
                    # A submission put under the lock after the timeout is still ours to take.
                    if self._queued > self._idle:
                        continue
                    self._threads.discard(me)
                    return
            with self._lock:
                self._idle -= 1
                if item is not None:
                    self._queued -= 1
            if item is None:  # shutdown
                with self._lock:
                    self._threads.discard(me)
                return
            future, fn, args, kwargs = item
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn(*args, **kwargs)
            except BaseException as exc:  # noqa: BLE001 - the future carries it, as upstream
                future.set_exception(exc)
                del exc
            else:
                future.set_result(result)
            del item, future, fn, args, kwargs  # nothing of the task kept while idle

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """No new submissions; queued ones still run unless ``cancel_futures``; every worker
        ends once the queue is empty (``wait``: joined here)."""
        with self._lock:
            self._shutdown = True
            threads = list(self._threads)
            if cancel_futures:
                while True:
                    try:
                        item = self._queue.get_nowait()
                    except queue.Empty:
                        break
                    if item is not None:
                        self._queued -= 1
                        item[0].cancel()
            for _ in threads:
                self._queue.put(None)
        if wait:
            for thread in threads:
                if thread is not threading.current_thread():
                    thread.join()


def install() -> bool:
    """``ViserServer`` builds an :class:`IdleThreadPool` for its callbacks from now on.

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser import _viser

    if hasattr(_viser, _MARK):
        return False
    setattr(_viser, _MARK, _viser.ThreadPoolExecutor)
    setattr(_viser, "ThreadPoolExecutor", IdleThreadPool)
    return True


def installed() -> bool:
    """Whether :func:`install` is in place."""
    from viser import _viser

    return hasattr(_viser, _MARK) and _viser.ThreadPoolExecutor is IdleThreadPool


def uninstall() -> bool:
    """Put viser's own executor class back (servers built from now on); True if it was patched."""
    from viser import _viser

    if not hasattr(_viser, _MARK):
        return False
    setattr(_viser, "ThreadPoolExecutor", getattr(_viser, _MARK))
    delattr(_viser, _MARK)
    return True
