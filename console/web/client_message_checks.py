"""The client guard's checks per message type: the widget, its value, and who may use it.

:class:`console.web.client_guard.ClientGuard` limits size and rate and decodes a frame (rules 1 and
2), then calls ``_check_<MessageType>`` of this mixin for it, if there is one: rule 3 (the value,
via :func:`console.web.client_values.validate_value`) and rule 4 (the access policy: shared widgets
are the operator's unless marked with ``allow_viewers``). Each returns True to pass the message
on to viser, False when it was handled here (a viewer's edit refused and its value sent back, a
value out of bounds not stored), or raises :class:`~console.web.client_values.Refused` (invalid).
"""

from __future__ import annotations

import collections
import dataclasses
from collections.abc import Callable
from typing import Any

from console.web.client_values import GuardLimits, OutOfBounds, Refused, short, validate_value

_UPLOAD_CHUNK = 512 * 1024  # viser's browser uploads files in parts of this size


@dataclasses.dataclass
class ClientState:
    """Per-connection bookkeeping (event-loop thread only): the rate bucket, recent drops and
    the uploads this browser started (kept here, beside the checks that read it)."""

    tokens: float
    last: float
    drops: collections.deque = dataclasses.field(default_factory=collections.deque)
    uploads: set = dataclasses.field(default_factory=set)


