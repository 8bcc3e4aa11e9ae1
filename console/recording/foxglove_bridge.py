"""Live bridge: the lab channels over the Foxglove WebSocket protocol, for Foxglove and Lichtblick.

``serve.py --foxglove-port P`` (off by default; bound to the same address as ``--host``) starts
one :class:`FoxgloveBridge`. It taps the console's recorder (``Recorder.add_tap``), so it streams
exactly what a recording would hold -- the same topics, schemas and messages
(``core.labdata.channels``) -- whether or not a recording runs, with log times on the console's
clock (ns since the epoch). State channels are latched: the bridge starts with the recorder's
newest state records (``Recorder.add_tap(..., latched=True)``: robot file, configuration,
objects, plan, phase, link, scene layers, taken in the same step as it joins) and sends a
channel's newest message again whenever a client subscribes to it (the SDK has no latching of
its own, so its ``on_subscribe`` callback asks the bridge thread), so a viewer that joins late
sees the table at once; nothing is repeated on a timer, so ``/events``
carries only what happened.

Read-only: the server is started with no capabilities (no client publish, no services, no
parameters, no asset fetching) and a listener that only hears subscriptions (to re-send the
latched state), so nothing a Foxglove client sends reaches the console; a client's bad frames
are logged once per client and kind, with its real address
(:mod:`console.recording.foxglove_log`); the tap only enqueues (a full queue drops and counts),
and one bridge thread encodes and logs. foxglove-sdk's server runs in its own (Rust) threads,
in a private ``foxglove.Context``, on a loopback port; the public port is a
:class:`~console.recording.foxglove_relay.SubprotocolRelay`, so clients asking for
``foxglove.websocket.v1`` (older Lichtblick) connect as well as those asking for the SDK's
``foxglove.sdk.v1`` (Foxglove, newer Lichtblick).
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from typing import Any

import foxglove
from foxglove.websocket import ServerListener

from console.recording.foxglove_log import BadFrameLog
from console.recording.foxglove_relay import SubprotocolRelay
from core.labdata.channels import (CHANNELS, EVENT_TOPICS, ArmGeometry, ChannelSpec, json_safe,
                                    latch_key, messages_for, spec_for)
from core.robots import Robot

log = logging.getLogger(__name__)
SERVER_NAME = "softarm-console"
RESEND_AGAIN_S = 0.3  # a latched channel is sent again this long after a subscription
RESEND_WAIT_S = 5.0  # how long a re-send waits for the subscription to take messages


class _Subscriptions(ServerListener):
    """foxglove-sdk server listener: a new subscription asks the bridge thread to re-send the
    channel's latched message (runs on the SDK's threads: only enqueues). The SDK calls every
    callback of its ``ServerListener`` (an unsubscribe, a client leaving...): the others are its
    no-ops, inherited (without them each call logged "Callback failed: AttributeError")."""

    def __init__(self, resend: Any) -> None:
        self._resend = resend

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._resend(str(channel.topic))


class FoxgloveBridge:
    """Serves the lab channels on ``ws://host:port`` (``foxglove.websocket.v1``), read-only.

    Args:
        recorder: The console's ``console.recording.recorder.Recorder`` (tapped for every record).
        robot: The arm (geometry of the scene and tip channels).
        host: Address to bind (as serve.py's ``--host``).
        port: TCP port (0: an ephemeral one, see :attr:`port`).
        max_queue: Records buffered for the bridge thread before new ones are dropped.
    """

    def __init__(self, recorder: Any, robot: Robot, host: str = "127.0.0.1", port: int = 8765,
                 max_queue: int = 2000) -> None:
        self.arm = ArmGeometry(robot)
        self.context = foxglove.Context()
        self.dropped = 0
        self.sent = 0
        self._stopped = False
        self._channels: dict[str, foxglove.Channel] = {}
        for spec in CHANNELS:
            self._channel(spec)
        self.server = foxglove.start_server(name=SERVER_NAME, host="127.0.0.1", port=0,
                                            capabilities=[], services=None,
                                            server_listener=_Subscriptions(self._resend),
                                            context=self.context)
        self.relay = SubprotocolRelay(int(self.server.port), host, port)
        # The SDK's "Invalid message" lines: once per client and kind, naming the real client.
        self.bad_frames = BadFrameLog(self.relay.client_of)
        self.bad_frames.attach()
        self._queue: queue.Queue[tuple[dict[str, Any], int] | str | None] = \
            queue.Queue(max_queue)
        # The scene logged before the bridge existed, then every record (in one step: a record
        # logged in between would reach neither).
        recorder.add_tap(self._enqueue, latched=True)
        self._thread = threading.Thread(target=self._run, name="foxglove-bridge", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        """The public port (the relay's)."""
        return self.relay.port

    def _channel(self, spec: ChannelSpec) -> foxglove.Channel:
        ch = self._channels.get(spec.topic)
        if ch is None:
            schema = foxglove.Schema(name=spec.schema_name, encoding="jsonschema",
                                     data=json.dumps(spec.schema).encode("utf-8"))
            ch = foxglove.Channel(spec.topic, schema=schema, message_encoding="json",
                                  context=self.context)
            self._channels[spec.topic] = ch
        return ch

    def _enqueue(self, record: dict[str, Any], ns: int) -> None:
        if self._stopped:
            return
        try:
            self._queue.put_nowait((record, ns))
        except queue.Full:
            self.dropped += 1

    def _resend(self, topic: str) -> None:
        if self._stopped:
            return
        try:
            self._queue.put_nowait(topic)
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        # The newest record per latch key, re-sent (its messages on the subscribed topic only)
        # when a client subscribes to a channel. The SDK calls on_subscribe before the new
        # subscription may take messages, so a re-send waits for the channel to have a sink and
        # goes once more RESEND_AGAIN_S later (a second client's subscription: a duplicate of
        # the same state for the first is harmless).
        latest: dict[str, tuple[dict[str, Any], int]] = {}
        pending: list[tuple[str, float, int]] = []  # (topic, not before, sends left)
        while True:
            try:
                item = self._queue.get(timeout=0.02 if pending else None)
            except queue.Empty:
                item = ""
            if item is None:
                return
            if isinstance(item, str):
                if item and item not in EVENT_TOPICS:  # what happened is never re-sent
                    pending.append((item, time.monotonic(), 2))
            else:
                record, ns = item
                self._send(record, ns)
                key = latch_key(record)
                if key is not None:
                    latest[key] = (record, ns)
            now = time.monotonic()
            kept: list[tuple[str, float, int]] = []
            for topic, at, left in pending:
                ch = self._channels.get(topic)
                if at > now or ch is None or not ch.has_sinks():
                    if now - at < RESEND_WAIT_S:
                        kept.append((topic, at, left))
                    continue
                for record, ns in list(latest.values()):
                    self._send(record, ns, only=topic)
                if left > 1:
                    kept.append((topic, now + RESEND_AGAIN_S, left - 1))
            pending = kept

    def _send(self, record: dict[str, Any], ns: int, only: str | None = None) -> None:
        try:
            for topic, msg in messages_for(record, ns, self.arm):
                if only is not None and topic != only:
                    continue
                ch = self._channel(spec_for(topic))
                try:
                    data = json.dumps(msg, separators=(",", ":"), allow_nan=False)
                except (TypeError, ValueError):
                    data = json.dumps(json_safe(msg), separators=(",", ":"))
                ch.log(data.encode("utf-8"), log_time=ns)
                self.sent += 1
        except Exception:  # a bad record must not end the live stream
            log.exception("foxglove bridge: record %s not sent", record.get("kind"))

    def stop(self) -> None:
        """Stop the server and the bridge thread (the recorder's tap then only enqueues)."""
        self._stopped = True
        self._queue.put(None)
        self._thread.join(2.0)
        self.relay.stop()
        self.server.stop()
        self.bad_frames.detach()
