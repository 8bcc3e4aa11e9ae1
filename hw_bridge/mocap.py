"""Motion capture behind one interface whose ``latest()`` never blocks: UDP, replay, NatNet.

Sources: :class:`UdpMocapReceiver` (the emulator's stream), :class:`ReplayMocap` (a recorded
``.npz``) and :class:`NatNetMocap` (OptiTrack, optional ``natnet`` package, imported lazily).
Every :class:`MocapFrame` carries ``t_received`` on this host's ``time.monotonic`` clock;
:func:`frame_health` says whether the loop may use it (``"ok"``) or must hold the arm
(``"stale"`` older than 50 ms, ``"invalid"`` body not tracked, ``"missing"`` nothing yet).

UDP packet (little-endian): ``"MCAP" u16 version=1 u16 n_points u32 seq f64 t_capture
u8 valid`` then ``n_points * 3`` f64 ``[x, y, theta]``.
"""

from __future__ import annotations

import dataclasses
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Any, Callable, Literal, Protocol

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
STALE_AFTER_S = 0.05
_HEADER = struct.Struct("<4sHHIdB")
_MAGIC = b"MCAP"


@dataclasses.dataclass(frozen=True)
class MocapFrame:
    """Tracked arm shape: ``points`` (M, 3) of [x, y, theta] (segment ends, base first)."""

    seq: int
    t_capture: float
    t_received: float
    points: Array
    valid: bool


def frame_health(frame: MocapFrame | None, now: float | None = None,
                 max_age: float = STALE_AFTER_S) -> Literal["ok", "stale", "invalid", "missing"]:
    """Whether a frame may drive the loop; anything but ``"ok"`` means hold the arm."""
    if frame is None:
        return "missing"
    if not frame.valid or not np.all(np.isfinite(frame.points)):
        return "invalid"
    now = time.monotonic() if now is None else now
    return "stale" if now - frame.t_received > max_age else "ok"


class MocapSource(Protocol):
    """Common interface; ``latest()`` returns immediately."""

    def start(self) -> None: ...

    def stop(self) -> None: ...

    def latest(self) -> MocapFrame | None: ...


def encode_mocap_packet(seq: int, t_capture: float, points: npt.ArrayLike, valid: bool) -> bytes:
    """UDP packet for one frame (see module docstring)."""
    pts = np.ascontiguousarray(points, dtype="<f8")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (M, 3), got {pts.shape}")
    return _HEADER.pack(_MAGIC, 1, pts.shape[0], seq & 0xFFFFFFFF, t_capture, int(valid)) + pts.tobytes()


def decode_mocap_packet(data: bytes, t_received: float) -> MocapFrame | None:
    """Parse a packet; None if it is not a well-formed version-1 packet."""
    if len(data) < _HEADER.size:
        return None
    magic, version, n, seq, t_cap, valid = _HEADER.unpack_from(data)
    if magic != _MAGIC or version != 1 or len(data) != _HEADER.size + 24 * n:
        return None
    pts = np.frombuffer(data, dtype="<f8", offset=_HEADER.size).reshape(n, 3).astype(float)
    return MocapFrame(seq, t_cap, t_received, pts, bool(valid))


class UdpMocapReceiver:
    """Receives the emulator's UDP frames on a background thread; ``latest()`` is a plain read."""

    def __init__(self, port: int, host: str = "127.0.0.1"):
        self.addr = (host, port)
        self.bad_packets = 0
        self.frames = 0
        self._latest: MocapFrame | None = None
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def start(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(self.addr)
        sock.settimeout(0.05)
        self._sock = sock
        self.addr = sock.getsockname()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, daemon=True, name="mocap-udp")
        self._thread.start()

    def _run(self) -> None:
        assert self._sock is not None
        while not self._stop.is_set():
            try:
                data = self._sock.recv(65536)
            except socket.timeout:
                continue
            except OSError:
                return
            frame = decode_mocap_packet(data, time.monotonic())
            if frame is None:
                self.bad_packets += 1
            else:
                self.frames += 1
                self._latest = frame  # single reference swap: atomic for readers

    def latest(self) -> MocapFrame | None:
        return self._latest

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._sock is not None:
            self._sock.close()


