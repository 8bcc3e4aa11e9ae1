"""HTML export: one file with the viewer and the scene embedded, no http(s) resource, and for a
recorded run an animation whose frames are the recorded configurations (decoded from the file
and compared with the kinematics)."""

from __future__ import annotations

import base64
import re
import time
from typing import Any

import msgspec
import numpy as np
import pytest
import viser
import zstandard

from console.app import ConsoleApp
from console.scene.arm_view_factory import make_arm_view
from console.playback.export import draw_overlay, external_urls, recording_html, scene_html
from console.recording.recorder import Event, Recording
from core.kinematics import planar as pk
from core.robots import load

SOFT = load("soft-arm")



def decode_embedded(html: str) -> tuple[dict[str, Any], list[bytes]]:
    """The scene payload viser embeds in an exported page, and its binary buffers."""
    match = re.search(r'__VISER_EMBED_DATA__="([^"]+)"', html)
    assert match, "no embedded scene"
    raw = base64.b64decode(match.group(1))
    inner_size = int.from_bytes(raw[:8], "little")
    inner = zstandard.ZstdDecompressor().decompress(raw[8:], max_output_size=inner_size)
    n = int.from_bytes(inner[:8], "little")
    payload = msgspec.msgpack.decode(inner[8:8 + n])
    offset, buffers = 8 + n, []
    for length in payload["binaryBufferLengths"]:
        offset += (8 - offset % 8) % 8
        buffers.append(inner[offset:offset + length])
        offset += length
    return payload, buffers


def node_updates(payload: dict[str, Any], buffers: list[bytes], name: str, prop: str):
    """(time, array) of every update of ``prop`` of scene node ``name``."""
    out = []
    for t, msg in payload["messages"]:
        if msg.get("name") != name:
            continue
        value = (msg.get("updates") or {}).get(prop) if msg["type"] == "SceneNodeUpdateMessage" \
            else (msg.get("props") or {}).get(prop)
        if isinstance(value, dict) and "__binary_index" in value:
            arr = np.frombuffer(buffers[value["__binary_index"]], dtype=np.dtype(value["dtype"]))
            out.append((t, arr.reshape(-1, 3).astype(float)))
    return out


def ring_centres(app: ConsoleApp, vertices: np.ndarray) -> np.ndarray:
    k, m = app.view.body_topology.sides, app.view.body_topology.n_rings
    return vertices[: m * k].reshape(m, k, 3).mean(axis=1)


def test_external_urls_finds_resources_but_not_namespace_names() -> None:
    page = ('<svg xmlns="http://www.w3.org/2000/svg"></svg>'
            '<script src="https://cdn.example.com/lib.js"></script><a href=http://x.org/a>')
    assert external_urls(page) == ["http://x.org/a", "https://cdn.example.com/lib.js"]


def test_scene_export_is_standalone_and_contains_the_arm_and_the_plan(server) -> None:
    app = ConsoleApp(SOFT, server)
    app.view = make_arm_view(server.scene, app.model, method="vertices", dead_band=None)
    q = np.array([4.0, -2.0, 6.0, 0.0, -8.0, 3.0])
    with app:
        state = app.store.request(q, "planner")
        deadline = time.monotonic() + 3
        while app.last_drawn_seq != state.seq and time.monotonic() < deadline:
            time.sleep(0.01)
    draw_overlay(server.scene, {"name": "plan", "points": [[0, 0, 0], [0.1, 0.2, 0],
                                                           [0.2, 0.3, 0]]})
    html = scene_html(server)
    assert html.lstrip().lower().startswith("<!doctype html>")
    assert external_urls(html) == []
    payload, buffers = decode_embedded(html)
    names = {m.get("name") for _, m in payload["messages"]}
    assert {"/arm/body", "/table/top", "/overlays/plan"} <= names
    body = node_updates(payload, buffers, "/arm/body", "vertices")[-1][1]
    backbone = pk.sample_backbone(q, SOFT.lengths, app.view.samples_per_segment, SOFT.base_pose)
    np.testing.assert_allclose(ring_centres(app, body)[:, :2], backbone[:, :2], atol=1e-5)
    assert not any(m["type"].startswith("Gui") for _, m in payload["messages"])


def test_recorded_run_export_animates_the_recorded_configurations() -> None:
    times = np.arange(0.0, 2.0, 1 / 30)
    qs = np.outer(np.sin(np.pi * times / 2.0), [8.0, -4.0, 2.0, 6.0, -3.0, 1.0])
    qs[times > 1.5] = qs[times <= 1.5][-1]  # the arm rests for the last half second
    rec = Recording("run.jsonl.gz", {"robot": "soft-arm"}, times, qs, ["jog"] * len(times),
                    [Event(0.5, "overlay", "Alice", "",
                           {"name": "plan", "points": [[0, 0, 0], [0.1, 0.1, 0]]})])
    html = recording_html(SOFT, rec, fps=10.0)
    assert external_urls(html) == []
    payload, buffers = decode_embedded(html)
    assert payload["durationSeconds"] == pytest.approx(times[-1], abs=0.1 + 1e-9)
    frames = node_updates(payload, buffers, "/arm/body", "vertices")
    stamps = np.array([t for t, _ in frames])
    assert np.all(np.diff(stamps) >= 0)
    # One frame per 0.1 s while moving (initial mesh + updates), none while resting.
    assert 14 <= len(frames) <= 18
    assert stamps[-1] <= 1.6 + 1e-9
    # The recorded table only: no live grasp session's objects, plan or shading in the file.
    assert not [m.get("name") for _, m in payload["messages"]
                if str(m.get("name", "")).startswith("/grasp/")]
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view_app = ConsoleApp(SOFT, srv, panels=())
        for t, verts in frames[1:]:
            q = rec.q_at(t)
            backbone = pk.sample_backbone(q, SOFT.lengths, 16, SOFT.base_pose)
            np.testing.assert_allclose(ring_centres(view_app, verts)[:, :2], backbone[:, :2],
                                       atol=1e-5)
    finally:
        srv.stop()
    overlay_times = [t for t, m in payload["messages"] if m.get("name") == "/overlays/plan"]
    assert overlay_times and min(overlay_times) == pytest.approx(0.5, abs=0.1 + 1e-9)
