"""What a viewer receives for one arm frame: the bone poses every websocket client decodes put the
skinned centre line on the arm's forward kinematics, and the message work is shared by all
clients (``console.web.shared_sends.share_wire_dicts``), not repeated per client."""

from __future__ import annotations

import time

import numpy as np
import pytest
from viser import _messages
from viser.infra import _messages as infra_messages

from console.scene.arm_view_factory import make_arm_view
from console.core.model import model_for
from console.scene.skin import bspline_weights
from fakes import open_guard
from console.web import install
from core.kinematics import planar as pk
from core.robots import load
from tests.ws_client import RawClient

SOFT = load("soft-arm")


def test_a_message_is_serialised_once_for_every_client(monkeypatch) -> None:
    install()
    calls = [0]
    original = infra_messages._prepare_for_serialization

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(infra_messages, "_prepare_for_serialization", counting)
    message = _messages.SetBonePositionMessage("/arm/body", 3, (0.1, 0.2, 0.3))
    first = message.as_serializable_dict([])
    once = calls[0]
    assert once > 0
    for _ in range(49):  # 49 more viewers' producers
        assert message.as_serializable_dict([]) is first
    assert calls[0] == once
    assert first == {"name": "/arm/body", "bone_index": 3, "position": (0.1, 0.2, 0.3),
                     "owner": message.owner, "type": "SetBonePositionMessage"}


def test_a_message_with_arrays_is_serialised_per_window() -> None:
    """An array travels as a binary buffer indexed within the client's own window."""
    install()
    poses = np.arange(12, dtype=np.float32).reshape(4, 3)
    message = _messages.SceneNodeUpdateMessage("/arm/segment_rings", {"batched_positions": poses})
    busy: list[memoryview] = [memoryview(b"x")]
    a = message.as_serializable_dict(busy)
    b = message.as_serializable_dict([])
    assert a is not b
    assert a["updates"]["batched_positions"]["__binary_index"] == 1
    assert b["updates"]["batched_positions"]["__binary_index"] == 0


def received_bones(client: RawClient, name: str, n: int) -> np.ndarray | None:
    """(n, 7) newest [wxyz, xyz] of every bone of ``name`` the client decoded (None if any
    is missing)."""
    wxyz: dict[int, tuple] = {}
    xyz: dict[int, tuple] = {}
    with client._lock:
        messages = list(client.messages)
    for m in messages:
        if m.get("name") != name:
            continue
        if m["type"] == "SetBoneOrientationMessage":
            wxyz[m["bone_index"]] = m["wxyz"]
        elif m["type"] == "SetBonePositionMessage":
            xyz[m["bone_index"]] = m["position"]
    if len(wxyz) < n or len(xyz) < n:
        return None
    return np.array([[*wxyz[i], *xyz[i]] for i in range(n)], dtype=float)


def pose_matrices(rows: np.ndarray) -> np.ndarray:
    import viser.transforms as vtf

    out = np.tile(np.eye(4), (len(rows), 1, 1))
    out[:, :3, :3] = vtf.SO3(rows[:, :4]).as_matrix()
    out[:, :3, 3] = rows[:, 4:]
    return out


@pytest.mark.parametrize("kappa", [np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0]),
                                   np.full(6, 16.7)])
def test_every_viewer_decodes_bone_poses_that_put_the_tube_on_the_kinematics(server,
                                                                              kappa) -> None:
    install()
    open_guard(server)
    view = make_arm_view(server.scene, model_for(SOFT))
    clients = [RawClient(server) for _ in range(3)]
    try:
        view.update(kappa)
        n = view.skin.n_bones
        deadline = time.monotonic() + 10.0
        got: list[np.ndarray] = []
        while time.monotonic() < deadline:
            got = [received_bones(c, view.body.name, n) for c in clients]
            if all(g is not None and np.allclose(g[:, 4:], view.skin.bone_poses(
                    view.frames(kappa))[:, :3, 3], atol=2.0**-15) for g in got):
                break
            time.sleep(0.05)
        else:
            raise AssertionError("the viewers did not receive the frame's bone poses")
        for g in got[1:]:
            np.testing.assert_array_equal(g, got[0])  # every viewer got the same poses
        poses = pose_matrices(got[0])
    finally:
        for c in clients:
            c.close()
    # Independent check: skin the bind-pose centre line at every segment end with the
    # received poses (three.js's linear blend) and compare with forward kinematics.
    skin = view.skin
    per_segment = view.samples_per_segment // view.bone_stride  # knots per segment
    u = np.arange(0, skin.n_knots, per_segment, dtype=float)  # knots on segment ends
    idx, w = bspline_weights(u, skin.n_knots)
    dense = np.zeros((len(u), skin.n_bones))
    np.put_along_axis(dense, idx, w, axis=1)
    centre = np.column_stack([np.zeros((len(u), 2)), u * skin.spacing])
    drawn = skin.deform(centre, dense, skin.bind_poses(), poses)
    ends = pk.forward_kinematics(kappa, SOFT.lengths, SOFT.base_pose)  # (N+1, 3)
    want = np.column_stack([ends[:, :2], np.full(len(ends), SOFT.half_width)])
    assert np.linalg.norm(drawn - want, axis=1).max() < 0.2e-3


