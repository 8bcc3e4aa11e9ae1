"""Viewers' browsers show the operator's controls disabled, though viser 1.1.1 broadcasts one GUI.

Upstream viser 1.1.1 keeps the shared GUI (``server.gui``) in one broadcast buffer
(``WebsockServer._broadcast_buffer``) that every client's producer reads unchanged: a handle's
``disabled`` is the same in every browser, so a viewer saw Plan grasp, Arm and Execute enabled
and learnt only from a refusal after clicking.

:func:`install` wraps ``AsyncMessageBuffer.window_generator``: on a persistent (broadcast)
buffer that carries a :class:`ViewerProps` (the client guard attaches one), each window a
client takes goes through :meth:`ViewerProps.window_for` on its way out. For a connection that
does not hold control, every message that sets a shared widget's ``disabled`` (its creation
message's props, a ``GuiUpdateMessage`` / ``CommandUpdateMessage``) is swapped for a copy with
``disabled=True`` unless the widget is one viewers may use
(``console.web.client_message_checks.MessageTypeChecks.viewer_may_use``: the very rule that
refuses viewers' messages, so there is one list). The operator's connection gets the messages
as they are: a panel's own disable / enable (Execute while busy) reaches it unchanged.

A change of holder calls :meth:`ViewerProps.resend`: each operator-only widget's true
``disabled`` is broadcast again, and the filter, applied per connection at send time, turns it
into the right value for each browser (the new operator's enabled, the old one's disabled).
Because the correction travels in the same ordered stream as every other GUI message, no
earlier message can overtake it. A role that cannot be read counts as a viewer (fails closed).

The 3D view's drag gizmos (transform controls: the objects', the bin's, the obstacles', the
extensible arm's tip target) only ever move things for the operator: for viewers a gizmo's
creation message and any later update of its handles (``SceneNodeUpdateMessage`` of
``disable_axes`` / ``disable_sliders`` / ``disable_rotations``) go out with all three handles
disabled, so a viewer's browser draws the gizmo without anything to drag. :meth:`resend` sends
the gizmos' true handles again too.

The server's state is never changed: ``handle.disabled`` stays the panel's own truth. Per-client
buffers (a browser's own widgets) are not filtered. Nothing is applied on import
(``console.web.install`` applies it; :func:`uninstall` undoes it for tests).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from collections.abc import AsyncGenerator, Callable, Sequence
from typing import Any

log = logging.getLogger(__name__)

_FILTER = "_console_viewer_props"  # on a broadcast buffer: its ViewerProps
_VIEWER_FORM = "_console_viewer_form"  # on a message: its form for viewers (shared by all)
_UPDATES = frozenset({"GuiUpdateMessage", "CommandUpdateMessage"})
_GIZMO = "TransformControlsMessage"
_GIZMO_HANDLES = ("disable_axes", "disable_sliders", "disable_rotations")  # all True: none


class ViewerProps:
    """The per-connection view of the shared GUI's ``disabled`` props (see the module docstring).

    Args:
        server: The viser server whose broadcast buffer it filters (it attaches itself).
        viewer_may_use: ``viewer_may_use(uuid)``: whether viewers may use that shared widget.
        is_operator: ``is_operator(client_id)``: whether that connection holds control.
    """

    def __init__(self, server: Any, *, viewer_may_use: Callable[[str], bool],
                 is_operator: Callable[[int], bool]) -> None:
        self.server = server
        self._viewer_may_use = viewer_may_use
        self._is_operator = is_operator
        buffer = server._websock_server._broadcast_buffer
        setattr(buffer, _FILTER, self)

    # -- per connection (event-loop thread) --------------------------------------------------

    def operator(self, client_id: int) -> bool:
        """Whether ``client_id`` holds control; False when that cannot be read (fails closed)."""
        try:
            return bool(self._is_operator(client_id))
        except Exception:  # a role nobody can read is a viewer's
            log.exception("role of client %s unreadable: treated as a viewer", client_id)
            return False

    def window_for(self, client_id: int, window: Sequence[Any]) -> Sequence[Any]:
        """``window`` as connection ``client_id`` is to receive it (the same object if unchanged)."""
        if self.operator(client_id):
            return window
        out: list[Any] | None = None
        for i, message in enumerate(window):
            viewer = self.viewer_form(message)
            if viewer is not message:
                if out is None:
                    out = list(window)
                out[i] = viewer
        return window if out is None else out

    def viewer_form(self, message: Any) -> Any:
        """``message`` as viewers receive it: with ``disabled=True`` if it would enable an
        operator-only widget, else ``message`` itself. The copy is kept on the message, so every
        viewer gets the same object (and ``console.web.shared_sends`` one frame for them all)."""
        kept = message.__dict__.get(_VIEWER_FORM)
        if kept is not None:
            return kept
        kind = type(message).__name__
        uuid = getattr(message, "uuid", None)
        form = message
        if kind == _GIZMO or kind == "SceneNodeUpdateMessage":
            form = self._gizmo_form(message, kind)
        elif not isinstance(uuid, str):
            return message
        elif kind in _UPDATES:
            updates = message.updates
            if ("disabled" in updates and not updates["disabled"]
                    and not self._may_use(uuid)):
                form = type(message)(uuid, {**updates, "disabled": True})
        else:
            props = getattr(message, "props", None)
            if (props is not None and dataclasses.is_dataclass(props)
                    and getattr(props, "disabled", True) is False and not self._may_use(uuid)):
                form = _replaced(message, props=dataclasses.replace(props, disabled=True))
        if form is message:
            return message
        form.excluded_self_client = message.excluded_self_client
        message.__dict__[_VIEWER_FORM] = form
        return form

    def _gizmo_form(self, message: Any, kind: str) -> Any:
        """A transform control's creation or update as viewers get it: no handle to drag."""
        name = getattr(message, "name", None)
        if not isinstance(name, str):
            return message
        if kind == _GIZMO:
            props = message.props
            if all(getattr(props, h, True) for h in _GIZMO_HANDLES):
                return message
            return _replaced(message, props=dataclasses.replace(
                props, **{h: True for h in _GIZMO_HANDLES}))
        updates = message.updates
        if not any(h in updates and not updates[h] for h in _GIZMO_HANDLES) \
                or name not in self.server.scene._handle_from_transform_controls_name:
            return message
        return _replaced(message, updates={**updates, **{h: True for h in _GIZMO_HANDLES
                                                          if h in updates}})

    def _may_use(self, uuid: str) -> bool:
        try:
            return bool(self._viewer_may_use(uuid))
        except Exception:  # a policy nobody can read keeps the widget the operator's
            log.exception("viewer policy of %s unreadable: operator-only", uuid)
            return False

    # -- changes (any thread) ------------------------------------------------------------------

    def resend(self, uuids: Sequence[str] | None = None) -> int:
        """Broadcast the true ``disabled`` of the shared widgets (all, or ``uuids``) once more,
        and, when all are resent, the drag gizmos' true handles, for each connection to receive
        its own form of it (after a change of holder, or of the viewer policy). Returns the
        messages queued."""
        from viser import _messages

        gui = self.server.gui
        handles = {**gui._gui_input_handle_from_uuid, **gui._command_handle_from_uuid}
        chosen = handles if uuids is None else {u: handles[u] for u in uuids if u in handles}
        queue = gui._websock_interface.queue_message
        sent = 0
        with self.server.atomic():
            for uuid, handle in chosen.items():
                impl = handle._impl
                disabled = getattr(impl.props, "disabled", None)
                if impl.removed or disabled is None:
                    continue
                command = uuid in gui._command_handle_from_uuid
                make = _messages.CommandUpdateMessage if command else _messages.GuiUpdateMessage
                queue(make(uuid, {"disabled": bool(disabled)}))
                sent += 1
            if uuids is None:
                sent += self._resend_gizmos()
        return sent

    def _resend_gizmos(self) -> int:
        """Queue each shared transform control's true handles (in ``server.atomic()``)."""
        from viser import _messages

        scene = self.server.scene
        gizmos = dict(scene._handle_from_transform_controls_name)
        for name, handle in gizmos.items():
            scene._queue_scene_message(_messages.SceneNodeUpdateMessage(
                name, {h: bool(getattr(handle, h)) for h in _GIZMO_HANDLES}))
        return len(gizmos)


