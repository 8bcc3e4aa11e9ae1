"""Fixes for viser 1.1.1's message path: a browser froze on updates from threads, and 50 viewers cost a core.

``viser.infra._async_message_buffer.AsyncMessageBuffer.push`` calls ``message_event.set()``
(an ``asyncio.Event``) directly from whatever thread queued the message: in this console, the
render thread, the jog thread and the GUI callback pool. ``asyncio.Event`` is not thread-safe:
``set()`` iterates the event's waiters while the event loop may be appending one. Found by the
load benchmark with 20 browsers: ``RuntimeError: deque mutated during iteration`` in our render
thread, and worse, when a waiter was being appended the event is left set with that waiter never
woken; ``set()`` is then a no-op, so a per-client buffer (its own single consumer) stops sending
to that browser for good (pages that never finished loading).

:func:`loop_safe_events` replaces each buffer's ``message_event`` with :class:`LoopSafeEvent`, whose
``set()`` from any other thread is handed to the event loop (``call_soon_threadsafe``); nothing
in viser reads the event synchronously (it is only awaited and cleared by the buffer's window
generator). A set inside an atomic block waits for the block's end (one wake-up per frame), and
a window holds up to ``WINDOW_MESSAGES`` (viser: 128, less than a frame of the extensible arm).
Idempotent; checked against viser 1.1.1 by ``tests/console/test_web_patches.py``.

:func:`share_wire_dicts` makes a message's wire form (``Message.as_serializable_dict``)
computed once and shared by every viewer: viser serialises every message again for every
connected client (a per-client producer walks each field in pure Python), so 50 viewers of
the extensible arm (~115 pose messages per frame: viser's client takes skinned-mesh bone poses
one message per bone and field, with no batched form) cost a whole core in that walk alone.

What viser 1.1.1 does with what browsers *send* (it trusts them) is fixed in
``console.web.client_guard``. Nothing here is applied on import: ``console.web.install``
applies every patch (:func:`loop_safe_events`, :func:`share_wire_dicts`, :func:`share_frames`
and ``console.web.shared_windows.install``), each with its undo for tests.
"""

from __future__ import annotations

import asyncio
import functools
import time
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt


