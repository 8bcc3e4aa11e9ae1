"""A Foxglove client's bad frames: the SDK logged one ERROR line per frame, naming the relay's
own loopback socket; now the first frame of each kind from a client is logged once, naming the
client's real address, and the rest are counted, not printed. The SDK still answers each frame
(the client is told), and nothing reaches the console."""

from __future__ import annotations

import json
import logging
import time
from typing import Any

import pytest
from websockets.sync.client import connect

from console.recording.foxglove_bridge import FoxgloveBridge
from console.recording.foxglove_log import SDK_LOGGER, kind_of
from core.robots import load


class NoRecorder:
    """The two things the bridge asks of the console's recorder."""

    def add_tap(self, fn: Any, latched: bool = False) -> None:
        pass

    def latched(self) -> list[dict[str, Any]]:
        return []


def test_kinds_ignore_positions_names_and_numbers() -> None:
    assert kind_of("expected ident at line 1 column 2") == "expected ident"
    assert kind_of("unknown variant `bogus`, expected one of `subscribe`") == \
        kind_of("unknown variant `other`, expected one of `subscribe`")
    assert kind_of("Unknown binary opcode 9") == kind_of("Unknown binary opcode 7")


def test_bad_frames_are_logged_once_per_client_and_kind_with_its_address(caplog) -> None:
    caplog.set_level(logging.ERROR, logger=SDK_LOGGER)
    bridge = FoxgloveBridge(NoRecorder(), load("soft-arm"), "127.0.0.1", 0)
    try:
        with connect(f"ws://127.0.0.1:{bridge.port}",
                     subprotocols=["foxglove.websocket.v1"]) as ws:  # type: ignore[list-item]
            host, port = ws.local_address[:2]
            for i in range(3):  # three kinds, three times each
                ws.send("not json")
                ws.send(json.dumps({"op": f"bogus{i}"}))
                ws.send(bytes([9 + i]) + b"junk")
            ws.send(json.dumps({"op": "subscribe"}))  # a fourth kind, last: all were handled
            deadline = time.monotonic() + 30
            lines: list[str] = []
            while time.monotonic() < deadline:
                lines = [r.getMessage() for r in caplog.records if r.name == SDK_LOGGER
                         and "invalid message" in r.getMessage().lower()]
                if any("missing field" in ln for ln in lines):
                    break
                time.sleep(0.05)
    finally:
        bridge.stop()
    assert len(lines) == 4, lines
    assert all(ln.startswith(f"Foxglove client {host}:{port} sent an invalid message: ")
               for ln in lines), lines
    assert bridge.bad_frames.suppressed == 6


@pytest.fixture(autouse=True)
def _no_filter_left(request: pytest.FixtureRequest) -> Any:
    yield
    assert not logging.getLogger(SDK_LOGGER).filters  # stop() removed it
