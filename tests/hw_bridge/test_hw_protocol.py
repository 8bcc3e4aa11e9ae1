"""Protocol framing: COBS and CRC against published vectors, layouts, round trips, error counting."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hw_bridge import protocol as p

# Wikipedia "Consistent Overhead Byte Stuffing", encoding examples 1-11 (without the delimiter).
_SEQ254 = bytes(range(1, 255))
COBS_VECTORS = [
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x00\x11\x00", b"\x01\x02\x11\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (_SEQ254, b"\xff" + _SEQ254),
    (b"\x00" + _SEQ254, b"\x01\xff" + _SEQ254),
    (bytes(range(1, 256)), b"\xff" + _SEQ254 + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
    (bytes(range(3, 256)) + b"\x00\x01", b"\xfe" + bytes(range(3, 256)) + b"\x02\x01"),
]


@pytest.mark.parametrize("raw,enc", COBS_VECTORS)
def test_cobs_matches_published_vectors(raw: bytes, enc: bytes) -> None:
    assert p.cobs_encode(raw) == enc
    assert p.cobs_decode(enc) == raw


@given(st.binary(max_size=800))
def test_cobs_round_trip_has_no_zero(data: bytes) -> None:
    enc = p.cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + len(data) // 254 + 1
    assert p.cobs_decode(enc) == data


def test_crc_is_ccitt_false() -> None:
    # Catalogue check value of CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740) for "123456789".
    assert p.crc16(b"123456789") == 0x29B1


def test_demand_wire_layout_by_hand() -> None:
    msg = p.Demand(seq=0x01020304, mask=0b101, counts=(-2, 70000), flags=0x80)
    body = bytes([0x10]) + bytes([4, 3, 2, 1, 0x80, 5, 0, 0, 0]) + (-2).to_bytes(4, "little", signed=True) \
        + (70000).to_bytes(4, "little", signed=True)
    crc = p.crc16(body)
    expected = p.cobs_encode(body + bytes([crc & 0xFF, crc >> 8])) + b"\x00"
    assert p.encode(msg) == expected
    assert p.decode_frame(expected[:-1]) == msg


def test_state_layout_by_hand() -> None:
    msg = p.State(seq=7, ack_seq=6, mcu_time_us=123456, status=p.Status.ARMED | p.Status.ESTOP,
                  rx_errors=3, positions=(1, -1), velocities=(10, -10))
    body = p.encode_payload(msg)
    assert body[0] == 0x11
    assert struct.unpack_from("<IIIHHBB", body, 1) == (7, 6, 123456, 0x05, 3, 2, 1)
    assert struct.unpack_from("<4i", body, 19) == (1, -1, 10, -10)


int32 = st.integers(-(2**31), 2**31 - 1)
u32 = st.integers(0, 2**32 - 1)


@st.composite
def demands(draw: st.DrawFn) -> p.Demand:
    mask = draw(st.integers(0, 2**32 - 1))
    n = bin(mask).count("1")
    return p.Demand(draw(u32), mask, tuple(draw(st.lists(int32, min_size=n, max_size=n))),
                    draw(st.integers(0, 255)))


@st.composite
def states(draw: st.DrawFn) -> p.State:
    n = draw(st.integers(0, p.MAX_MOTORS))
    pos = tuple(draw(st.lists(int32, min_size=n, max_size=n)))
    vel = draw(st.none() | st.lists(int32, min_size=n, max_size=n).map(tuple))
    return p.State(draw(u32), draw(u32), draw(u32), draw(st.integers(0, 0xFFFF)),
                   draw(st.integers(0, 0xFFFF)), pos, vel)


messages = st.one_of(
    st.builds(p.Hello, st.integers(0, 255), st.integers(0, 255), st.integers(0, 0xFFFF)),
    st.just(p.Arm()), st.just(p.Disarm()), demands(), states(),
    st.builds(p.Config, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 255), int32),
    st.builds(p.ConfigAck, st.integers(0, 0xFFFF), st.integers(0, 255)),
)


@settings(max_examples=300)
@given(messages)
def test_every_message_round_trips(msg: p.Message) -> None:
    frame = p.encode(msg)
    assert frame.endswith(b"\x00") and 0 not in frame[:-1]
    assert len(frame) - 1 <= p.MAX_ENCODED
    assert p.decode_frame(frame[:-1]) == msg


@settings(max_examples=200)
@given(st.lists(messages, min_size=1, max_size=8), st.data())
def test_stream_decoder_is_independent_of_chunking(msgs: list[p.Message], data: st.DataObject) -> None:
    stream = b"".join(p.encode(m) for m in msgs)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=12)))
    dec = p.StreamDecoder()
    out: list[p.Message] = []
    prev = 0
    for c in cuts + [len(stream)]:
        out += dec.feed(stream[prev:c])
        prev = c
    assert out == msgs
    assert dec.stats.frames == len(msgs) and dec.stats.bad_frames == 0


def _frame_from_body(body: bytes) -> bytes:
    return p.cobs_encode(body + struct.pack("<H", p.crc16(body))) + b"\x00"


def test_each_kind_of_bad_frame_is_counted_once() -> None:
    good = p.encode(p.Arm())
    body = p.encode_payload(p.Demand.full(1, [5, 6]))
    crc_bad = p.cobs_encode(body + struct.pack("<H", p.crc16(body) ^ 0x0100)) + b"\x00"
    unknown = _frame_from_body(bytes([0x7F, 1, 2]))
    bad_len = _frame_from_body(bytes([p.MsgType.ARM, 9]))
    bad_demand = _frame_from_body(bytes([p.MsgType.DEMAND]) + struct.pack("<IBI", 1, 0, 0b11) + b"\x01\x00\x00\x00")
    bad_cobs = b"\x09\x01\x02\x00"  # code says 8 data bytes follow, only 2 do
    overflow = b"\x01" * (p.MAX_ENCODED + 5) + b"\x00"
    stream = b"\x00\x00" + good + bytes(crc_bad) + unknown + bad_len + bad_demand + bad_cobs \
        + overflow + good
    dec = p.StreamDecoder()
    out = dec.feed(stream)
    assert out == [p.Arm(), p.Arm()]
    s = dec.stats
    assert (s.frames, s.crc_errors, s.unknown_type, s.length_errors, s.cobs_errors, s.overflow) == \
        (2, 1, 1, 2, 1, 1)


def test_encoder_rejects_inconsistent_messages() -> None:
    with pytest.raises(ValueError, match="mask"):
        p.encode(p.Demand(1, 0b111, (1, 2)))
    with pytest.raises(ValueError, match="int32"):
        p.encode(p.Demand.full(1, [2**31]))
    with pytest.raises(ValueError, match="velocities"):
        p.encode(p.State(1, 1, 0, 0, 0, (1, 2), (1,)))


def test_sequence_arithmetic_wraps() -> None:
    assert p.seq_newer(5, 4) and not p.seq_newer(4, 5) and not p.seq_newer(4, 4)
    assert p.seq_newer(0, 0xFFFFFFFF) and p.seq_newer(3, 0xFFFFFFF0)
    assert not p.seq_newer(0xFFFFFFF0, 3)
