"""Closes viser's share tunnel on a console server: hiding its button leaves it one message away.

viser 1.1.1's ``ViserServer.__init__`` registers handlers for the browser's
``ShareUrlRequest`` / ``ShareUrlDisconnect`` on its ``WebsockServer`` (``_incoming_handlers``):
any websocket client could send ``ShareUrlRequest`` and viser would open a public tunnel to the
internet (``ViserServer.request_share_url``). :func:`disable_share_tunnel` drops those handlers
and makes the method a no-op on one server. (The client guard also refuses both message types:
this is the second wall.)
"""

from __future__ import annotations

from typing import Any

import viser


def disable_share_tunnel(server: viser.ViserServer) -> None:
    """Make viser's share tunnel impossible on ``server``, not only hidden.

    Changes upstream viser 1.1.1: ``WebsockMessageHandler._incoming_handlers`` of the server's
    ``WebsockServer`` loses its ``ShareUrlRequest`` and ``ShareUrlDisconnect`` handlers, and
    ``ViserServer.request_share_url`` does nothing.
    """
    from viser import _messages

    handlers: dict[Any, Any] = getattr(server._websock_server, "_incoming_handlers", {})
    for cls in (_messages.ShareUrlRequest, _messages.ShareUrlDisconnect):
        handlers.pop(cls, None)
    server.request_share_url = lambda *a, **k: None  # type: ignore[method-assign]


def share_handlers(server: viser.ViserServer) -> int:
    """How many share-tunnel message handlers ``server`` has registered (0 once disabled)."""
    from viser import _messages

    handlers: dict[Any, Any] = getattr(server._websock_server, "_incoming_handlers", {})
    return sum(len(handlers.get(cls, ())) for cls in (_messages.ShareUrlRequest,
                                                       _messages.ShareUrlDisconnect))
