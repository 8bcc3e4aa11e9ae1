"""viser 1.1.1's broadcast windows collected once for all viewers, not once per viewer.

Every connected client has a producer that walks the broadcast buffer message by message
(``AsyncMessageBuffer._window_loop``: a dictionary look-up, a comparison and an append each), so a
frame of the extensible arm (~115 bone-pose messages) was walked 50 times with 50 viewers: with
the encoding shared (:mod:`console.web.shared_sends`) that walk and the per-client check of which
frame a window matches were most of the event loop's remaining work per frame.

:func:`install` replaces ``_window_loop`` with :func:`_window_loop`, viser's own loop line for
line except the inner walk: on a persistent (broadcast) buffer the window for the same range of
message ids is taken from :func:`shared_window`, which walks the range once and hands every
client the same list object (so :func:`console.web.shared_sends.encode_window` finds its frame by
identity). A range holding a message that skips one client (``excluded_self_client``) is walked
per client, as before; per-client buffers (not persistent: they pop what they take) are too.
"""

from __future__ import annotations

import asyncio
from typing import Any, AsyncGenerator, Sequence

_WINDOWS = "_viser_windows_shared"  # on a buffer: {(first id, last id, size): window}
_WINDOWS_KEPT = 8


def shared_window(buffer: Any, last_sent_id: int, most_recent_id: int,
                  client_id: int) -> tuple[list[Any], int]:
    """The window a client whose cursor is ``last_sent_id`` takes from a persistent buffer.

    Returns the messages after ``last_sent_id`` up to ``most_recent_id`` (at most
    ``buffer.max_window_size`` of them; ids of culled messages are skipped) and the new cursor,
    exactly as viser's per-client walk; the list is shared by every client asking for the
    same range and must not be changed.
    """
    key = (last_sent_id, most_recent_id, buffer.max_window_size)
    kept: dict[tuple[int, int, int], tuple[list[Any], int, bool]] = \
        buffer.__dict__.setdefault(_WINDOWS, {})
    hit = kept.get(key)
    if hit is None:
        window: list[Any] = []
        get = buffer.message_from_id.get
        size = buffer.max_window_size
        excluded = False
        cursor = last_sent_id
        while cursor < most_recent_id and len(window) < size:
            cursor += 1
            message = get(cursor)
            if message is not None:
                window.append(message)
                excluded = excluded or message.excluded_self_client is not None
        hit = (window, cursor, excluded)
        kept[key] = hit
        while len(kept) > _WINDOWS_KEPT:
            del kept[next(iter(kept))]
    window, cursor, excluded = hit
    if excluded:  # rare (a client's own echo): walked for this client alone, as viser does
        return _own_window(buffer, last_sent_id, most_recent_id, client_id)
    return window, cursor


def _own_window(buffer: Any, last_sent_id: int, most_recent_id: int,
                client_id: int) -> tuple[list[Any], int]:
    window: list[Any] = []
    while (last_sent_id < most_recent_id and len(window) < buffer.max_window_size
           and buffer.atomic_counter == 0):
        last_sent_id += 1
        if buffer.persistent_messages:
            message = buffer.message_from_id.get(last_sent_id, None)
        else:
            with buffer.buffer_lock:
                message = buffer.pop_message_locked(last_sent_id)
        if message is not None and message.excluded_self_client != client_id:
            window.append(message)
    return window, last_sent_id


async def _window_loop(self: Any, client_id: int, backlog_last_id: int,
                       backlog_done_message: Any) -> AsyncGenerator[Sequence[Any], None]:
    """viser 1.1.1's ``AsyncMessageBuffer._window_loop`` with the walk shared (module doc)."""
    last_sent_id = -1
    backlog_done_pending = backlog_done_message is not None
    flush_wait = self.event_loop.create_task(self.flush_event.wait())
    self.generator_cursors[client_id] = last_sent_id
    try:
        while not self.done:
            window: list[Any] = []
            most_recent_message_id = self.message_counter - 1
            if backlog_done_pending:
                most_recent_message_id = min(most_recent_message_id, backlog_last_id)
            if last_sent_id < most_recent_message_id and self.atomic_counter == 0:
                if self.persistent_messages:
                    window, last_sent_id = shared_window(self, last_sent_id,
                                                         most_recent_message_id, client_id)
                else:
                    window, last_sent_id = _own_window(self, last_sent_id,
                                                       most_recent_message_id, client_id)
            self.generator_cursors[client_id] = last_sent_id
            if (backlog_done_pending and last_sent_id >= backlog_last_id
                    and self.atomic_counter == 0):
                backlog_done_pending = False
                window = [*window, backlog_done_message]  # (never the shared list itself)
            if len(window) > 0:
                yield window
            else:
                await self.message_event.wait()
                self.message_event.clear()
            most_recent_message_id = self.message_counter - 1
            if len(window) == 0 or most_recent_message_id == last_sent_id:
                done, pending = await asyncio.wait([flush_wait],
                                                   timeout=self.window_duration_sec)
                del pending
                if flush_wait in done and not self.done:
                    self.flush_event.clear()
                    flush_wait = self.event_loop.create_task(self.flush_event.wait())
    finally:
        self.generator_cursors.pop(client_id, None)
        flush_wait.cancel()
        try:
            await flush_wait
        except asyncio.CancelledError:
            pass


def install() -> bool:
    """Replace upstream viser 1.1.1's ``AsyncMessageBuffer._window_loop`` (each client walks the
    broadcast buffer itself) by :func:`_window_loop` (one walk per range, shared).

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if getattr(cls, "_shared_windows", False):
        return False
    cls._upstream_window_loop = cls._window_loop
    cls._window_loop = _window_loop
    cls._shared_windows = True
    return True


def installed() -> bool:
    """Whether ``AsyncMessageBuffer._window_loop`` is :func:`_window_loop`."""
    from viser.infra import _async_message_buffer as amb

    return bool(getattr(amb.AsyncMessageBuffer, "_shared_windows", False))


def uninstall() -> bool:
    """Put viser's own ``_window_loop`` back (tests); True if it was installed."""
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if not getattr(cls, "_shared_windows", False):
        return False
    cls._window_loop = cls._upstream_window_loop
    del cls._shared_windows, cls._upstream_window_loop
    return True