class MessageTypeChecks:
    """``_check_<MessageType>`` for :class:`console.web.client_guard.ClientGuard` (its base class),
    on the guard's state below (event-loop thread only)."""

    server: Any
    limits: GuardLimits
    counts: collections.Counter[str]
    _is_operator: Callable[[int], bool]
    _refuse: Callable[[Any, str, str], None]
    _refusal: Callable[[str], str]
    _viewer_allowed: set[str]
    log: Callable[[int, str, str], None]  # ClientGuard.log: one warning per client and kind

    # -- per message type (True: pass on; False: handled here; Refused: invalid) --------------

    def _client(self, client_id: int) -> Any:
        return self.server._connected_clients.get(client_id)

    def _gui_handle(self, client_id: int, uuid: str, registry: str) -> tuple[Any, bool]:
        """(handle, shared) for a GUI element of the server's or this browser's GUI."""
        handle = getattr(self.server.gui, registry).get(uuid)
        if handle is not None:
            return handle, True
        client = self._client(client_id)
        if client is not None:
            handle = getattr(client.gui, registry).get(uuid)
        return handle, False

    def viewer_may_use(self, key: str) -> bool:
        """Whether viewers may use the shared widget ``key`` (uuid, or a gizmo's name): rule 4's
        one list, read here for what browsers send and by ``console.web.viewer_props`` for what
        they are shown (the others are drawn disabled for viewers)."""
        return key in self._viewer_allowed

    def _may_use(self, client_id: int, handle: Any, shared: bool, key: str) -> bool:
        return not shared or self.viewer_may_use(key) or self._is_operator(client_id)

    def _refuse_use(self, client_id: int, handle: Any, label: str, is_button: bool) -> None:
        self.counts["refused"] += 1
        verb = "press" if is_button else "change"
        action = _action_of(handle) or f"{verb} “{label}”"
        self.log(client_id, "refused", f"viewer refused: {action}")
        client = self._client(client_id)
        if client is not None:
            self._refuse(client, self._refusal(action), action)

    def _check_GuiUpdateMessage(self, client_id: int, state: ClientState, msg: Any) -> bool:
        updates = msg.updates
        if not isinstance(updates, dict) or set(updates) != {"value"}:
            keys = list(updates) if isinstance(updates, dict) else updates
            raise Refused(f"only 'value' may be sent, got {short(keys)}")
        handle, shared = self._gui_handle(client_id, msg.uuid, "_gui_input_handle_from_uuid")
        if handle is None:
            raise Refused(f"no input widget {short(msg.uuid)}")
        impl = handle._impl
        props = impl.props
        label = str(getattr(props, "label", type(handle).__name__))[:40]
        if impl.removed or getattr(props, "disabled", False) or not getattr(props, "visible", 1):
            self.log(client_id, "inactive", f"“{label}” is disabled or hidden")
            return False
        if not self._may_use(client_id, handle, shared, impl.uuid):
            self._restore(client_id, handle)
            self._refuse_use(client_id, handle, label, impl.is_button)
            return False
        try:
            value = validate_value(handle, updates["value"], self.limits)
        except OutOfBounds as exc:
            self.counts["invalid"] += 1
            self.log(client_id, "bounds", f"“{label}”: {exc}")
            return False
        except Refused as exc:
            self._restore(client_id, handle)
            self.counts["invalid"] += 1
            self.log(client_id, "invalid", f"“{label}”: {exc}")
            client = self._client(client_id)
            if client is not None:
                self._refuse(client, f"“{label}”: {exc}", f"value for {label}")
            return False
        msg.updates = {"value": value}
        return True

    def _restore(self, client_id: int, handle: Any) -> None:
        """Send this browser (only) its widget's current value back."""
        from viser import _messages

        client = self._client(client_id)
        impl = handle._impl
        if client is None or impl.is_button or type(handle).__name__ == "GuiUploadButtonHandle":
            return
        client._websock_connection.queue_message(
            _messages.GuiUpdateMessage(impl.uuid, {"value": impl.value}))

    def _check_GuiButtonHoldMessage(self, client_id: int, state: ClientState, msg: Any) -> bool:
        handle, shared = self._gui_handle(client_id, msg.uuid, "_gui_input_handle_from_uuid")
        if handle is None or not handle._impl.is_button:
            raise Refused(f"no button {short(msg.uuid)}")
        if not 0.0 < float(msg.frequency) <= 100.0:
            raise Refused(f"hold frequency {short(msg.frequency)}")
        if getattr(handle._impl.props, "disabled", False):
            return False
        if not self._may_use(client_id, handle, shared, handle._impl.uuid):
            self._refuse_use(client_id, handle, _label(handle), True)
            return False
        return True

    def _check_CommandTriggerMessage(self, client_id: int, state: ClientState, msg: Any) -> bool:
        handle, shared = self._gui_handle(client_id, msg.uuid, "_command_handle_from_uuid")
        if handle is None:
            raise Refused(f"no command {short(msg.uuid)}")
        if not self._may_use(client_id, handle, shared, handle._impl.uuid):
            self._refuse_use(client_id, handle, _label(handle), True)
            return False
        return True

    def _gizmo(self, client_id: int, name: str) -> tuple[Any, bool]:
        handle = self.server.scene._handle_from_transform_controls_name.get(name)
        if handle is not None:
            return handle, True
        client = self._client(client_id)
        return (None if client is None else
                client.scene._handle_from_transform_controls_name.get(name)), False

    def _check_TransformControlsUpdateMessage(self, client_id: int, state: ClientState,
                                              msg: Any) -> bool:
        handle, shared = self._gizmo(client_id, msg.name)
        if handle is None:
            raise Refused(f"no transform control {short(msg.name)}")
        if len(msg.wxyz) != 4 or len(msg.position) != 3 or not any(msg.wxyz):
            raise Refused("pose must be a unit quaternion and a 3-vector")
        if max(abs(float(p)) for p in msg.position) > 100.0:
            raise Refused(f"position {short(msg.position)} is off the scene")
        if not self._may_use(client_id, handle, shared, msg.name):
            self._restore_gizmo(client_id, handle, msg)
            self._refuse_use(client_id, handle, msg.name, False)
            return False
        return True

    def _restore_gizmo(self, client_id: int, handle: Any, msg: Any) -> None:
        from viser import _messages

        client = self._client(client_id)
        if client is None:
            return
        for out in (_messages.SetPositionMessage(msg.name, tuple(map(float, handle.position))),
                    _messages.SetOrientationMessage(msg.name, tuple(map(float, handle.wxyz)))):
            out.owner = msg.owner  # type: ignore[attr-defined]
            client._websock_connection.queue_message(out)

    def _check_gizmo_phase(self, client_id: int, msg: Any) -> bool:
        handle, shared = self._gizmo(client_id, msg.name)
        if handle is None:
            raise Refused(f"no transform control {short(msg.name)}")
        return self._may_use(client_id, handle, shared, msg.name)

    def _check_TransformControlsDragStartMessage(self, client_id: int, state: ClientState,
                                                 msg: Any) -> bool:
        return self._check_gizmo_phase(client_id, msg)

    def _check_TransformControlsDragEndMessage(self, client_id: int, state: ClientState,
                                               msg: Any) -> bool:
        return self._check_gizmo_phase(client_id, msg)

    def _check_FileTransferStartUpload(self, client_id: int, state: ClientState,
                                       msg: Any) -> bool:
        handle, shared = self._gui_handle(client_id, msg.source_component_uuid,
                                          "_gui_input_handle_from_uuid")
        if handle is None or type(handle).__name__ != "GuiUploadButtonHandle":
            raise Refused(f"no upload button {short(msg.source_component_uuid)}")
        size, parts = int(msg.size_bytes), int(msg.part_count)
        if not 0 <= size <= self.limits.max_upload_bytes:
            raise Refused(f"file of {size} bytes (at most {self.limits.max_upload_bytes})")
        if not 0 <= parts <= size // _UPLOAD_CHUNK + 1:
            raise Refused(f"{parts} parts for {size} bytes")
        if not self._may_use(client_id, handle, shared, handle._impl.uuid):
            self._refuse_use(client_id, handle, _label(handle), True)
            return False
        state.uploads.add(msg.transfer_uuid)
        return True

    def _check_FileTransferPart(self, client_id: int, state: ClientState, msg: Any) -> bool:
        if msg.transfer_uuid not in state.uploads:
            raise Refused("part of an upload this browser did not start")
        if len(msg.content) > _UPLOAD_CHUNK:
            raise Refused(f"upload part of {len(msg.content)} bytes")
        return True


def _label(handle: Any) -> str:
    return str(getattr(handle._impl.props, "label", type(handle).__name__))[:40]


def _action_of(handle: Any) -> str | None:
    """The ``operator_only`` action of one of ``handle``'s callbacks (the refusal's wording)."""
    impl = handle._impl
    holds = [cb for cbs in getattr(impl, "hold_cbs_from_freq", {}).values() for cb in cbs]
    for cb in (*holds, *getattr(impl, "update_cb", ()), *getattr(impl, "trigger_cb", ())):
        what = getattr(cb, "operator_only", None)
        if what:
            return str(what)
    return None
