"""A fix for viser 1.1.1's message buffers, which can freeze a browser when updates come from threads.

``viser.infra._async_message_buffer.AsyncMessageBuffer.push`` calls ``message_event.set()``
(an ``asyncio.Event``) directly from whatever thread queued the message: in this console, the
render thread, the jog thread and the GUI callback pool. ``asyncio.Event`` is not thread-safe:
``set()`` iterates the event's waiters while the event loop may be appending one. Found by the
load benchmark with 20 browsers: ``RuntimeError: deque mutated during iteration`` in our render
thread, and worse, when a waiter was being appended the event is left set with that waiter never
woken; ``set()`` is then a no-op, so a per-client buffer (its own single consumer) stops sending
to that browser for good (pages that never finished loading).

:func:`install` replaces each buffer's ``message_event`` with :class:`LoopSafeEvent`, whose
``set()`` from any other thread is handed to the event loop (``call_soon_threadsafe``); nothing
in viser reads the event synchronously (it is only awaited and cleared by the buffer's window
generator). Idempotent; checked against viser 1.1.1 by ``tests/test_lab_many_clients.py``.

What viser 1.1.1 does with what browsers *send* (it trusts them) is fixed in
``console.client_guard``, which ``ConsoleApp`` installs beside this module.
"""

from __future__ import annotations

import asyncio
import functools
from typing import Any


class LoopSafeEvent(asyncio.Event):
    """``asyncio.Event`` that may be set from any thread: off the loop, ``set()`` is scheduled."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._owner = loop

    def set(self) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._owner:
            super().set()
            return
        try:
            self._owner.call_soon_threadsafe(super().set)
        except RuntimeError:  # loop closed (shutdown): nobody is waiting any more
            pass


def install() -> bool:
    """Make every viser message buffer created from now on use :class:`LoopSafeEvent`.

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if getattr(cls, "_loop_safe_event", False):
        return False
    original_init = cls.__init__

    @functools.wraps(original_init)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        original_init(self, *args, **kwargs)
        self.message_event = LoopSafeEvent(self.event_loop)

    cls.__init__ = __init__
    cls._loop_safe_event = True
    return True
