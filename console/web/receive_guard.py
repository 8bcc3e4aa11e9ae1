"""viser's receive loop with the client guard in front: the one place every browser frame passes.

:func:`install` replaces upstream viser 1.1.1's ``viser.infra._infra._message_consumer`` (a
module-level function looked up per connection, so one patch covers every server; upstream it
decodes every frame and hands it to ``handle_incoming``, which stores and broadcasts it) by
:func:`_guarded_consumer`: each frame goes through the guard's
:meth:`~console.web.client_guard.ClientGuard.admit` before viser decodes and dispatches it (what
the guard checks and why: ``console.web.client_guard``).

How a connection finds its guard: a :class:`~console.web.client_guard.ClientGuard` attaches
itself to the server's ``WebsockServer`` (:func:`~console.web.client_guard.guard_of` reads
it); the connection's server and client id are the free variables ``self`` and ``client_id``
of viser's per-connection ``handle_incoming`` closure (:data:`ROUTE_NAMES`).
:func:`check_route` checks at install time that viser's code still has them and
:func:`install` refuses to patch when it does not. Failing closed, with one log line per
connection: frames of a connection that cannot be traced to a server (the names
changed anyway) are read and dropped; frames sent to a server with no guard attached (yet: a
browser may connect before the console is built) wait unread until one is. None is ever handed
to viser unguarded. Log lines are the guard's (logger
``console.web.client_guard``).
"""

from __future__ import annotations

import asyncio
import functools
import inspect
import types
from typing import Any, Callable

from console.web import IncompatibleViser
from console.web.client_guard import ClientGuard, Disconnect, guard_of, log
from console.web.client_values import short

#: The free variables of viser 1.1.1's ``handle_incoming`` closure this module reads.
ROUTE_NAMES = ("self", "client_id")
#: viser 1.1.1's ``_message_consumer`` parameters, in order.
CONSUMER_PARAMS = ("websocket", "handle_message", "message_class")


def route_of(handle_message: Callable[..., Any]) -> tuple[Any, int] | None:
    """(WebsockServer, client id) of a connection, from viser's ``handle_incoming`` closure
    (its free variables :data:`ROUTE_NAMES`); None when they are not there."""
    code = getattr(handle_message, "__code__", None)
    closure = getattr(handle_message, "__closure__", None)
    if code is None or closure is None:
        return None
    try:
        cells = dict(zip(code.co_freevars, (c.cell_contents for c in closure)))
        server, client_id = (cells[n] for n in ROUTE_NAMES)
        return server, int(client_id)
    except (KeyError, ValueError, TypeError):
        return None


def _nested(code: types.CodeType, name: str) -> types.CodeType | None:
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            if const.co_name == name:
                return const
            found = _nested(const, name)
            if found is not None:
                return found
    return None


def check_route(owner: type | None = None, consumer: Callable[..., Any] | None = None) -> None:
    """Check that viser still hands its receive loop a ``handle_incoming`` closing over
    :data:`ROUTE_NAMES` and calls the loop with :data:`CONSUMER_PARAMS`.

    Args:
        owner: The class one of whose methods defines ``handle_incoming`` (default: viser's
            ``WebsockServer``; viser 1.1.1 defines it in ``_background_worker``).
        consumer: The receive loop (default: viser's ``_message_consumer``, or the one this
            module installed, which keeps its signature).

    Raises:
        IncompatibleViser: naming what is missing.
    """
    from viser.infra import _infra

    owner = _infra.WebsockServer if owner is None else owner
    consumer = _infra._message_consumer if consumer is None else consumer
    codes = (_nested(f.__code__, "handle_incoming") for f in vars(owner).values()
             if isinstance(f, types.FunctionType))
    code = next((c for c in codes if c is not None), None)
    if code is None:
        raise IncompatibleViser(f"viser's {owner.__name__} defines no handle_incoming: the "
                                "client guard cannot tell which server a message is for")
    missing = [n for n in ROUTE_NAMES if n not in code.co_freevars]
    if missing:
        raise IncompatibleViser(f"viser's handle_incoming no longer closes over {missing} "
                                f"(it has {list(code.co_freevars)}): the client guard cannot "
                                "tell which server a message is for")
    params = tuple(inspect.signature(consumer).parameters)
    if params != CONSUMER_PARAMS:
        raise IncompatibleViser(f"viser's _message_consumer takes {params}, not "
                                f"{CONSUMER_PARAMS}")


