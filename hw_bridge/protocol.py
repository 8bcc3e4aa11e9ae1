"""Wire protocol between the host and an arm controller: COBS frames, CRC-16, little-endian messages.

A frame on the wire is ``COBS(type:u8 | payload | crc:u16le) 0x00`` where
``crc = binascii.crc_hqx(type | payload, 0xFFFF)`` (CRC-16/CCITT-FALSE, poly 0x1021).
The same layouts are implemented in C in ``firmware/arduino_due/protocol.c``; the frame table
and bandwidth figures are in ``docs/protocol.md``.

Semantics that matter for safety:

* DEMAND is streamed by the host at 100 Hz and never retransmitted; the device applies the
  newest sequence number (serial-number arithmetic, RFC 1982) and ignores older ones.
* Every accepted DEMAND is echoed as ``State.ack_seq`` in the next STATE, armed or not, so a
  host can measure round trips and losses without arming (the link probe does that).
* HELLO and ARM reset the device's sequence window so a restarted host may begin at seq 1.
"""

from __future__ import annotations

import binascii
import dataclasses
import enum
import struct
from typing import Union

PROTOCOL_VERSION = 1
MAX_MOTORS = 32
#: Largest decoded frame (type + payload + crc): a STATE with 32 positions and velocities.
MAX_DECODED = 1 + 18 + 8 * MAX_MOTORS + 2
#: Largest COBS-encoded frame without the delimiter.
MAX_ENCODED = MAX_DECODED + MAX_DECODED // 254 + 1
DELIMITER = b"\x00"


class MsgType(enum.IntEnum):
    """First byte of every frame."""

    HELLO = 0x01
    ARM = 0x02
    DISARM = 0x03
    DEMAND = 0x10
    STATE = 0x11
    CONFIG = 0x20
    CONFIG_ACK = 0x21


class Status(enum.IntFlag):
    """Status bits of a STATE message."""

    ARMED = 0x01
    WATCHDOG_TRIPPED = 0x02
    ESTOP = 0x04
    FAULT = 0x08


STATE_HAS_VELOCITIES = 0x01
TELEMETRY_VELOCITIES = 0x01
CONFIG_OK = 0
CONFIG_REJECTED = 1


@dataclasses.dataclass(frozen=True)
class Hello:
    """Handshake. The host sends n_motors=0, watchdog_ms=0; the device answers with its values."""

    version: int = PROTOCOL_VERSION
    n_motors: int = 0
    watchdog_ms: int = 0


@dataclasses.dataclass(frozen=True)
class Arm:
    """Enable the motors; clears a latched watchdog trip; the device holds its current position."""


@dataclasses.dataclass(frozen=True)
class Disarm:
    """Disable the motors (controlled stop)."""


@dataclasses.dataclass(frozen=True)
class Demand:
    """Position demands for the motors whose bits are set in ``mask``, in bit order.

    ``len(counts)`` must equal the number of set bits of ``mask``.
    """

    seq: int
    mask: int
    counts: tuple[int, ...]
    flags: int = 0

    @classmethod
    def full(cls, seq: int, counts: "list[int] | tuple[int, ...]", flags: int = 0) -> "Demand":
        """Demand for motors 0..len(counts)-1."""
        return cls(seq=seq, mask=(1 << len(counts)) - 1, counts=tuple(int(c) for c in counts),
                   flags=flags)


@dataclasses.dataclass(frozen=True)
class State:
    """Device telemetry: encoder positions (counts) and optionally velocities (counts/s)."""

    seq: int
    ack_seq: int
    mcu_time_us: int
    status: int
    rx_errors: int
    positions: tuple[int, ...]
    velocities: tuple[int, ...] | None = None


@dataclasses.dataclass(frozen=True)
class Config:
    """Runtime settings; the device answers CONFIG_ACK with the same ``config_id``.

    ``max_speed`` in counts/s (0 keeps the device's value).
    """

    config_id: int
    watchdog_ms: int
    telemetry: int = 0
    max_speed: int = 0


@dataclasses.dataclass(frozen=True)
class ConfigAck:
    """Answer to CONFIG: ``result`` is CONFIG_OK or CONFIG_REJECTED."""

    config_id: int
    result: int = CONFIG_OK


Message = Union[Hello, Arm, Disarm, Demand, State, Config, ConfigAck]

_HELLO = struct.Struct("<BBH")
_DEMAND = struct.Struct("<IBI")
_STATE = struct.Struct("<IIIHHBB")
_CONFIG = struct.Struct("<HHBBi")
_ACK = struct.Struct("<HB")
_CRC = struct.Struct("<H")


