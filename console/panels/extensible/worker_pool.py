"""The extensible arm's planning / IK worker process, which can be killed when stuck in a plan.

The Paths and Tip target panels plan and solve in one ``spawn``-ed worker process, off the
console's GIL. ``ProcessPoolExecutor.shutdown`` cannot end a task that is running (Python 3.11
has no ``terminate_workers``), so :class:`WorkerPool` asks the worker for its pid as its first
task and :meth:`WorkerPool.terminate` sends it SIGTERM: public API only, no executor internals.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
from typing import Any, Callable, TypeVar

from hw_bridge.parent_watch import watch_parent

T = TypeVar("T")


class WorkerPool:
    """One ``spawn``-ed worker process for CPU-bound planning / IK.

    It leaves when the console process is gone, even SIGKILLed (a spawned worker holds its own
    queue's write end, so it would wait forever); its initializer lives in ``hw_bridge`` so the
    worker does not import the console (viser) to start.
    """

    def __init__(self) -> None:
        self._executor = cf.ProcessPoolExecutor(
            1, mp_context=multiprocessing.get_context("spawn"), initializer=watch_parent,
            initargs=(os.getpid(),))
        # The first task, so it has run whenever a later one is running (one worker, FIFO).
        self._pid: cf.Future[int] = self._executor.submit(os.getpid)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> cf.Future[T]:
        """Run ``fn(*args, **kwargs)`` in the worker (RuntimeError once shut down)."""
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        """Let the worker finish its task and leave (``ProcessPoolExecutor.shutdown``)."""
        self._executor.shutdown(wait=wait, cancel_futures=cancel_futures)

    def terminate(self) -> None:
        """Shut down and end the worker now, even in the middle of a task (a stuck plan:
        shutdown alone would leave it computing)."""
        self._executor.shutdown(wait=False, cancel_futures=True)
        if not self._pid.done() or self._pid.cancelled() or self._pid.exception() is not None:
            return  # never started a task: shutdown ends it
        try:
            os.kill(self._pid.result(), signal.SIGTERM)
        except ProcessLookupError:
            pass  # already gone