async def _guarded_consumer(websocket: Any, handle_message: Callable[[Any], None],
                            message_class: Any) -> None:
    """viser's receive loop (``_message_consumer``) with :meth:`ClientGuard.admit` in front;
    never hands viser a frame the guard has not admitted (module doc)."""
    import websockets.exceptions

    route = route_of(handle_message)
    if route is None:
        await _refuse_all(websocket)
        return
    websock_server, client_id = route
    guard = await _wait_for_guard(websocket, websock_server, client_id)
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
        except Disconnect as exc:
            log.warning("client %s disconnected: %s", client_id, short(exc.reason, 200))
            guard.counts["disconnected"] += 1
            await websocket.close(exc.code, exc.reason[:120])
            await websocket.recv()  # raises ConnectionClosed: viser's handler tears down
            return
        if message is not None:
            handle_message(message)
        await asyncio.sleep(0)  # one client's backlog never holds the loop


GUARD_POLL_S = 0.05  # how often a connection waiting for its server's guard looks again


async def _wait_for_guard(websocket: Any, websock_server: Any, client_id: int) -> ClientGuard:
    """The server's guard; until one is attached (a browser that connected before the console
    was built, or a server that never gets one) the browser's frames stay unread.

    Raises:
        websockets.exceptions.ConnectionClosed: the browser left while waiting.
    """
    guard = guard_of(websock_server)
    if guard is not None:
        return guard
    log.warning("client %s: this server has no client guard attached (yet): its messages wait "
                "unread until one is (console.web fails closed)", client_id)
    wait_closed = getattr(websocket, "wait_closed", None)
    closed = None if wait_closed is None else asyncio.ensure_future(wait_closed())
    try:
        while guard is None:
            if closed is None:
                await asyncio.sleep(GUARD_POLL_S)
            else:
                await asyncio.wait({closed}, timeout=GUARD_POLL_S)
                if closed.done():
                    await websocket.recv()  # closed: raises ConnectionClosed, as viser expects
            guard = guard_of(websock_server)
    finally:
        if closed is not None:
            closed.cancel()
    return guard


async def _refuse_all(websocket: Any) -> None:
    """Read and drop every frame of a connection that cannot be traced to its server's guard
    (viser's ``handle_incoming`` no longer has :data:`ROUTE_NAMES`); says so once."""
    log.error("a browser's connection cannot be traced to its server (viser's handle_incoming "
              "lacks %s): every message it sends is refused (console.web fails closed)",
              list(ROUTE_NAMES))
    while True:
        await websocket.recv()  # dropped; ConnectionClosed ends the loop as viser's would


def install() -> bool:
    """Route every viser connection's receive loop through :func:`_guarded_consumer`.

    Changes upstream viser 1.1.1's ``viser.infra._infra._message_consumer`` (decode every frame
    and hand it to ``handle_incoming``, trusting the browser) for every server of the process.

    Raises:
        IncompatibleViser: viser's receive route is not the one :func:`check_route` expects
            (nothing is patched then).

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _infra

    if getattr(_infra._message_consumer, "_client_guard", False):
        return False
    check_route()
    consumer: Any = functools.wraps(_infra._message_consumer)(_guarded_consumer)
    consumer._client_guard = True
    _infra._message_consumer = consumer
    return True


def installed() -> bool:
    """Whether viser's receive loop is :func:`_guarded_consumer`."""
    from viser.infra import _infra

    return bool(getattr(_infra._message_consumer, "_client_guard", False))


def uninstall() -> bool:
    """Put viser's own receive loop back (tests); True if it was installed."""
    from viser.infra import _infra

    consumer: Any = _infra._message_consumer
    if not getattr(consumer, "_client_guard", False):
        return False
    _infra._message_consumer = consumer.__wrapped__
    return True