class DecodeError(ValueError):
    """A frame could not be decoded; ``kind`` is the counter it belongs to."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor-out)."""
    return binascii.crc_hqx(data, 0xFFFF)


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing; the output contains no zero byte (no delimiter added)."""
    out = bytearray()
    parts = bytes(data).split(b"\x00")
    last = len(parts) - 1
    for i, part in enumerate(parts):
        full_blocks = False
        while len(part) >= 254:
            out.append(0xFF)
            out += part[:254]
            part = part[254:]
            full_blocks = True
        if i == last and full_blocks and not part:
            break  # a run of 254 at the very end needs no trailing code byte
        out.append(len(part) + 1)
        out += part
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises DecodeError('cobs') on malformed input."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        end = i + code
        if code == 0 or end > n:
            raise DecodeError("cobs", f"bad COBS code {code} at {i} (frame length {n})")
        block = data[i + 1:end]
        if 0 in block:
            raise DecodeError("cobs", "zero byte inside a COBS frame")
        out += block
        i = end
        if code < 0xFF and i < n:
            out.append(0)
    return bytes(out)


def _check_counts(name: str, values: tuple[int, ...]) -> None:
    if len(values) > MAX_MOTORS:
        raise ValueError(f"{name}: at most {MAX_MOTORS} values, got {len(values)}")
    for v in values:
        if not -(1 << 31) <= v < (1 << 31):
            raise ValueError(f"{name}: {v} does not fit int32")


def encode_payload(msg: Message) -> bytes:
    """Type byte and payload of ``msg`` (no CRC, no COBS)."""
    if isinstance(msg, Hello):
        return bytes([MsgType.HELLO]) + _HELLO.pack(msg.version, msg.n_motors, msg.watchdog_ms)
    if isinstance(msg, Arm):
        return bytes([MsgType.ARM])
    if isinstance(msg, Disarm):
        return bytes([MsgType.DISARM])
    if isinstance(msg, Demand):
        if not 0 <= msg.mask < (1 << MAX_MOTORS):
            raise ValueError(f"demand mask {msg.mask:#x} out of range")
        if bin(msg.mask).count("1") != len(msg.counts):
            raise ValueError(f"demand mask {msg.mask:#x} has {bin(msg.mask).count('1')} bits "
                             f"but {len(msg.counts)} counts were given")
        _check_counts("demand counts", msg.counts)
        return (bytes([MsgType.DEMAND]) + _DEMAND.pack(msg.seq & 0xFFFFFFFF, msg.flags, msg.mask)
                + struct.pack(f"<{len(msg.counts)}i", *msg.counts))
    if isinstance(msg, State):
        n = len(msg.positions)
        _check_counts("state positions", msg.positions)
        flags = 0
        tail = b""
        if msg.velocities is not None:
            if len(msg.velocities) != n:
                raise ValueError("state velocities must have one value per position")
            _check_counts("state velocities", msg.velocities)
            flags = STATE_HAS_VELOCITIES
            tail = struct.pack(f"<{n}i", *msg.velocities)
        return (bytes([MsgType.STATE])
                + _STATE.pack(msg.seq & 0xFFFFFFFF, msg.ack_seq & 0xFFFFFFFF,
                              msg.mcu_time_us & 0xFFFFFFFF, msg.status, min(msg.rx_errors, 0xFFFF),
                              n, flags)
                + struct.pack(f"<{n}i", *msg.positions) + tail)
    if isinstance(msg, Config):
        return bytes([MsgType.CONFIG]) + _CONFIG.pack(msg.config_id, msg.watchdog_ms,
                                                      msg.telemetry, 0, msg.max_speed)
    if isinstance(msg, ConfigAck):
        return bytes([MsgType.CONFIG_ACK]) + _ACK.pack(msg.config_id, msg.result)
    raise TypeError(f"not a protocol message: {msg!r}")


def encode(msg: Message) -> bytes:
    """Complete wire frame for ``msg``, including the trailing 0x00 delimiter."""
    body = encode_payload(msg)
    return cobs_encode(body + _CRC.pack(crc16(body))) + DELIMITER


def _expect(body: bytes, size: int, name: str) -> None:
    if len(body) != size:
        raise DecodeError("length", f"{name}: expected {size} bytes, got {len(body)}")


def decode_payload(body: bytes) -> Message:
    """Parse type byte + payload (CRC already checked and stripped)."""
    if not body:
        raise DecodeError("length", "empty frame")
    kind, p = body[0], body[1:]
    if kind == MsgType.HELLO:
        _expect(p, _HELLO.size, "HELLO")
        return Hello(*_HELLO.unpack(p))
    if kind == MsgType.ARM:
        _expect(p, 0, "ARM")
        return Arm()
    if kind == MsgType.DISARM:
        _expect(p, 0, "DISARM")
        return Disarm()
    if kind == MsgType.DEMAND:
        if len(p) < _DEMAND.size:
            raise DecodeError("length", f"DEMAND: header needs {_DEMAND.size} bytes, got {len(p)}")
        seq, flags, mask = _DEMAND.unpack_from(p)
        n = bin(mask).count("1")
        _expect(p, _DEMAND.size + 4 * n, "DEMAND")
        return Demand(seq=seq, mask=mask, flags=flags,
                      counts=struct.unpack_from(f"<{n}i", p, _DEMAND.size))
    if kind == MsgType.STATE:
        if len(p) < _STATE.size:
            raise DecodeError("length", f"STATE: header needs {_STATE.size} bytes, got {len(p)}")
        seq, ack, t_us, status, rx_err, n, flags = _STATE.unpack_from(p)
        if n > MAX_MOTORS:
            raise DecodeError("length", f"STATE: {n} motors > {MAX_MOTORS}")
        has_vel = bool(flags & STATE_HAS_VELOCITIES)
        _expect(p, _STATE.size + 4 * n * (2 if has_vel else 1), "STATE")
        pos = struct.unpack_from(f"<{n}i", p, _STATE.size)
        vel = struct.unpack_from(f"<{n}i", p, _STATE.size + 4 * n) if has_vel else None
        return State(seq, ack, t_us, status, rx_err, pos, vel)
    if kind == MsgType.CONFIG:
        _expect(p, _CONFIG.size, "CONFIG")
        cid, wd, tel, _reserved, speed = _CONFIG.unpack(p)
        return Config(config_id=cid, watchdog_ms=wd, telemetry=tel, max_speed=speed)
    if kind == MsgType.CONFIG_ACK:
        _expect(p, _ACK.size, "CONFIG_ACK")
        return ConfigAck(*_ACK.unpack(p))
    raise DecodeError("unknown_type", f"unknown message type {kind:#04x}")


def decode_frame(frame: bytes) -> Message:
    """Decode one COBS frame (without the delimiter); raises DecodeError."""
    if len(frame) > MAX_ENCODED:
        raise DecodeError("length", f"frame of {len(frame)} bytes > {MAX_ENCODED}")
    raw = cobs_decode(frame)
    if len(raw) < 3:
        raise DecodeError("length", f"frame of {len(raw)} bytes is shorter than type + crc")
    body, crc = raw[:-2], _CRC.unpack(raw[-2:])[0]
    if crc16(body) != crc:
        raise DecodeError("crc", f"crc mismatch: got {crc:#06x}, computed {crc16(body):#06x}")
    return decode_payload(body)


@dataclasses.dataclass
class DecoderStats:
    """Counters of a StreamDecoder; every discarded frame increments exactly one error counter."""

    frames: int = 0
    crc_errors: int = 0
    cobs_errors: int = 0
    length_errors: int = 0
    unknown_type: int = 0
    overflow: int = 0

    @property
    def bad_frames(self) -> int:
        """All discarded frames."""
        return (self.crc_errors + self.cobs_errors + self.length_errors + self.unknown_type
                + self.overflow)


class StreamDecoder:
    """Turns arbitrary byte chunks into messages; never raises on bad input, counts it instead.

    Empty frames (consecutive delimiters) are ignored: a sender may emit a lone 0x00 to resync.
    A frame longer than MAX_ENCODED is discarded up to the next delimiter and counted once
    as ``overflow``.
    """

    def __init__(self) -> None:
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._overflowing = False

    def reset(self) -> None:
        """Drop any partial frame (e.g. after reopening a port); counters are kept."""
        self._buf.clear()
        self._overflowing = False

    def feed(self, chunk: bytes) -> list[Message]:
        """Consume ``chunk``; return the messages completed by it, in order."""
        out: list[Message] = []
        start = 0
        while True:
            end = chunk.find(0, start)
            if end < 0:
                self._append(chunk[start:])
                return out
            self._append(chunk[start:end])
            frame = bytes(self._buf)
            overflowing = self._overflowing
            self._buf.clear()
            self._overflowing = False
            start = end + 1
            if overflowing or not frame:
                continue
            try:
                msg = decode_frame(frame)
            except DecodeError as exc:
                setattr(self.stats, _COUNTER[exc.kind], getattr(self.stats, _COUNTER[exc.kind]) + 1)
            except Exception:  # pragma: no cover - defensive: nothing may escape
                self.stats.length_errors += 1
            else:
                self.stats.frames += 1
                out.append(msg)

    def _append(self, data: bytes) -> None:
        if self._overflowing or not data:
            return
        if len(self._buf) + len(data) > MAX_ENCODED:
            self._buf.clear()
            self._overflowing = True
            self.stats.overflow += 1
            return
        self._buf += data


_COUNTER = {"crc": "crc_errors", "cobs": "cobs_errors", "length": "length_errors",
            "unknown_type": "unknown_type"}


def seq_newer(seq: int, last: int) -> bool:
    """True if u32 ``seq`` comes after ``last`` (serial-number arithmetic, RFC 1982)."""
    d = (seq - last) & 0xFFFFFFFF
    return 0 < d < 0x80000000
