"""The list of every change ``console.web`` makes to viser, each with its check and its undo.

``console.web.install`` applies them in order (the receive guard first: it checks viser's
receive route and may refuse, before anything else is patched); ``installed`` asks each whether
it is in place, ``uninstall`` undoes them in reverse. Each patch's module says which upstream
viser 1.1.1 behaviour it changes and why.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from console.web import (callback_pool, receive_guard, resting_redraw, shared_sends,
                         shared_windows, viewer_props)


@dataclasses.dataclass(frozen=True)
class Patch:
    """One change to viser: its name, how to apply it, whether it is applied, how to undo it.

    ``apply`` and ``undo`` return whether they changed anything (both are idempotent).
    """

    name: str
    apply: Callable[[], bool]
    applied: Callable[[], bool]
    undo: Callable[[], bool]


#: Every patch, in the order they are applied.
PATCHES: tuple[Patch, ...] = (
    Patch("client guard in front of _message_consumer", receive_guard.install,
          receive_guard.installed, receive_guard.uninstall),
    Patch("loop-safe AsyncMessageBuffer events", shared_sends.loop_safe_events,
          shared_sends.events_are_loop_safe, shared_sends.upstream_events),
    Patch("Message.as_serializable_dict shared by clients", shared_sends.share_wire_dicts,
          shared_sends.wire_dicts_shared, shared_sends.unshare_wire_dicts),
    Patch("_message_producer frames shared by clients", shared_sends.share_frames,
          shared_sends.frames_shared, shared_sends.unshare_frames),
    Patch("AsyncMessageBuffer._window_loop windows shared by clients", shared_windows.install,
          shared_windows.installed, shared_windows.uninstall),
    Patch("AsyncMessageBuffer.window_generator: viewers get operator-only widgets disabled",
          viewer_props.install, viewer_props.installed, viewer_props.uninstall),
    Patch("ViserServer's callback pool: idle workers end", callback_pool.install,
          callback_pool.installed, callback_pool.uninstall),
    Patch("WebsockServer.start: viser's page with its 1 s redraw resting while still",
          resting_redraw.install, resting_redraw.installed, resting_redraw.uninstall),
)
