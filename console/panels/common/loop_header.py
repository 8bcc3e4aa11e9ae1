"""Keeps the header's Phase and Link true to the arm's loop process, for both arms.

:class:`LoopHeader` is the one writer of the header's ``phase`` and ``link`` fields. Panels
offer their wording of the newest view (:meth:`LoopHeader.show`: "approach · waypoint 1 of 5 ·
ARMED"); whether it may be shown is :func:`console.arm_status.header_fields`' decision, taken
again every :data:`REFRESH_S` by a thread of its own, so a loop process that died or went
silent is said within 1 s even when no new view (and so no new frame) comes. Without panels
the header still tells the truth, worded from the view's link health alone.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any, Callable, Protocol, runtime_checkable

from console.core.arm_status import (STALE_AFTER_S, Field, LoopNews, Tone, header_fields,
                                loop_trouble)

log = logging.getLogger(__name__)

REFRESH_S = 0.25  # re-evaluated this often: stale (> 0.5 s) is said within 0.75 s
FIELDS = ("phase", "link")


@runtime_checkable
class LoopSource(Protocol):
    """The parent-side handle of an arm's loop process
    (:class:`hw_bridge.loop_process.LoopProcess`; a test's stand-in without a view age is
    not one, and its panels word the header themselves)."""

    @property
    def view(self) -> Any: ...

    @property
    def alive(self) -> bool: ...

    @property
    def failure(self) -> str | None: ...

    @property
    def pid(self) -> int | None: ...

    def view_age(self) -> float: ...

    def restart(self) -> None: ...


class HeaderSink(Protocol):
    """Where the fields go (:class:`console.panels.common.header.ConsoleHeader`)."""

    def show(self, field: str, text: str, tone: Tone | None = None, *,
             escape: bool = True) -> None: ...


def news_of(loop: LoopSource) -> LoopNews:
    """The loop's news at this moment."""
    return LoopNews(started=loop.pid is not None, alive=loop.alive, failure=loop.failure,
                    age=loop.view_age())


class LinkView(Protocol):
    """What both arms' views carry: the link's :class:`hw_bridge.interface.LinkHealth`
    (None: no serial link)."""

    @property
    def link(self) -> Any: ...


def link_health_phase(view: LinkView) -> Field:
    """Phase wording from the view's link health alone (no panel offered one yet)."""
    h = view.link
    if h is None:
        return "running", "ok"
    return ("running · ARMED" if h.armed else "running · disarmed"), "ok"


def link_health_link(view: LinkView) -> Field:
    """Link wording from the view's link health alone (no panel offered one yet)."""
    h = view.link
    if h is None:
        return "no serial link", "ok"
    if h.fault:
        return h.fault, "fault"
    return f"{h.state} · {'ARMED' if h.armed else 'disarmed'}", "ok"


class LoopHeader:
    """The header's Phase and Link from ``loop``'s view and its age (see the module docstring).

    Args:
        header: Where the fields are shown.
        loop: The arm's loop process.
    """

    def __init__(self, header: HeaderSink, loop: LoopSource) -> None:
        self.header = header
        self.loop = loop
        self._lock = threading.Lock()
        self._wording: dict[str, Callable[[Any], Field]] = {}
        self.trouble = False  # whether the last refresh found the view untrustworthy
        self.needs_restart = False  # ... because the loop process died, failed or went silent
        self._quit = threading.Event()
        self._thread: threading.Thread | None = None

    def show(self, field: str, text: str, tone: Tone | None = None) -> None:
        """A panel's wording of the newest view for ``field`` (``phase`` or ``link``); shown
        only while the view is fresh (else the header says why not), and kept for later
        refreshes until the loop goes stale or is restarted."""
        if field not in FIELDS:
            raise ValueError(f"the loop header has no field {field!r}; fields: {FIELDS}")
        fixed: Field = (text, tone)
        with self._lock:
            self._wording[field] = lambda view: fixed
        self.refresh()

    def refresh(self) -> tuple[Field, Field]:
        """Decide and show both fields now; returns them."""
        loop = self.loop
        news = news_of(loop)
        view = loop.view
        with self._lock:
            phase_of = self._wording.get("phase", link_health_phase)
            link_of = self._wording.get("link", link_health_link)
        phase, link = header_fields(news, view, phase_of, link_of)
        with self._lock:
            self.trouble = view is None or loop_trouble(news) is not None
            self.needs_restart = news.started and (not news.alive or news.failure is not None
                                                   or STALE_AFTER_S < news.age < math.inf)
            if self.trouble:  # a panel's wording is of an old view: never shown again
                self._wording.clear()
        self.header.show("phase", phase[0], phase[1])
        self.header.show("link", link[0], link[1])
        return phase, link

    # -- the thread ---------------------------------------------------------------------------
    def start(self) -> LoopHeader:
        """Refresh every :data:`REFRESH_S` until :meth:`stop` (idempotent)."""
        if self._thread is None or not self._thread.is_alive():
            self._quit.clear()
            self._thread = threading.Thread(target=self._run, name="loop-header", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        self._quit.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._thread = None

    def _run(self) -> None:
        while not self._quit.wait(REFRESH_S):
            try:
                self.refresh()
            except Exception:  # noqa: BLE001 - a display hiccup must not end the truth
                log.debug("loop header refresh failed", exc_info=True)
