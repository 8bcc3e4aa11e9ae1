"""Tells the operator a plan is still running: the long way round around obstacles and the carry
to the bin can take seconds, and a console that shows nothing meanwhile looks hung.

:class:`PlanningClock` has one daemon thread per grasp session. The session's worker calls
:meth:`PlanningClock.start` before it plans and :meth:`PlanningClock.stop` after; from
``delay`` seconds on (0.5 s) the clock calls ``report(elapsed_s)`` every ``period`` seconds
until stopped. :meth:`stop` returns only once no report is running, so a late "planning…"
never overwrites the outcome the worker shows next.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)


class PlanningClock:
    """Reports how long the running plan has taken; see the module docstring."""

    def __init__(self, report: Callable[[float], None], delay: float = 0.5,
                 period: float = 0.5) -> None:
        self.report, self.delay, self.period = report, float(delay), float(period)
        self._cond = threading.Condition()
        self._since: float | None = None
        self._next = 0.0
        self._reporting = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="planning-clock", daemon=True)
        self._thread.start()

    def start(self) -> None:
        """A plan starts now."""
        with self._cond:
            self._since = time.perf_counter()
            self._next = self._since + self.delay
            self._cond.notify_all()

    def stop(self) -> None:
        """The plan ended: no report after this returns."""
        with self._cond:
            self._since = None
            self._cond.notify_all()
            while self._reporting:
                self._cond.wait()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._since = None
            self._cond.notify_all()

    def _run(self) -> None:
        with self._cond:
            while not self._closed:
                if self._since is None:
                    self._cond.wait()
                    continue
                now = time.perf_counter()
                if now < self._next:
                    self._cond.wait(self._next - now)
                    continue
                elapsed = now - self._since
                self._next = now + self.period
                self._reporting = True
                self._cond.release()
                try:
                    self.report(elapsed)
                except Exception:  # a panel's error must not stop the clock
                    log.exception("planning progress report failed")
                finally:
                    self._cond.acquire()
                    self._reporting = False
                    self._cond.notify_all()