class LoopSafeEvent(asyncio.Event):
    """``asyncio.Event`` that may be set from any thread: off the loop, ``set()`` is scheduled.

    With ``buffer`` (the viser message buffer whose event this is), a set() from another
    thread while the buffer is in an atomic block (``server.atomic()``: the render thread's
    frame) is deferred to the block's end (:func:`loop_safe_events` patches ``atomic_end``): viser's
    consumers take no message during the block, so waking them then only made each of 50
    viewers' window loops spin once per burst for nothing, several times a frame.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, buffer: Any = None) -> None:
        super().__init__()
        self._owner = loop
        self._buffer = buffer
        self._pending = False  # a set() is scheduled on the loop and has not run yet
        self.deferred = False  # a set() waits for the buffer's atomic block to end

    def set(self) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._owner:
            super().set()
            return
        buffer = self._buffer
        if buffer is not None and buffer.atomic_counter > 0:
            self.deferred = True
            if buffer.atomic_counter > 0:  # (else the block ended meanwhile: schedule now)
                return
        self.deferred = False
        # One scheduled set() serves every message pushed before it runs: scheduling writes
        # to the loop's wake-up socket, and viser sets the event once per message (a frame of
        # the extensible arm is ~115 messages; a system call each cost ~1/3 of the render
        # thread's time on a busy machine). A set() seeing one pending is covered by it: its
        # message was pushed before, and the callback clears the flag before setting.
        if self._pending:
            return
        self._pending = True
        try:
            self._owner.call_soon_threadsafe(self._set_on_loop)
        except RuntimeError:  # loop closed (shutdown): nobody is waiting any more
            self._pending = False

    def _set_on_loop(self) -> None:
        self._pending = False
        super().set()


WINDOW_MESSAGES = 512  # largest window of messages sent as one websocket frame
_WIRE = "_viser_fixes_wire"  # where a message keeps its shared wire dict (in its __dict__)


def share_wire_dicts() -> bool:
    """Serialise each viser message once for all clients, not once per client.

    Patches ``viser.infra.Message.as_serializable_dict`` (upstream 1.1.1: a new dict per call,
    i.e. per client's producer): the first call on a message stores the
    dict it returns on the message, later calls (the other clients' producers) return that same
    dict. Only messages without numpy arrays are shared: an array travels as a binary buffer
    whose placeholder index depends on the client's window, so those are serialised as before.
    Safe because viser builds a new message object for every update and never changes one after
    queueing it (the owner stamp and the name are set before); readers only encode the dict.

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _messages as infra_messages

    cls: Any = infra_messages.Message
    if getattr(cls, "_shared_wire_dicts", False):
        return False
    original = cls.as_serializable_dict

    @functools.wraps(original)
    def as_serializable_dict(self: Any, binary_buffers: Any = None) -> Any:
        cached = self.__dict__.get(_WIRE)
        if cached is not None:
            return cached
        before = None if binary_buffers is None else len(binary_buffers)
        out = original(self, binary_buffers)
        if binary_buffers is not None and len(binary_buffers) == before:
            self.__dict__[_WIRE] = out
        return out

    cls.as_serializable_dict = as_serializable_dict  # (functools.wraps: __wrapped__ = viser's)
    cls._shared_wire_dicts = True
    return True


def wire_dicts_shared() -> bool:
    """Whether :func:`share_wire_dicts` is in place."""
    from viser.infra import _messages as infra_messages

    return bool(getattr(infra_messages.Message, "_shared_wire_dicts", False))


def unshare_wire_dicts() -> bool:
    """Undo :func:`share_wire_dicts` (tests); True if it was installed."""
    from viser.infra import _messages as infra_messages

    cls: Any = infra_messages.Message
    if not getattr(cls, "_shared_wire_dicts", False):
        return False
    cls.as_serializable_dict = cls.as_serializable_dict.__wrapped__
    del cls._shared_wire_dicts
    return True


_FRAMES = "_viser_fixes_frames"  # a buffer's recent encoded windows (on the buffer)
_FRAMES_KEPT = 4


def encode_window(buffer: Any, window: Any, zstd: Any) -> bytes:
    """viser 1.1.1's websocket frame for a window of messages, encoded once per buffer.

    The frame is exactly what ``viser.infra._infra._message_producer`` sends (zstd-compressed
    msgpack of ``{"messages", "timestampSec", "binaryBufferLengths"}``, then the 8-byte aligned
    binary buffers). Every client's producer reads the same broadcast buffer and, woken by the
    same push, mostly takes the same window: the frame of a window made of the very same message
    objects is reused from the buffer's last few instead of being encoded again per client. A
    window holding a message meant to skip a client (``excluded_self_client``) is not shared.
    """
    from viser.infra import _infra

    kept: list[tuple[Any, tuple[Any, ...], bytes]] = buffer.__dict__.setdefault(_FRAMES, [])
    for source, _, frame in kept:  # the very window object (console.web.shared_windows shares it)
        if source is window:
            return frame
    messages = tuple(window)
    shareable = all(m.excluded_self_client is None for m in messages)
    if shareable:
        for _, cached, frame in kept:
            if len(cached) == len(messages) and all(a is b for a, b in zip(cached, messages)):
                return frame
    binary_buffers: list[memoryview] = []
    serialized = tuple(m.as_serializable_dict(binary_buffers) for m in messages)
    inner = msgspec.msgpack.encode({"messages": serialized, "timestampSec": time.perf_counter(),
                                    "binaryBufferLengths": tuple(b.nbytes for b in binary_buffers)})
    compressed = zstd.compress(inner)
    parts: list[Any] = [len(inner).to_bytes(8, "little"), len(compressed).to_bytes(8, "little"),
                        compressed]
    _infra._append_aligned_buffers(parts, binary_buffers, 16 + len(compressed))
    frame = b"".join(parts)
    if shareable:  # holding the messages keeps their ids from being reused while cached
        kept.append((window, messages, frame))
        del kept[:-_FRAMES_KEPT]
    return frame


def share_frames() -> bool:
    """Encode each window of messages once for all clients (:func:`encode_window`).

    Replaces ``viser.infra._infra._message_producer`` (looked up when a client connects;
    upstream 1.1.1 encodes and compresses every window per client) with
    the same loop, sending :func:`encode_window`'s frame: with 50 viewers the encoding and
    compression of every frame, 50 times over, was most of the console's CPU. The producers
    all run on the server's event loop, so the per-buffer cache needs no lock.

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _infra

    if getattr(_infra._message_producer, "_shared_frames", False):
        return False
    import zstandard

    async def _message_producer(websocket: Any, buffer: Any, client_id: int,
                                backlog_done_message: Any = None) -> None:
        window_generator = buffer.window_generator(
            client_id, backlog_done_message=backlog_done_message)
        zstd = zstandard.ZstdCompressor(level=1)
        try:
            while not buffer.done:
                try:
                    outgoing = await window_generator.__anext__()
                except StopAsyncIteration:
                    break
                await websocket.send(encode_window(buffer, outgoing, zstd))
        finally:
            await window_generator.aclose()  # as viser: its finallys run now, not at GC

    _message_producer._shared_frames = True  # type: ignore[attr-defined]
    _message_producer.upstream = _infra._message_producer  # type: ignore[attr-defined]
    _infra._message_producer = _message_producer
    return True


def frames_shared() -> bool:
    """Whether :func:`share_frames` is in place."""
    from viser.infra import _infra

    return bool(getattr(_infra._message_producer, "_shared_frames", False))


def unshare_frames() -> bool:
    """Undo :func:`share_frames` (tests); True if it was installed."""
    from viser.infra import _infra

    producer: Any = _infra._message_producer
    if not getattr(producer, "_shared_frames", False):
        return False
    _infra._message_producer = producer.upstream
    return True


def loop_safe_events() -> bool:
    """Make every viser message buffer created from now on use :class:`LoopSafeEvent`.

    Changes upstream viser 1.1.1: ``AsyncMessageBuffer.__init__`` (its ``message_event`` is a
    :class:`LoopSafeEvent`, its ``max_window_size`` at least :data:`WINDOW_MESSAGES`) and
    ``AsyncMessageBuffer.atomic_end`` (a set() deferred during the block is cleared at its end).

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if getattr(cls, "_loop_safe_event", False):
        return False
    original_init = cls.__init__
    original_atomic_end = cls.atomic_end

    @functools.wraps(original_init)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        original_init(self, *args, **kwargs)
        self.message_event = LoopSafeEvent(self.event_loop, self)
        # A frame of the extensible arm is ~120 messages: one window (one websocket frame
        # per viewer), not two.
        self.max_window_size = max(self.max_window_size, WINDOW_MESSAGES)

    @functools.wraps(original_atomic_end)
    def atomic_end(self: Any) -> None:
        original_atomic_end(self)  # at the outermost end it wakes the loop (viser's own)
        if self.atomic_counter == 0:
            self.message_event.deferred = False

    cls.__init__ = __init__
    cls.atomic_end = atomic_end
    cls._loop_safe_event = True
    return True


def events_are_loop_safe() -> bool:
    """Whether :func:`loop_safe_events` is in place."""
    from viser.infra import _async_message_buffer as amb

    return bool(getattr(amb.AsyncMessageBuffer, "_loop_safe_event", False))


def upstream_events() -> bool:
    """Undo :func:`loop_safe_events` for buffers created from now on (tests); True if it was
    installed."""
    from viser.infra import _async_message_buffer as amb

    cls: Any = amb.AsyncMessageBuffer
    if not getattr(cls, "_loop_safe_event", False):
        return False
    cls.__init__ = cls.__init__.__wrapped__
    cls.atomic_end = cls.atomic_end.__wrapped__
    del cls._loop_safe_event
    return True


def set_bone_poses(handle: Any, wxyzs: npt.ArrayLike, positions: npt.ArrayLike) -> int:
    """Assign all bone poses of a ``MeshSkinnedHandle`` at once; returns the messages queued.

    Queues exactly what assigning ``handle.bones[i].wxyz`` and ``.position`` one by one queues
    (a ``SetBoneOrientationMessage`` / ``SetBonePositionMessage`` for each value that is not
    ``np.allclose`` to the bone's current one, which is updated), but compares all bones in one
    vectorised step instead of one ``np.allclose`` and one tuple cast per setter: those cost
    about half of the render thread's time for the extensible arm's 56 bones. viser 1.1.1's
    client has no message carrying several bones, so the message count stays the same.

    Args:
        handle: The skinned mesh (viser 1.1.1 ``MeshSkinnedHandle``).
        wxyzs: (B, 4) unit quaternions.
        positions: (B, 3) positions.
    """
    from viser import _messages

    impl = handle._impl
    if impl.removed:
        raise RuntimeError("Cannot assign bone poses on a removed skinned mesh")
    bones = handle.bones
    queue = impl.api._queue_scene_message
    sent = 0
    for field, values, make in (
            ("wxyz", wxyzs, _messages.SetBoneOrientationMessage),
            ("position", positions, _messages.SetBonePositionMessage)):
        new = np.asarray(values, dtype=float)
        if new.shape != (len(bones), 4 if field == "wxyz" else 3):
            raise ValueError(f"{field}: expected {len(bones)} rows, got shape {new.shape}")
        current = [getattr(b._impl, field) for b in bones]
        old = np.array(current)
        same = np.all(np.abs(new - old) <= 1e-8 + 1e-5 * np.abs(old), axis=1)  # np.allclose
        kind = make.__name__
        for i in np.flatnonzero(~same):
            current[i][:] = new[i]
            value = tuple(new[i].tolist())
            message = make(impl.name, int(i), value)
            queue(message)  # (stamps the owner)
            # Its wire form, as viser's generic walk of the type hints would write it (the
            # same dict, a tenth of the cost; ~115 a frame for the extensible arm).
            message.__dict__.setdefault(_WIRE, {"name": impl.name, "bone_index": int(i),
                                                field: value, "owner": message.owner,
                                                "type": kind})
            sent += 1
    return sent