def save_recording(path: str | Path, frames: list[MocapFrame]) -> None:
    """Write frames (same point count) to ``.npz``: t (F,), points (F, M, 3), valid (F,)."""
    if not frames:
        raise ValueError("no frames to record")
    np.savez(path, t=np.array([f.t_capture for f in frames]),
             points=np.stack([f.points for f in frames]),
             valid=np.array([f.valid for f in frames]))


class ReplayMocap:
    """Plays a recording back in real time from :meth:`start`; frames are stamped as received now.

    Args:
        path: ``.npz`` written by :func:`save_recording`.
        loop: Start over at the end (otherwise the last frame is kept and goes stale).
        clock: Monotonic seconds.
    """

    def __init__(self, path: str | Path, loop: bool = True,
                 clock: Callable[[], float] = time.monotonic):
        with np.load(path) as data:
            self.t = np.asarray(data["t"], dtype=float)
            self.points = np.asarray(data["points"], dtype=float)
            self.valid = np.asarray(data["valid"], dtype=bool)
        if self.t.ndim != 1 or self.points.shape[:1] != self.t.shape or self.t.size == 0:
            raise ValueError(f"{path}: need t (F,), points (F, M, 3), valid (F,)")
        if np.any(np.diff(self.t) < 0):
            raise ValueError(f"{path}: timestamps must not decrease")
        self.loop = loop
        self.clock = clock
        self._start: float | None = None

    def start(self) -> None:
        self._start = self.clock()

    def stop(self) -> None:
        self._start = None

    def latest(self) -> MocapFrame | None:
        if self._start is None:
            return None
        now = self.clock()
        span = self.t[-1] - self.t[0]
        elapsed = now - self._start
        if elapsed > span and not self.loop:
            i = len(self.t) - 1
            t_rx = self._start + span
        else:
            rel = elapsed % span if span > 0 else 0.0
            i = int(np.searchsorted(self.t - self.t[0], rel, side="right")) - 1
            t_rx = now - (rel - (self.t[i] - self.t[0]))
        return MocapFrame(i, float(self.t[i]), t_rx, self.points[i].copy(), bool(self.valid[i]))


class NatNetMocap:
    """OptiTrack via the optional ``natnet`` package (rigid bodies -> points, planar pose).

    Each tracked rigid body id in ``body_ids`` becomes one point [x, y, yaw]; a body reported
    untracked makes the frame invalid. Not exercised in tests (needs the package and a server).
    """

    def __init__(self, server: str, body_ids: list[int]):
        try:
            import natnet  # noqa: F401  (optional dependency)
        except ImportError:
            raise ImportError("OptiTrack support needs the optional 'natnet' package "
                              "(pip install natnet); use the emulator's UDP stream or a "
                              "replay file instead") from None
        self._natnet: Any = natnet
        self.server = server
        self.body_ids = list(body_ids)
        self._latest: MocapFrame | None = None
        self._client: Any = None
        self._thread: threading.Thread | None = None
        self._seq = 0

    def _callback(self, rigid_bodies: Any, markers: Any, timing: Any) -> None:
        by_id = {rb.id_: rb for rb in rigid_bodies}
        pts = np.full((len(self.body_ids), 3), np.nan)
        valid = True
        for k, bid in enumerate(self.body_ids):
            rb = by_id.get(bid)
            if rb is None or not getattr(rb, "tracking_valid", True):
                valid = False
                continue
            x, y, _z = rb.position
            qx, qy, qz, qw = rb.orientation
            pts[k] = (x, y, np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz)))
        self._seq += 1
        self._latest = MocapFrame(self._seq, float(getattr(timing, "timestamp", 0.0)),
                                  time.monotonic(), pts, valid)

    def start(self) -> None:
        self._client = self._natnet.Client.connect(self.server)
        self._client.set_callback(self._callback)
        self._thread = threading.Thread(target=self._client.spin, daemon=True, name="natnet")
        self._thread.start()

    def latest(self) -> MocapFrame | None:
        return self._latest

    def stop(self) -> None:
        if self._client is not None and hasattr(self._client, "stop"):
            self._client.stop()
