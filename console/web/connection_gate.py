"""Connection limits in front of viser's per-client set-up, so a flood of sockets builds nothing.

viser 1.1.1 builds a ``ClientHandle`` (a GUI and a scene API of its own, a camera handler, and
on its first camera message every console panel's per-browser widgets) in the connect callbacks
of its ``WebsockServer`` for every websocket that completes the handshake, and tears it down in
the disconnect callbacks. A thousand sockets opened from one address grew ``serve.py`` by ~0.7 MB
each. :class:`ConnectionGate` takes the callbacks registered on the ``WebsockServer`` so far
(viser registers its own in ``ViserServer.__init__``) and puts one gated callback of its own in
their place: a connection over the limits (:class:`ConnectionLimits`: per address, in all) is
closed with code 1008 and a reason saying which limit, before any of viser's callbacks ran, so
no client handle, GUI or panel state exists for it and its disconnect runs none of them either.
:data:`TRIM_AFTER_S` after the last of a batch of browsers left, the memory their connections used is handed back to the
system (:func:`release_free_memory`).

Addresses for which ``privileged(address)`` is true (the console's: loopback, and the address
the operator's browser connects from) are never refused and count towards no limit, so others'
sockets cannot lock the operator or the machine's own browser out. Refusals are logged once per
address and ``log_every`` seconds, with how many were refused since. Everything runs on viser's
event loop thread (the callbacks' thread); the counts are read by tests and benchmarks.
"""

from __future__ import annotations

import asyncio
import collections
import ctypes
import ctypes.util
import dataclasses
import functools
import gc
import inspect
import ipaddress
import logging
import threading
import time
from typing import Any, Callable

from console.web import IncompatibleViser

log = logging.getLogger(__name__)

_GATE = "_console_connection_gate"  # where a viser WebsockServer keeps its gate
#: Seconds after a browser left before the memory its connection used is handed back.
TRIM_AFTER_S = 2.0
TRIM_AT_MOST_S = 10.0  # ... and at the latest this long after the first of them left
#: Seconds after a connection closed at which viser is checked for a client it registered late.
REAP_AFTER_S = (0.5, 5.0)


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim`` (None elsewhere)."""
    name = ctypes.util.find_library("c")
    try:
        return getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
    except OSError:
        return None


def release_free_memory() -> bool:
    """Collect the garbage and hand the C allocator's free memory back to the system (glibc's
    ``malloc_trim``; it releases the GIL while it runs); whether it could. A browser's connection allocates its
    messages and compression buffers in the thread that served it; freed, glibc keeps them in
    that thread's arena, so after 40 browsers left ``serve.py`` stayed ~50 MB above where it
    was (tests/console/test_connection_flood.py)."""
    gc.collect()  # a browser's client handle and widgets are reference cycles: free them first
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True


@dataclasses.dataclass(frozen=True)
class ConnectionLimits:
    """How many websocket connections the console serves.

    Attributes:
        per_address: Connections from one remote address (host) at once.
        total: Connections in all at once (privileged addresses not counted).
        log_every: Seconds between two log lines about one address's refusals.
    """

    per_address: int = 20
    total: int = 200
    log_every: float = 60.0

    def __post_init__(self) -> None:
        if self.per_address < 1 or self.total < 1:
            raise ValueError(f"connection limits must be at least 1, got per address "
                             f"{self.per_address}, in all {self.total}")


def is_loopback(address: str | None) -> bool:
    """Whether ``address`` is this machine's (127.0.0.0/8, ::1, or IPv4-mapped loopback)."""
    if not address:
        return False
    try:
        ip = ipaddress.ip_address(address.split("%", 1)[0])
    except ValueError:
        return False
    mapped = getattr(ip, "ipv4_mapped", None)
    return bool(ip.is_loopback or (mapped is not None and mapped.is_loopback))


def gate_of(websock_server: Any) -> ConnectionGate | None:
    """The gate on a viser ``WebsockServer`` (``server._websock_server``), or None."""
    gate = getattr(websock_server, _GATE, None)
    return gate if isinstance(gate, ConnectionGate) else None


