"""Live bridge: the lab channels over the Foxglove WebSocket protocol, for Foxglove and Lichtblick.

``serve.py --foxglove-port P`` (off by default; bound to the same address as ``--host``) starts
one :class:`FoxgloveBridge`. It taps the console's recorder (``Recorder.add_tap``), so it streams
exactly what a recording would hold -- the same topics, schemas and messages
(``core.labdata.channels``) -- whether or not a recording runs, with log times on the console's
clock (ns since the epoch). While the arm rests, the newest configuration, objects, plan and
phase are sent again once a second, so a layout opened later shows them.

Read-only: the server is started with no capabilities (no client publish, no services, no
parameters, no asset fetching) and no listener, so nothing a Foxglove client sends reaches the
console; the tap only enqueues (a full queue drops and counts), and one bridge thread encodes and
logs. foxglove-sdk's server runs in its own (Rust) threads, in a private ``foxglove.Context``, on
a loopback port; the public port is a :class:`~console.recording.foxglove_relay.SubprotocolRelay`, so
clients asking for ``foxglove.websocket.v1`` (older Lichtblick) connect as well as those asking
for the SDK's ``foxglove.sdk.v1`` (Foxglove, newer Lichtblick).
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from typing import Any

import foxglove

from console.recording.foxglove_relay import SubprotocolRelay
from core.labdata.channels import (CHANNELS, ArmGeometry, ChannelSpec, json_safe, messages_for,
                                    spec_for)
from core.robots import Robot

log = logging.getLogger(__name__)
SERVER_NAME = "softarm-console"
LATCHED = ("state", "objects", "plan", "phase")  # repeated while quiet, for late joiners
REPEAT_S = 1.0


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
                                            server_listener=None, context=self.context)
        self.relay = SubprotocolRelay(int(self.server.port), host, port)
        self._queue: queue.Queue[tuple[dict[str, Any], int] | None] = queue.Queue(max_queue)
        self._thread = threading.Thread(target=self._run, name="foxglove-bridge", daemon=True)
        self._thread.start()
        recorder.add_tap(self._enqueue)

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

    def _run(self) -> None:
        # The newest record of each latched kind, re-sent once a second while none comes, so a
        # layout opened later shows the arm, objects, plan and phase without waiting for motion.
        latest: dict[str, tuple[dict[str, Any], float]] = {}
        while True:
            try:
                item = self._queue.get(timeout=REPEAT_S / 2)
            except queue.Empty:
                item = ()
            if item is None:
                return
            now = time.monotonic()
            if item:
                record, ns = item
                self._send(record, ns)
                if record.get("kind") in LATCHED:
                    latest[str(record["kind"])] = (record, now)
            for kind, (record, at) in list(latest.items()):
                if now - at >= REPEAT_S:
                    self._send(record, time.time_ns())
                    latest[kind] = (record, now)

    def _send(self, record: dict[str, Any], ns: int) -> None:
        try:
            for topic, msg in messages_for(record, ns, self.arm):
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
