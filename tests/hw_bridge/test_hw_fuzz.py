"""Fuzzing the stream decoder: no exception escapes and every completed bad frame is counted.

Expectation computed independently of the decoder: the byte stream is split at 0x00; every
non-empty completed segment must show up as exactly one decoded frame or one error count, and
an incomplete trailing segment longer than MAX_ENCODED is counted once as overflow.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hw_bridge import protocol as p


def _expected_accounted(stream: bytes) -> int:
    *complete, tail = stream.split(b"\x00")
    return sum(1 for seg in complete if seg) + (1 if len(tail) > p.MAX_ENCODED else 0)


def _feed_in_chunks(stream: bytes, rng: np.random.Generator) -> p.StreamDecoder:
    dec = p.StreamDecoder()
    i = 0
    while i < len(stream):
        n = int(rng.integers(1, 300))
        dec.feed(stream[i:i + n])
        i += n
    return dec


@settings(max_examples=500)
@given(st.binary(max_size=2000), st.integers(0, 2**32 - 1))
def test_random_bytes_never_raise_and_are_accounted(stream: bytes, seed: int) -> None:
    dec = _feed_in_chunks(stream, np.random.default_rng(seed))
    assert dec.stats.frames + dec.stats.bad_frames == _expected_accounted(stream)


def _valid_frames(rng: np.random.Generator, n: int) -> list[bytes]:
    frames = []
    for _ in range(n):
        k = int(rng.integers(0, 4))
        if k == 0:
            motors = int(rng.integers(1, 17))
            msg: p.Message = p.Demand.full(int(rng.integers(0, 2**32)),
                                           rng.integers(-(2**31), 2**31, motors).tolist())
        elif k == 1:
            motors = int(rng.integers(0, 17))
            msg = p.State(1, 2, 3, 1, 0, tuple(rng.integers(-(2**31), 2**31, motors).tolist()))
        elif k == 2:
            msg = p.Config(int(rng.integers(0, 65536)), 50, 1, 0)
        else:
            msg = p.Hello(1, 6, 50)
        frames.append(p.encode(msg))
    return frames


def _mutate(frame: bytes, rng: np.random.Generator) -> bytes:
    while (out := _mutate_once(frame, rng)) == frame:
        pass  # e.g. the same bit flipped twice: not a mutation
    return out


def _mutate_once(frame: bytes, rng: np.random.Generator) -> bytes:
    b = bytearray(frame[:-1])
    for _ in range(int(rng.integers(1, 4))):
        op = int(rng.integers(0, 4))
        if op == 0 and b:
            b[int(rng.integers(0, len(b)))] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:
            b.insert(int(rng.integers(0, len(b) + 1)), int(rng.integers(0, 256)))
        elif op == 2 and b:
            del b[int(rng.integers(0, len(b)))]
        elif b:
            del b[int(rng.integers(0, len(b))):]
    return bytes(b) + b"\x00"


def test_100k_random_and_mutated_frames() -> None:
    """50k random byte frames + 50k mutated valid frames, seeded; nothing escapes, all counted."""
    rng = np.random.default_rng(20240604)
    parts: list[bytes] = []
    for _ in range(50):
        lengths = rng.integers(0, 120, 1000)
        blob = rng.integers(1, 256, int(lengths.sum()), dtype=np.uint8)  # no 0x00 inside
        segments = np.split(blob, np.cumsum(lengths)[:-1])
        parts.append(b"\x00".join(seg.tobytes() for seg in segments) + b"\x00")
    mutated = [_mutate(f, rng) for f in _valid_frames(rng, 50_000)]
    stream = b"".join(parts) + b"".join(mutated)
    dec = _feed_in_chunks(stream, rng)
    s = dec.stats
    assert s.frames + s.bad_frames == _expected_accounted(stream)
    assert s.bad_frames > 90_000  # nearly all garbage is rejected ...
    assert s.crc_errors > 0 and s.cobs_errors > 0 and s.length_errors > 0
    # ... what still decodes is rare: a CRC-16 collision (~2**-16 of frames that survive COBS)
    # or a mutation that only inserted a 0x00 after a complete frame.
    assert s.frames < 20
