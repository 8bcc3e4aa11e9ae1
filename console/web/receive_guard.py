"""viser's receive loop with the client guard in front: the one place every browser frame passes.

:func:`install` replaces ``viser.infra._infra._message_consumer`` (a module-level function looked
up per connection, so one patch covers every server) by :func:`_guarded_consumer`: on a server
with a :class:`~console.web.client_guard.ClientGuard` attached each frame goes through
:meth:`~console.web.client_guard.ClientGuard.admit` before viser decodes and dispatches it (what the
guard checks and why: ``console.web.client_guard``); servers without one behave as upstream. Its
log lines are the guard's (logger ``console.web.client_guard``).
"""

from __future__ import annotations

import asyncio
import functools
from typing import Any, Callable

from console.web.client_guard import ClientGuard, _Disconnect, log
from console.web.client_values import short


async def _guarded_consumer(websocket: Any, handle_message: Callable[[Any], None],
                            message_class: Any) -> None:
    """viser's receive loop (``_message_consumer``) with :meth:`ClientGuard.admit` in front."""
    import websockets.exceptions

    guard, client_id = _guard_of(handle_message)
    if guard is None:
        await _ORIGINAL[0](websocket, handle_message, message_class)
        return
    protocol = getattr(websocket, "protocol", None)
    if protocol is not None and hasattr(protocol, "max_message_size"):
        protocol.max_message_size = guard.limits.max_message_bytes  # bigger frames: 1009
    while True:
        try:
            raw = await websocket.recv()
        except websockets.exceptions.ConnectionClosed as exc:
            code = getattr(exc.rcvd or exc.sent, "code", None)
            if code == 1009:
                log.warning("client %s disconnected: sent a message over %d bytes", client_id,
                            guard.limits.max_message_bytes)
            raise
        try:
            message = guard.admit(client_id, raw, message_class)
        except _Disconnect as exc:
            log.warning("client %s disconnected: %s", client_id, short(exc.reason, 200))
            guard.counts["disconnected"] += 1
            await websocket.close(exc.code, exc.reason[:120])
            await websocket.recv()  # raises ConnectionClosed: viser's handler tears down
            return
        if message is not None:
            handle_message(message)
        await asyncio.sleep(0)  # one client's backlog never holds the loop


def _guard_of(handle_message: Callable[..., Any]) -> tuple[ClientGuard | None, int]:
    """The guard of the server this connection belongs to, and the client id, from viser's
    per-connection ``handle_incoming`` closure (``self`` is the WebsockServer)."""
    try:
        cells = dict(zip(handle_message.__code__.co_freevars,
                         (c.cell_contents for c in handle_message.__closure__ or ())))
        return getattr(cells["self"], "_client_guard", None), int(cells["client_id"])
    except (AttributeError, KeyError, ValueError, TypeError):
        return None, -1


_ORIGINAL: list[Any] = []  # viser's own consumer, kept for servers without a guard


def install() -> bool:
    """Route every viser connection's receive loop through :func:`_guarded_consumer`.

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _infra

    if getattr(_infra._message_consumer, "_client_guard", False):
        return False
    _ORIGINAL[:] = [_infra._message_consumer]
    consumer = functools.wraps(_infra._message_consumer)(_guarded_consumer)
    consumer._client_guard = True  # type: ignore[attr-defined]
    _infra._message_consumer = consumer
    return True