def test_set_bone_poses_queues_what_the_bone_setters_queue(server) -> None:
    """The vectorised assignment sends the same messages as viser's per-bone setters, and
    nothing for bones that did not move."""
    from console.web.shared_sends import set_bone_poses

    view_a = make_arm_view(server.scene, model_for(SOFT), root="/a", dead_band=None)
    view_b = make_arm_view(server.scene, model_for(SOFT), root="/b", dead_band=None)
    rng = np.random.default_rng(3)
    n = view_a.skin.n_bones
    wxyz = rng.standard_normal((n, 4))
    wxyz /= np.linalg.norm(wxyz, axis=1, keepdims=True)
    xyz = rng.uniform(-0.3, 0.3, (n, 3))
    xyz[::3] = [b.position for b in view_a.body.bones][::3]  # a third of the bones stay put
    sent: list[object] = []
    original = server.scene._queue_scene_message
    server.scene._queue_scene_message = lambda m: (sent.append(m), original(m))[1]

    def wire(messages: list[object]) -> list[tuple]:
        return sorted((type(m).__name__, m.bone_index,
                       tuple(getattr(m, "wxyz", ()) or m.position)) for m in messages)

    for bone, q, p in zip(view_a.body.bones, wxyz, xyz):
        bone.wxyz, bone.position = q, p
    by_setters = wire(sent)
    sent.clear()
    assert set_bone_poses(view_b.body, wxyz, xyz) == len(by_setters)
    assert wire(sent) == by_setters
    assert {m.name for m in sent} == {"/b/body"}
    assert sum(type(m).__name__ == "SetBonePositionMessage" for m in sent) == n - len(xyz[::3])
    np.testing.assert_array_equal([b.position for b in view_b.body.bones], xyz)
    sent.clear()
    assert set_bone_poses(view_b.body, wxyz, xyz) == 0 and sent == []
    with pytest.raises(ValueError):
        set_bone_poses(view_b.body, wxyz[:-1], xyz)


def test_bone_poses_go_on_the_wire_as_viser_writes_them(server) -> None:
    """set_bone_poses gives each message its wire dict directly: viser's own walk of the type
    hints gives the same keys, order and values (the same bytes once encoded)."""
    import msgspec

    from console.web.shared_sends import set_bone_poses

    install()
    view = make_arm_view(server.scene, model_for(SOFT), root="/w", dead_band=None)
    sent: list[object] = []
    original = server.scene._queue_scene_message
    server.scene._queue_scene_message = lambda m: (sent.append(m), original(m))[1]
    n = view.skin.n_bones
    rng = np.random.default_rng(5)
    wxyz = rng.standard_normal((n, 4))
    wxyz /= np.linalg.norm(wxyz, axis=1, keepdims=True)
    assert set_bone_poses(view.body, wxyz, rng.uniform(-0.3, 0.3, (n, 3))) == 2 * n
    viser_walk = infra_messages.Message.as_serializable_dict.__wrapped__
    for m in sent:
        fast, slow = m.as_serializable_dict([]), viser_walk(m, [])
        assert list(fast) == list(slow) and fast == slow and fast["owner"] == m.owner
        assert msgspec.msgpack.encode(fast) == msgspec.msgpack.encode(slow)


def test_loop_safe_event_schedules_one_set_for_a_burst_of_messages() -> None:
    """A frame's ~100 pushes from the render thread wake the loop once, not once each."""
    import asyncio

    from console.web.shared_sends import LoopSafeEvent

    import threading

    loop = asyncio.new_event_loop()

    def run_once() -> None:  # in a thread of its own: this one may hold a running loop already
        worker = threading.Thread(target=loop.run_until_complete, args=(asyncio.sleep(0),))
        worker.start()
        worker.join(5.0)

    try:
        event = LoopSafeEvent(loop)
        for _ in range(100):
            event.set()  # from this thread: the loop is not running here
        assert len(loop._ready) == 1  # type: ignore[attr-defined]
        assert not event.is_set()
        run_once()
        assert event.is_set()
        event.clear()
        event.set()  # a later message schedules again
        run_once()
        assert event.is_set()
    finally:
        loop.close()


