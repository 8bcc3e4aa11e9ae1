"""A Foxglove client's bad frames, logged once per client and kind with the client's own address.

foxglove-sdk's server logs every frame it cannot parse at ERROR ("Invalid message from ADDR:
...", Python logger ``foxglove.websocket.connected_client``): one terminal line per frame, so a
buggy or hostile client floods the console's terminal, and ADDR is the relay's loopback socket
(:mod:`console.recording.foxglove_relay` connects to the SDK for each client), which says
nothing about who sent it. :class:`BadFrameLog` is a :class:`logging.Filter` on that logger: it
rewrites the first such line of each (client, kind) pair to name the client's real address and
drops the rest. A kind is the SDK's error with the parts that vary per frame removed (positions,
quoted names, numbers).
"""

from __future__ import annotations

import logging
import re
import threading
from typing import Callable

SDK_LOGGER = "foxglove.websocket.connected_client"
_INVALID = re.compile(r"Invalid message from (\S+): (.*)", re.DOTALL)
MAX_KEYS = 4096  # (client, kind) pairs remembered; past it the memory starts again


def kind_of(error: str) -> str:
    """The kind of an SDK parse error: without positions, quoted names and numbers."""
    text = re.sub(r" at line \d+ column \d+", "", error)
    text = re.sub(r"`[^`]*`", "`…`", text)
    text = re.sub(r"\d+", "#", text)
    return text[:120]


class BadFrameLog(logging.Filter):
    """Filters the SDK's "Invalid message" lines (see the module docstring).

    Args:
        client_of: The real address ("host:port") of the client behind a loopback address the
            SDK names, or None if unknown (then the SDK's address is kept).
    """

    def __init__(self, client_of: Callable[[str], str | None]) -> None:
        super().__init__()
        self.client_of = client_of
        self.suppressed = 0
        self._seen: set[tuple[str, str]] = set()
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            text = record.getMessage()
        except Exception:  # a record we cannot format is not ours to judge
            return True
        m = _INVALID.match(text)
        if m is None:
            return True
        client = self.client_of(m.group(1)) or m.group(1)
        key = (client, kind_of(m.group(2)))
        with self._lock:
            if key in self._seen:
                self.suppressed += 1
                return False
            if len(self._seen) >= MAX_KEYS:
                self._seen.clear()
            self._seen.add(key)
        record.msg = (f"Foxglove client {client} sent an invalid message: {m.group(2)} "
                      "(further ones of this kind from it are not logged)")
        record.args = ()
        return True

    def attach(self) -> None:
        logging.getLogger(SDK_LOGGER).addFilter(self)

    def detach(self) -> None:
        logging.getLogger(SDK_LOGGER).removeFilter(self)
