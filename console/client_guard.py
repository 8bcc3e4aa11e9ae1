"""One gate for everything a browser sends: viser 1.1.1 trusts its clients, a shared console cannot.

What upstream viser 1.1.1 does with a client's message (checked by ``tests/test_client_guard.py``):

* ``GuiApi._handle_gui_updates`` applies *every* attribute a client names in
  ``GuiUpdateMessage.updates`` with ``setattr`` -- ``removed``, ``update_cb``, ``props`` ... --
  after only a type cast, broadcasts it to every other browser, then runs the callbacks. A viewer
  could set ``removed`` on STOP, which then did nothing.
* Values are not validated: ``1e308`` sent to an integer number field becomes a 1025-bit ``int``
  that msgpack cannot encode, so every browser's sender raised ``OverflowError`` (closed with
  1011, again on every reconnect: the value is persistent state); NaN / inf are stored and sent to
  everyone; a 10 MB string is stored and sent to every browser.
* Callbacks run after the value is stored and broadcast, so ``operator_only`` could only snap a
  viewer's edit back after everyone had seen it (and after the operator's next action used it).
* No rate limit: each message becomes two event-loop tasks and a callback in the shared thread
  pool, so a burst of 10 000 STOP clicks delayed the operator's lease probe by 8-9 s.
* Messages up to 50 MB are accepted; a frame that does not decode closes only its own connection.

The fix sits at the one place every client frame passes before viser decodes and dispatches it:
``viser.infra._infra._message_consumer``, which ``console.guarded_receive.install`` replaces
(a module-level function looked up per connection, so one patch covers every server). A server
with a :class:`ClientGuard` attached (``ConsoleApp`` attaches one) has each frame checked by
:meth:`ClientGuard.admit`; servers without one behave as upstream. Rules, in order:

1. Size and rate: frames over ``max_message_bytes`` close that connection (1009); a token bucket
   per client drops messages beyond ``rate`` per second (``burst`` at once), and a client whose
   drops or protocol violations keep coming is disconnected alone (1008), with a log line.
2. Shape: undecodable frames disconnect; only the message types a viser browser sends are
   accepted; a ``GuiUpdateMessage`` may carry only ``value``, for a known input widget of the
   server or of that browser. Everything else is dropped and logged (coalesced, truncated).
3. Value: the right type, finite, within the widget's bounds (number / slider / multi-slider /
   vector min and max, integer fields stay integers, dropdown and button-group options, checkbox
   bool, colour ranges, text at most ``max_text`` characters). A refused value is never stored.
4. Access (the policy): every shared input is operator-only unless a panel marked it with
   :meth:`ClientGuard.allow_viewers` (STOP, Save scene, Export ...); a browser's own widgets
   (``client.gui``: name, token, Take control, replay) are its own. A viewer's edit is refused
   before it is stored: only that browser gets its widget's value back, plus one notification
   (``ConsoleApp.refuse`` coalesces them) naming who holds control.

The guard runs on viser's event loop; it only reads GUI state and queues messages.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import time
from typing import Any, Callable

from console.client_values import (GuardLimits, OutOfBounds, Refused, check_fields, short,
                                   validate_value)

log = logging.getLogger(__name__)

#: Message types a viser 1.1.1 browser sends that this console accepts (by class name).
CLIENT_MESSAGES = frozenset({
    "GuiUpdateMessage", "GuiButtonHoldMessage", "CommandTriggerMessage", "ViewerCameraMessage",
    "ScenePointerMessage", "SceneNodeClickMessage", "SceneNodeDragMessage",
    "TransformControlsUpdateMessage", "TransformControlsDragStartMessage",
    "TransformControlsDragEndMessage", "FileTransferStartUpload", "FileTransferPart",
    "LocalStorageGetItemResponseMessage"})
_UPLOAD_CHUNK = 512 * 1024  # viser's browser uploads files in parts of this size


class _Disconnect(Exception):
    """Close this client's connection (``code``, ``reason``)."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


