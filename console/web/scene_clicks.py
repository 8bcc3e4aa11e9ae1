"""Lets one tool take a browser's clicks on the 3D scene for a while, so other panels skip them.

Several panels act on a click on the table (Objects places an object, Control's "Click to
grasp" runs a grasp). When a browser starts a measurement (``console.panels.common.view``) its next
clicks must measure and do nothing else, while every other browser's clicks act as before.
viser 1.1.1 calls every registered scene-click callback for every click and has no way to stop
the others, so :class:`ClickClaims` wraps the click callbacks registered so far (again whenever
a browser is claimed, so panels added later are wrapped too): a wrapped callback skips a click
of a claimed browser. Which browser a click belongs to, and whether it was claimed, is decided
once per click (viser hands every callback the same event object), so a claim that ends on a
click never lets that same click through to another panel.

Relies on viser 1.1.1's ``SceneApi._scene_pointer_cb`` (a list of entries with ``callback``,
``event_type`` and ``event_class``); ``tests/console/test_view_panel.py`` checks it is there.
"""

from __future__ import annotations

import collections
import functools
import inspect
import threading
import time
from collections.abc import Callable
from typing import Any

import viser

CLAIM_S = 120.0     # a claim no click used for this long lapses (a forgotten measurement)


class ClickClaims:
    """Route the scene clicks of claimed browsers to ``handler`` and nowhere else.

    Args:
        server: The viser server whose scene clicks to route.
        handler: Called (on a viser worker thread) with each click of a claimed browser,
            exactly once per click.
    """

    def __init__(self, server: viser.ViserServer,
                 handler: Callable[[viser.SceneClickEvent], None]) -> None:
        self._scene = server.scene
        self._handler = handler
        self._lock = threading.Lock()
        self._claimed: dict[int, float] = {}          # client id -> when claimed (monotonic)
        self._recent: collections.deque = collections.deque(maxlen=64)  # (event, taken)
        self._scene.on_click()(self._own)             # clicks reach us even if nobody else asks
        server.on_client_disconnect(lambda client: self.release(client.client_id))
        self.wrap_existing()

    def claim(self, client_id: int) -> None:
        """From now on this browser's clicks go to the handler only (until :meth:`release`)."""
        self.wrap_existing()
        with self._lock:
            self._claimed[client_id] = time.monotonic()

    def release(self, client_id: int) -> None:
        with self._lock:
            self._claimed.pop(client_id, None)

    def claimed(self, client_id: int) -> bool:
        with self._lock:
            return self._live(client_id)

    def _live(self, client_id: int) -> bool:
        since = self._claimed.get(client_id)
        if since is None:
            return False
        if time.monotonic() - since > CLAIM_S:
            del self._claimed[client_id]
            return False
        return True

    def taken(self, event: Any) -> bool:
        """Whether ``event`` belongs to a claimed browser; the first call for an event decides
        (and hands the event to the handler), later calls for the same event repeat it."""
        with self._lock:
            for seen, taken in self._recent:
                if seen is event:
                    return taken
            taken = self._live(event.client_id)
            self._recent.append((event, taken))
        if taken:
            self._handler(event)
        return taken

    def _own(self, event: viser.SceneClickEvent) -> None:
        self.taken(event)

    def wrap_existing(self) -> int:
        """Wrap the click callbacks not wrapped yet; returns how many were wrapped."""
        wrapped = 0
        for entry in list(self._scene._scene_pointer_cb):
            cb = entry.callback
            if (entry.event_type != "click" or entry.event_class is not viser.SceneClickEvent
                    or getattr(cb, "_claims", None) is self or cb == self._own):
                continue
            entry.callback = self._wrap(cb)
            wrapped += 1
        return wrapped

    def _wrap(self, cb: Callable[[Any], Any]) -> Callable[[Any], Any]:
        if inspect.iscoroutinefunction(cb):
            @functools.wraps(cb)
            async def async_unless_taken(event: Any) -> Any:
                if not self.taken(event):
                    return await cb(event)
                return None

            async_unless_taken._claims = self  # type: ignore[attr-defined]
            return async_unless_taken

        @functools.wraps(cb)
        def unless_taken(event: Any) -> Any:
            if not self.taken(event):
                return cb(event)
            return None

        unless_taken._claims = self  # type: ignore[attr-defined]
        return unless_taken