def test_a_window_is_encoded_once_for_every_client() -> None:
    """Producers taking the same window of the broadcast buffer send the same frame."""
    import zstandard

    from console.web.shared_sends import encode_window
    from tests.ws_client import decode_frame

    class Buffer:  # what encode_window keeps its frames on
        pass

    buffer, zstd = Buffer(), zstandard.ZstdCompressor(level=1)
    window = [_messages.SetBonePositionMessage("/arm/body", i, (0.0, 0.01 * i, 0.0))
              for i in range(5)]
    frame = encode_window(buffer, window, zstd)
    assert encode_window(buffer, list(window), zstd) is frame  # the next client's producer
    decoded = decode_frame(frame)
    assert [m["bone_index"] for m in decoded] == list(range(5))
    assert decoded[3]["position"] == [0.0, 0.03, 0.0]
    # A different window (other message objects, equal content) is encoded afresh.
    other = [_messages.SetBonePositionMessage("/arm/body", i, (0.0, 0.01 * i, 0.0))
             for i in range(5)]
    assert encode_window(buffer, other, zstd) is not frame
    # A message that skips one client makes its window that client's own.
    skip = _messages.SetBonePositionMessage("/arm/body", 9, (1.0, 0.0, 0.0))
    skip.excluded_self_client = 7
    first = encode_window(buffer, [skip], zstd)
    assert encode_window(buffer, [skip], zstd) is not first


def test_a_frame_in_an_atomic_block_wakes_the_viewers_once_at_its_end(server) -> None:
    """Pushes inside ``server.atomic()`` (the render thread's frame) schedule no wake-up: the
    viewers' window loops take nothing during the block; its end wakes them once, and every
    viewer receives the frame's messages in one websocket frame."""
    install()
    buffer = server._websock_server._broadcast_buffer
    loop = buffer.event_loop
    scheduled = []
    original = loop.call_soon_threadsafe

    def counting(callback, *args, **kwargs):  # type: ignore[no-untyped-def]
        scheduled.append(callback)
        return original(callback, *args, **kwargs)

    view = make_arm_view(server.scene, model_for(SOFT), dead_band=None)
    open_guard(server)
    clients = [RawClient(server) for _ in range(2)]
    try:
        time.sleep(0.5)
        frames0 = [c.frames for c in clients]
        loop.call_soon_threadsafe = counting  # type: ignore[method-assign]
        try:
            with server.atomic():
                for k in range(5):  # five frames' worth of bone poses: ~250 messages
                    view.update(np.full(6, 2.0 + k))
                during = list(scheduled)
            after = list(scheduled)
        finally:
            del loop.call_soon_threadsafe
        assert during == []
        assert len(after) == 1  # viser's own wake-up at the block's end
        n = view.skin.n_bones
        deadline = time.monotonic() + 10.0
        while not all(received_bones(c, view.body.name, n) is not None for c in clients):
            assert time.monotonic() < deadline, "the viewers did not receive the frame"
            time.sleep(0.02)
        time.sleep(0.2)
        assert [c.frames - f for c, f in zip(clients, frames0)] == [1, 1]
    finally:
        for c in clients:
            c.close()


def test_a_broadcast_window_is_collected_once_for_every_client() -> None:
    """Clients at the same cursor get the same window object with what viser's own per-client
    walk takes: culled ids skipped, at most a window's size; a range holding a message that
    skips one client is that client's own."""
    import asyncio

    from viser.infra._async_message_buffer import AsyncMessageBuffer

    from console.web.shared_windows import shared_window

    loop = asyncio.new_event_loop()
    try:
        buffer = AsyncMessageBuffer(loop, persistent_messages=True)
        buffer.max_window_size = 4
        for i in range(6):
            buffer.push(_messages.SetBonePositionMessage("/arm/body", i % 3, (0.0, 0.01 * i, 0.0)))
        # Bones 0-2 were set twice: ids 0-2 were culled, 3-5 remain.
        assert sorted(buffer.message_from_id) == [3, 4, 5]
        a, cursor_a = shared_window(buffer, -1, 5, client_id=1)
        b, cursor_b = shared_window(buffer, -1, 5, client_id=2)
        assert a is b and cursor_a == cursor_b == 5
        assert [m.position[1] for m in a] == [0.03, 0.04, 0.05]
        for i in range(6, 12):
            buffer.push(_messages.SetBonePositionMessage("/arm/body", i, (0.0, 0.0, 0.0)))
        c, cursor = shared_window(buffer, 5, 11, client_id=1)
        assert [m.bone_index for m in c] == [6, 7, 8, 9] and cursor == 9  # the window's size
        echo = _messages.SetBonePositionMessage("/arm/body", 20, (1.0, 0.0, 0.0))
        echo.excluded_self_client = 2
        buffer.push(echo)
        own, _ = shared_window(buffer, 11, 12, client_id=2)
        other, _ = shared_window(buffer, 11, 12, client_id=1)
        assert own == [] and other == [echo]
    finally:
        loop.close()
