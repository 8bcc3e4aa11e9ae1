"""The soft-arm emulator's scene channel over a real UDP socket, against the plant's own sim."""

from __future__ import annotations

import json
import socket

import pytest

from core.control.sim import EmulatorPlant
from core.robots import load
from hw_bridge.emulator_scene import SceneChannel


@pytest.fixture
def channel():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.settimeout(5.0)
    events: list[tuple[str, dict]] = []
    ch = SceneChannel(sock, EmulatorPlant(load("soft-arm"), seed=0).sim,
                      lambda event, **fields: events.append((event, fields)))
    yield ch, peer, sock.getsockname(), events
    sock.close()
    peer.close()


def _ask(ch, peer, addr, payload: bytes) -> dict:
    peer.sendto(payload, addr)
    while True:                        # the datagram may take a moment to arrive
        ch.serve()
        try:
            peer.settimeout(0.05)
            return json.loads(peer.recv(4096))
        except TimeoutError:
            continue


def test_place_read_and_remove_the_object(channel) -> None:
    ch, peer, addr, events = channel
    assert _ask(ch, peer, addr, b'{"cmd": "scene"}') == {
        "ok": True, "captured": False, "finger": None, "object": None}
    assert _ask(ch, peer, addr, b'{"cmd": "place_object", "x": 0.25, "y": 0.02, "r": 0.02}') \
        == {"ok": True}
    assert events == [("object_placed", {"xy": [0.25, 0.02], "r": 0.02})]
    scene = _ask(ch, peer, addr, b'{"cmd": "scene"}')
    assert scene["object"] == pytest.approx([0.25, 0.02, 0.02]) and not scene["captured"]
    assert _ask(ch, peer, addr, b'{"cmd": "remove_object"}') == {"ok": True}
    assert ch.sim.obj is None


@pytest.mark.parametrize("payload, error", [
    (b'{"cmd": "place_object", "x": "nan", "y": 0, "r": 0.02}', "must be finite"),
    (b'{"cmd": "fly"}', "unknown scene command 'fly'"),
    (b'[1, 2]', "unknown scene command None"),
    (b'not json', "Expecting value"),
])
def test_bad_input_is_answered_and_changes_nothing(channel, payload, error) -> None:
    ch, peer, addr, events = channel
    reply = _ask(ch, peer, addr, payload)
    assert reply["ok"] is False and error in reply["error"]
    assert ch.sim.obj is None and events == []