class ConnectionGate:
    """Refuses connections over the limits before viser sets a client up (module docstring).

    Args:
        server: The viser server (its ``WebsockServer``'s callbacks registered so far are gated).
        limits: The limits.
        privileged: ``privileged(address)``: an address never refused (default: loopback).
        clock: Monotonic time of the log coalescing.

    Raises:
        IncompatibleViser: viser's ``WebsockServer`` has no callback lists where 1.1.1 has them.
    """

    def __init__(self, server: Any, limits: ConnectionLimits | None = None, *,
                 privileged: Callable[[str | None], bool] = is_loopback,
                 clock: Callable[[], float] = time.monotonic) -> None:
        ws = server._websock_server
        lists = (getattr(ws, "_client_connect_cb", None), getattr(ws, "_client_disconnect_cb", None),
                 getattr(ws, "_live_connections", None))
        if not (isinstance(lists[0], list) and isinstance(lists[1], list)
                and isinstance(lists[2], dict)
                and isinstance(getattr(server, "_connected_clients", None), dict)):
            raise IncompatibleViser("viser's WebsockServer has no _client_connect_cb / "
                                    "_client_disconnect_cb lists or _live_connections dict, or "
                                    "its ViserServer no _connected_clients: the connection gate "
                                    "cannot go in front of its client set-up")
        self.limits = limits or ConnectionLimits()
        self._ws = ws
        self._privileged = privileged
        self._clock = clock
        self._connect = tuple(lists[0])
        self._disconnect = tuple(lists[1])
        self._admitted: dict[int, str | None] = {}  # client id -> address (None: privileged)
        self._per_address: collections.Counter[str | None] = collections.Counter()
        before = gate_of(ws)
        if before is not None:  # a second console on the same server: it takes the gate over
            self._connect, self._disconnect = before._connect, before._disconnect
            self._admitted, self._per_address = before._admitted, before._per_address
        self._logged: dict[str | None, list[float]] = {}  # address -> [last line at, refused since]
        self.refused = 0
        #: ``closed(client_id)`` for every connection that closed, admitted or refused (the
        #: client guard forgets its rate state: a frame read before the close created it).
        self.closed: list[Callable[[int], None]] = []
        self._server = server
        self._trim: asyncio.TimerHandle | None = None
        self._trim_first = 0.0
        lists[0][:] = [self._on_connect]
        lists[1][:] = [self._on_disconnect]
        setattr(ws, _GATE, self)

    @property
    def admitted(self) -> int:
        """Connections admitted and not yet closed (privileged ones included)."""
        return len(self._admitted)

    def counted(self, address: str | None = None) -> int:
        """Connections counted towards the limits: from ``address``, or in all (None)."""
        if address is not None:
            return self._per_address[address]
        return sum(n for a, n in self._per_address.items() if a is not None)

    def refusal(self, address: str | None) -> str | None:
        """Why a new connection from ``address`` is refused now, or None (admitted)."""
        if self._privileged(address):
            return None
        lim = self.limits
        if self._per_address[address] >= lim.per_address:
            return f"too many connections from {address} (limit {lim.per_address} per address)"
        if self.counted() >= lim.total:
            return f"the console serves at most {lim.total} connections"
        return None

    def _address(self, client_id: int) -> str | None:
        conn = self._ws._live_connections.get(client_id)
        try:
            return None if conn is None else str(conn.remote_address[0])
        except (TypeError, IndexError, AttributeError):
            return None

    async def _on_connect(self, conn: Any) -> None:
        cid = conn.client_id
        address = self._address(cid)
        reason = self.refusal(address)
        if reason is not None:
            self.refused += 1
            self._log(address, reason)
            live = self._ws._live_connections.get(cid)
            if live is not None:
                await live.close(1008, reason[:120])
            return
        counted = None if self._privileged(address) else address
        self._admitted[cid] = counted
        if counted is not None:
            self._per_address[counted] += 1
        await _call_each(self._connect, conn)

    async def _on_disconnect(self, conn: Any) -> None:
        cid = conn.client_id
        for forget in self.closed:
            forget(cid)
        if cid not in self._admitted:
            return  # refused: none of viser's set-up ran, so none of its teardown runs
        counted = self._admitted.pop(cid)
        if counted is not None:
            self._per_address[counted] -= 1
            if self._per_address[counted] <= 0:
                del self._per_address[counted]
        await _call_each(self._disconnect, conn)
        loop = asyncio.get_running_loop()
        for after in REAP_AFTER_S:
            loop.call_later(after, self._reap, conn)
        # TRIM_AFTER_S after the last browser left, or TRIM_AT_MOST_S after the first one
        # that left since the last release (a flood that goes on does not put it off for ever).
        now = loop.time()
        if self._trim is None:
            self._trim_first = now
        elif now - self._trim_first < TRIM_AT_MOST_S:
            self._trim.cancel()
        else:
            return
        self._trim = loop.call_later(TRIM_AFTER_S, self._release)

    def _reap(self, conn: Any) -> None:
        """A browser's first camera message is handled in a task of its own, which can run
        after its connection closed: viser then registers a client (and runs every per-browser
        set-up of the console) that nothing will ever disconnect. Its teardown, once more."""
        cid = conn.client_id
        if cid not in self._admitted and cid in self._server._connected_clients:
            asyncio.ensure_future(_call_each(self._disconnect, conn))

    def _release(self) -> None:
        self._trim = None
        threading.Thread(target=release_free_memory, name="release-memory", daemon=True).start()

    def _log(self, address: str | None, reason: str) -> None:
        now = self._clock()
        entry = self._logged.setdefault(address, [-1e18, 0])
        entry[1] += 1
        if now - entry[0] < self.limits.log_every:
            return
        more = f" ({entry[1]} refused since the last line)" if entry[1] > 1 else ""
        log.warning("connection refused: %s%s", reason, more)
        entry[0], entry[1] = now, 0
        for stale in [a for a, (at, n) in self._logged.items()
                      if n == 0 and now - at >= self.limits.log_every]:
            del self._logged[stale]  # (an address that stopped trying is forgotten)


async def _call_each(callbacks: tuple[Callable[[Any], Any], ...], conn: Any) -> None:
    """viser's way: await coroutine functions, call the others, in order."""
    for cb in callbacks:
        if inspect.iscoroutinefunction(cb):
            await cb(conn)
        else:
            cb(conn)