@dataclasses.dataclass
class _ClientState:
    """Per-connection bookkeeping (event-loop thread only)."""

    tokens: float
    last: float
    drops: collections.deque = dataclasses.field(default_factory=collections.deque)
    uploads: set = dataclasses.field(default_factory=set)


class ClientGuard:
    """Checks every message a browser sends before viser stores or broadcasts anything.

    Args:
        server: The viser server to guard (the guard attaches itself to it).
        is_operator: ``is_operator(client_id)``: whether that browser holds control.
        refuse: ``refuse(client, reason, action)``: tell a browser why (coalesced by the app).
        refusal: ``refusal(action)``: the sentence for an operator-only ``action``.
        limits: What one browser may send.
    """

    def __init__(self, server: Any, *, is_operator: Callable[[int], bool],
                 refuse: Callable[[Any, str, str], None],
                 refusal: Callable[[str], str] = lambda action: f"Only the operator can {action}.",
                 limits: GuardLimits | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.server = server
        self.limits = limits or GuardLimits()
        self._is_operator = is_operator
        self._refuse = refuse
        self._refusal = refusal
        self._clock = clock
        self._viewer_allowed: set[str] = set()
        self._clients: dict[int, _ClientState] = {}
        self._logged: dict[tuple[int, str], list[float]] = {}
        self.counts: collections.Counter[str] = collections.Counter()
        server._websock_server._client_guard = self
        server.on_client_disconnect(self._forget)

    # -- policy ------------------------------------------------------------------------------

    def allow_viewers(self, *handles: Any) -> None:
        """Mark shared widgets (GUI inputs, commands, transform controls) as usable by viewers."""
        for handle in handles:
            impl = getattr(handle, "_impl", None)
            key = getattr(impl, "uuid", None) or getattr(impl, "name", None)
            if key is None:
                raise TypeError(f"not a viser widget handle: {handle!r}")
            self._viewer_allowed.add(str(key))

    def viewer_allowed(self, handle: Any) -> bool:
        """Whether ``handle`` is one a viewer may use (see :meth:`allow_viewers`)."""
        impl = getattr(handle, "_impl", None)
        return str(getattr(impl, "uuid", None) or getattr(impl, "name", "")) in self._viewer_allowed

    def address_of(self, client: Any) -> str | None:
        """The remote address (host) of a connected browser, or None."""
        cid = getattr(client, "client_id", client)
        conn = self.server._websock_server._live_connections.get(cid)
        try:
            return None if conn is None else str(conn.remote_address[0])
        except (TypeError, IndexError, AttributeError):
            return None

    def _forget(self, client: Any) -> None:
        cid = client.client_id
        self._clients.pop(cid, None)
        for key in [k for k in list(self._logged) if k[0] == cid]:  # (another thread)
            self._logged.pop(key, None)

    # -- the gate ----------------------------------------------------------------------------

    def admit(self, client_id: int, raw: Any, message_class: Any) -> Any | None:
        """The decoded message if it may go on to viser, else None (dropped and logged).

        Raises:
            _Disconnect: the client is to be disconnected (flood, undecodable frame).
        """
        lim = self.limits
        now = self._clock()
        state = self._clients.get(client_id)
        if state is None:
            state = self._clients[client_id] = _ClientState(lim.burst, now)
        state.tokens = min(lim.burst, state.tokens + (now - state.last) * lim.rate)
        state.last = now
        if state.tokens < 1.0:
            self._drop(client_id, state, "rate", f"over {lim.rate:g} messages/s: dropped")
            return None
        state.tokens -= 1.0
        if not isinstance(raw, (bytes, bytearray)):
            raise _Disconnect(1003, "text frame (viser speaks binary msgpack)")
        if len(raw) > lim.max_message_bytes:
            raise _Disconnect(1009, f"message of {len(raw)} bytes")
        try:
            message = message_class.deserialize(bytes(raw))
        except Exception as exc:  # msgpack, unknown type, wrong fields: never from a browser
            raise _Disconnect(1008, f"undecodable message ({type(exc).__name__}: "
                                    f"{short(str(exc))})") from None
        kind = type(message).__name__
        if kind not in CLIENT_MESSAGES:
            self._drop(client_id, state, "type", f"{kind} is not accepted from browsers")
            return None
        try:
            check_fields(getattr(message, "__dict__", {}), lim, depth=0,
                         skip_bytes=kind == "FileTransferPart",
                         text_limit=lim.max_string)
            check = getattr(self, f"_check_{kind}", None)
            ok = True if check is None else check(client_id, state, message)
        except Refused as exc:
            uuid = getattr(message, "uuid", None)
            if kind == "GuiUpdateMessage" and isinstance(uuid, str):  # that browser gets its
                handle, _ = self._gui_handle(client_id, uuid,  # value back (e.g. 10 MB text)
                                             "_gui_input_handle_from_uuid")
                if handle is not None:
                    self._restore(client_id, handle)
            self._drop(client_id, state, "invalid", f"{kind}: {exc}")
            return None
        except (TypeError, ValueError, AttributeError, KeyError, IndexError) as exc:
            self._drop(client_id, state, "invalid", f"{kind}: malformed fields "
                                                    f"({type(exc).__name__}: {short(str(exc))})")
            return None
        if not ok:
            return None
        self.counts["accepted"] += 1
        return message

    def _drop(self, client_id: int, state: _ClientState, reason: str, detail: str) -> None:
        """Drop a message: count it, log it (coalesced), disconnect a client that keeps on."""
        self.counts[reason] += 1
        self.log(client_id, reason, detail)
        now = self._clock()
        drops = state.drops
        drops.append(now)
        while drops and now - drops[0] > self.limits.flood_window:
            drops.popleft()
        if len(drops) > self.limits.flood_drops:
            raise _Disconnect(1008, f"{len(drops)} messages dropped in "
                                    f"{self.limits.flood_window:g} s ({reason}: {detail})")

    def log(self, client_id: int, kind: str, detail: str) -> None:
        """One warning per client and kind every ``log_every`` s, saying how many were dropped."""
        now = self._clock()
        entry = self._logged.setdefault((client_id, kind), [-1e18, 0])
        entry[1] += 1
        if now - entry[0] < self.limits.log_every:
            return
        more = f" (+{entry[1] - 1} more since the last line)" if entry[1] > 1 else ""
        log.warning("client %s: %s%s", client_id, short(detail, 200), more)
        entry[0], entry[1] = now, 0

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

    def _may_use(self, client_id: int, handle: Any, shared: bool, key: str) -> bool:
        return (not shared or key in self._viewer_allowed or self._is_operator(client_id))

    def _refuse_use(self, client_id: int, handle: Any, label: str, is_button: bool) -> None:
        self.counts["refused"] += 1
        verb = "press" if is_button else "change"
        action = _action_of(handle) or f"{verb} “{label}”"
        self.log(client_id, "refused", f"viewer refused: {action}")
        client = self._client(client_id)
        if client is not None:
            self._refuse(client, self._refusal(action), action)

    def _check_GuiUpdateMessage(self, client_id: int, state: _ClientState, msg: Any) -> bool:
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

    def _check_GuiButtonHoldMessage(self, client_id: int, state: _ClientState, msg: Any) -> bool:
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

    def _check_CommandTriggerMessage(self, client_id: int, state: _ClientState, msg: Any) -> bool:
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

    def _check_TransformControlsUpdateMessage(self, client_id: int, state: _ClientState,
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

    def _check_TransformControlsDragStartMessage(self, client_id: int, state: _ClientState,
                                                 msg: Any) -> bool:
        return self._check_gizmo_phase(client_id, msg)

    def _check_TransformControlsDragEndMessage(self, client_id: int, state: _ClientState,
                                               msg: Any) -> bool:
        return self._check_gizmo_phase(client_id, msg)

    def _check_FileTransferStartUpload(self, client_id: int, state: _ClientState,
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

    def _check_FileTransferPart(self, client_id: int, state: _ClientState, msg: Any) -> bool:
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