def _replaced(message: Any, **changes: Any) -> Any:
    """A copy of a viser message dataclass with ``changes`` (its non-init stamps kept)."""
    copy = dataclasses.replace(message, **changes)
    for field in dataclasses.fields(message):
        if not field.init:
            setattr(copy, field.name, getattr(message, field.name))
    return copy


def props_filter_of(buffer: Any) -> ViewerProps | None:
    """The :class:`ViewerProps` attached to a viser message buffer, or None."""
    found = buffer.__dict__.get(_FILTER)
    return found if isinstance(found, ViewerProps) else None


async def _filtered(buffer: Any, client_id: int,
                    inner: AsyncGenerator[Sequence[Any], None]
                    ) -> AsyncGenerator[Sequence[Any], None]:
    try:
        async for window in inner:
            props = props_filter_of(buffer)
            yield window if props is None else props.window_for(client_id, window)
    finally:
        await inner.aclose()


def install() -> bool:
    """Filter every broadcast buffer's windows per connection (:class:`ViewerProps`).

    Wraps ``viser.infra._async_message_buffer.AsyncMessageBuffer.window_generator`` (upstream
    1.1.1: the same windows for every client). Buffers without a :class:`ViewerProps`, and
    per-client buffers, are passed through unchanged.

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if getattr(cls, "_viewer_props", False):
        return False
    original = cls.window_generator

    @functools.wraps(original)
    def window_generator(self: Any, client_id: int, backlog_done_message: Any = None
                         ) -> AsyncGenerator[Sequence[Any], None]:
        inner = original(self, client_id, backlog_done_message=backlog_done_message)
        if not self.persistent_messages:  # a browser's own buffer: its own widgets
            return inner
        return _filtered(self, client_id, inner)

    cls.window_generator = window_generator
    cls._viewer_props = True
    return True


def installed() -> bool:
    """Whether :func:`install` is in place."""
    from viser.infra import _async_message_buffer as amb

    return bool(getattr(amb.AsyncMessageBuffer, "_viewer_props", False))


def uninstall() -> bool:
    """Undo :func:`install` for generators created from now on (tests); True if it was in place."""
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if not getattr(cls, "_viewer_props", False):
        return False
    cls.window_generator = cls.window_generator.__wrapped__
    del cls._viewer_props
    return True
