"""Who sent a viser event and what it is about, for callbacks that take more than one event kind.

A panel's ``on_refused`` gets whatever event a refused callback got (``GuiEvent``,
``TransformControlsEvent``, ``SceneClickEvent``, ...), and a future's report may have no event at
all; not every kind has a ``target``. :func:`client_of` and :func:`target_of` narrow such an
event through typed Protocols (checked at run time), so callers neither ``getattr`` nor ignore
types.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import viser


@runtime_checkable
class FromClient(Protocol):
    """An event a browser (or the server itself: None) sent; every viser event kind is one."""

    @property
    def client(self) -> viser.ClientHandle | None: ...


@runtime_checkable
class OnTarget(Protocol):
    """An event about one handle (a GUI input, a gizmo, a scene node); a scene click is not."""

    @property
    def target(self) -> object: ...


def client_of(event: object) -> viser.ClientHandle | None:
    """The client that sent ``event`` (None: no event, or one the server sent itself)."""
    return event.client if isinstance(event, FromClient) else None


def target_of(event: object) -> object | None:
    """The handle ``event`` is about (None: no event, or one about no handle)."""
    return event.target if isinstance(event, OnTarget) else None


def connected(server: viser.ViserServer, client: viser.ClientHandle) -> bool:
    """Whether ``client`` is still one of ``server``'s browsers. viser drops a client from its
    list first thing when it disconnects, then runs the disconnect callbacks; a connect callback
    (run in viser's thread pool) that built per-browser widgets for a browser that left
    meanwhile checks this afterwards, or what it built outlives the browser."""
    return client.client_id in server.get_clients()
