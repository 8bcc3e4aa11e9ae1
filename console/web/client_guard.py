"""One gate for everything a browser sends: viser 1.1.1 trusts its clients, a shared console cannot.

What upstream viser 1.1.1 does with a client's message (checked by
``tests/console/test_client_guard.py`` and ``tests/console/test_web_patches.py``):

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
``viser.infra._infra._message_consumer``, which ``console.web.receive_guard.install`` replaces
(a module-level function looked up per connection, so one patch covers every server). A server
with a :class:`ClientGuard` attached (``ConsoleApp`` attaches one) has each frame checked by
:meth:`ClientGuard.admit`; on a server without one no frame is read until one is attached
(failing closed, see ``console.web.receive_guard``). Rules, in order:

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

Rules 1 and 2 are :meth:`ClientGuard.admit`; rules 3 and 4, per message type, are the
``_check_<MessageType>`` methods it inherits from
:class:`console.web.client_message_checks.MessageTypeChecks`. The guard runs on viser's event loop;
it only reads GUI state and queues messages.
"""

from __future__ import annotations

import collections
import logging
import time
from typing import Any, Callable

from console.web.client_message_checks import ClientState, MessageTypeChecks
from console.web.client_values import GuardLimits, Refused, check_fields, short
from console.web.viewer_props import ViewerProps

log = logging.getLogger(__name__)

#: Message types a viser 1.1.1 browser sends that this console accepts (by class name).
CLIENT_MESSAGES = frozenset({
    "GuiUpdateMessage", "GuiButtonHoldMessage", "CommandTriggerMessage", "ViewerCameraMessage",
    "ScenePointerMessage", "SceneNodeClickMessage", "SceneNodeDragMessage",
    "TransformControlsUpdateMessage", "TransformControlsDragStartMessage",
    "TransformControlsDragEndMessage", "FileTransferStartUpload", "FileTransferPart",
    "LocalStorageGetItemResponseMessage"})


_GUARD = "_console_client_guard"  # where a viser WebsockServer keeps its guard


def guard_of(websock_server: Any) -> ClientGuard | None:
    """The guard attached to a viser ``WebsockServer`` (``server._websock_server``), or None."""
    guard = getattr(websock_server, _GUARD, None)
    return guard if isinstance(guard, ClientGuard) else None


class Disconnect(Exception):
    """Close this client's connection (``code``, ``reason``)."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


class ClientGuard(MessageTypeChecks):
    """Checks every message a browser sends before viser stores or broadcasts anything.

    Args:
        server: The viser server to guard (the guard attaches itself to it).
        is_operator: ``is_operator(client_id)``: whether that browser holds control.
        refuse: ``refuse(client, reason, action)``: tell a browser why (coalesced by the app).
        refusal: ``refusal(action)``: the sentence for an operator-only ``action``.
        limits: What one browser may send.
        clock: Monotonic time source of the rate limit, the flood window and the log coalescing
            (tests pass a simulated one; ``clock`` is also an attribute they may replace).
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
        self.clock = clock  # public: a test may stop the rate limit's time (tests/console)
        self._viewer_allowed: set[str] = set()
        self._clients: dict[int, ClientState] = {}
        self._logged: dict[tuple[int, str], list[float]] = {}
        self.counts: collections.Counter[str] = collections.Counter()
        setattr(server._websock_server, _GUARD, self)  # the receive loop's route here
        # What browsers are shown follows the same policy: viewers see operator-only widgets
        # disabled (console.web.viewer_props); a change of holder calls viewer_props.resend().
        self.viewer_props = ViewerProps(server, viewer_may_use=self.viewer_may_use,
                                        is_operator=is_operator)
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
        if self.server.get_clients():  # a browser may have been sent these as disabled
            self.viewer_props.resend([str(getattr(h._impl, "uuid", "")) for h in handles])

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
        self.forget(client.client_id)

    def forget(self, cid: int) -> None:
        """Drop what the guard keeps of connection ``cid`` (it closed)."""
        self._clients.pop(cid, None)
        for key in [k for k in list(self._logged) if k[0] == cid]:  # (another thread)
            self._logged.pop(key, None)

    # -- the gate ----------------------------------------------------------------------------

    def admit(self, client_id: int, raw: Any, message_class: Any) -> Any | None:
        """The decoded message if it may go on to viser, else None (dropped and logged).

        Raises:
            Disconnect: the client is to be disconnected (flood, undecodable frame).
        """
        lim = self.limits
        now = self.clock()
        state = self._clients.get(client_id)
        if state is None:
            state = self._clients[client_id] = ClientState(lim.burst, now)
        state.tokens = min(lim.burst, state.tokens + (now - state.last) * lim.rate)
        state.last = now
        if state.tokens < 1.0:
            self._drop(client_id, state, "rate", f"over {lim.rate:g} messages/s: dropped")
            return None
        state.tokens -= 1.0
        if not isinstance(raw, (bytes, bytearray)):
            raise Disconnect(1003, "text frame (viser speaks binary msgpack)")
        if len(raw) > lim.max_message_bytes:
            raise Disconnect(1009, f"message of {len(raw)} bytes")
        try:
            message = message_class.deserialize(bytes(raw))
        except Exception as exc:  # msgpack, unknown type, wrong fields: never from a browser
            raise Disconnect(1008, f"undecodable message ({type(exc).__name__}: "
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

    def _drop(self, client_id: int, state: ClientState, reason: str, detail: str) -> None:
        """Drop a message: count it, log it (coalesced), disconnect a client that keeps on."""
        self.counts[reason] += 1
        self.log(client_id, reason, detail)
        now = self.clock()
        drops = state.drops
        drops.append(now)
        while drops and now - drops[0] > self.limits.flood_window:
            drops.popleft()
        if len(drops) > self.limits.flood_drops:
            raise Disconnect(1008, f"{len(drops)} messages dropped in "
                                    f"{self.limits.flood_window:g} s ({reason}: {detail})")

    def log(self, client_id: int, kind: str, detail: str) -> None:
        """One warning per client and kind every ``log_every`` s, saying how many were dropped."""
        now = self.clock()
        entry = self._logged.setdefault((client_id, kind), [-1e18, 0])
        entry[1] += 1
        if now - entry[0] < self.limits.log_every:
            return
        more = f" (+{entry[1] - 1} more since the last line)" if entry[1] > 1 else ""
        log.warning("client %s: %s%s", client_id, short(detail, 200), more)
        entry[0], entry[1] = now, 0
