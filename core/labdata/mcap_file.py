"""MCAP files of lab channels: a synchronous writer and a reader on the ``mcap`` package.

No threads here (the console's Recorder calls :class:`McapLog` from its writer thread; the trials
CLI from its main thread). A file holds JSON-encoded channels with JSON schemas (see
:mod:`core.labdata.channels`), chunked and zstd-compressed, and one metadata record
``softarm.recording`` with the header (robot, kind, shape, who started it, start time in ns).
Log times are the console's clock in ns since the epoch, never decreasing within a file, except
on the 100 Hz tick channels (:mod:`core.labdata.ticks`), whose log time is each tick's own loop
time (a batch arrives up to a publish period after its first tick).
"""

from __future__ import annotations

import dataclasses
import json
import struct
from pathlib import Path
from typing import Any, BinaryIO, Iterator

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from core.labdata.channels import ArmGeometry, ChannelSpec, json_safe, messages_for, spec_for
from core.labdata.ticks import TickBatch, tick_messages

PROFILE = ""  # plain JSON channels (no ROS profile)
LIBRARY = "softarm-console"
META_NAME = "softarm.recording"
FORMAT = "softarm-console-mcap/1"
MESSAGE_INDEX_OPCODE = 0x07  # the MCAP spec's Message Index record


class McapLog:
    """Writes console records (or channel messages) to one MCAP file.

    Args:
        target: Path to create (must not exist) or a binary file object.
        header: Recording header (robot, robot_kind, shape, by, started, ...): stored as
            metadata, strings only (other values JSON-encoded).
        start_ns: Log time of ``t = 0`` (ns since the epoch).
        arm: Geometry for the arm channels (needed when ``state`` records are written).
        chunk_size: Uncompressed bytes per chunk (256 KiB: ~2 s of a 30 Hz session, so a crash
            loses little; ``mcap recover`` restores the chunks written).
    """

    def __init__(self, target: str | Path | BinaryIO, header: dict[str, Any], start_ns: int,
                 arm: ArmGeometry | None = None, chunk_size: int = 256 << 10) -> None:
        if isinstance(target, (str, Path)):
            path = Path(target)
            if path.exists():
                raise FileExistsError(f"{path} exists")
            self._file: BinaryIO = open(path, "xb")  # noqa: SIM115 - closed by close()
            self._owned = True
        else:
            self._file, self._owned = target, False
        self.start_ns = int(start_ns)
        self.arm = arm
        self.messages = 0
        self.last_ns = self.start_ns
        self._writer = Writer(self._file, chunk_size=chunk_size,
                              compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        meta = {"format": FORMAT, "start_ns": str(self.start_ns)}
        for key, value in header.items():
            if key == "format":  # the file's format id is this writer's, never the caller's
                continue
            meta[str(key)] = value if isinstance(value, str) else json.dumps(value)
        self._writer.add_metadata(META_NAME, meta)
        self.closed = False

    def _channel(self, spec: ChannelSpec) -> int:
        cid = self._channels.get(spec.topic)
        if cid is None:
            sid = self._schemas.get(spec.schema_name)
            if sid is None:
                sid = self._writer.register_schema(
                    spec.schema_name, "jsonschema", json.dumps(spec.schema).encode("utf-8"))
                self._schemas[spec.schema_name] = sid
            cid = self._writer.register_channel(spec.topic, "json", sid)
            self._channels[spec.topic] = cid
        return cid

    def ns_of(self, t: float) -> int:
        """Log time of ``t`` s after the start, never before the last one written."""
        return max(self.start_ns + int(round(float(t) * 1e9)), self.last_ns)

    def write(self, topic: str, message: dict[str, Any], ns: int, clamp: bool = True) -> None:
        """One channel message at log time ``ns`` (clamped so log times never decrease, unless
        ``clamp`` is False: a tick's own time, which may be a little older than the last)."""
        cid = self._channel(spec_for(topic))
        ns = max(int(ns), self.last_ns) if clamp else int(ns)
        seq = self._seq.get(cid, 0)
        self._seq[cid] = seq + 1
        try:
            text = json.dumps(message, separators=(",", ":"), allow_nan=False)
        except (TypeError, ValueError):  # NaN/inf (e.g. a lost measurement) -> null; numpy
            text = json.dumps(json_safe(message), separators=(",", ":"), allow_nan=False)
        self._writer.add_message(cid, log_time=ns, publish_time=ns, sequence=seq,
                                 data=text.encode("utf-8"))
        self.last_ns = max(self.last_ns, ns)
        self.messages += 1

    def ticks(self, batch: TickBatch, offset_ns: int) -> None:
        """Every row of ``batch`` on its arm's tick channel at log time ``offset_ns`` plus its
        loop time (``core.labdata.ticks``)."""
        for topic, ns, msg in tick_messages(batch, lambda t: offset_ns + round(t * 1e9)):
            self.write(topic, msg, ns, clamp=False)

    def record(self, rec: dict[str, Any]) -> None:
        """Write console record ``rec`` on its channels, at its ``ns`` (epoch ns) if it has one,
        else ``t`` s after the start."""
        if rec.get("kind") == "ticks":  # {"batch": TickBatch, "offset_ns": log ns of t = 0}
            self.ticks(rec["batch"], int(rec["offset_ns"]))
            return
        ns = int(rec["ns"]) if "ns" in rec else self.ns_of(rec.get("t", 0.0))
        for topic, msg in messages_for(rec, ns, self.arm):
            self.write(topic, msg, ns)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._writer.finish()
        if self._owned:
            self._file.close()

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclasses.dataclass(frozen=True)
class LabMessage:
    """One decoded message: topic, schema name, log time (ns) and the JSON message."""

    topic: str
    schema_name: str
    log_time: int
    message: Any
    size: int = 0  # bytes of the encoded message


def read_header(f: BinaryIO) -> dict[str, str]:
    """The ``softarm.recording`` metadata of an MCAP file (ValueError if it has none)."""
    reader = make_reader(f)
    for meta in reader.iter_metadata():
        if meta.name == META_NAME:
            return dict(meta.metadata)
    raise ValueError("not a console recording (no softarm.recording metadata)")


def stored_size(f: BinaryIO, exclude: tuple[str, ...] = ()) -> tuple[int, int] | None:
    """(uncompressed bytes, message count) of the messages not on an ``exclude`` topic, from the
    file's summary and message indexes, read without decompressing a message; None when the
    file has no summary (a recording cut short).

    Without ``exclude`` the bytes are the chunks' uncompressed sizes. With it, each chunk counts
    the records of the other channels only: a record's size is the gap to the next record's
    offset in the decompressed chunk, which the chunk's message indexes (uncompressed, after the
    chunk) list for every channel; a chunk without indexes counts whole."""
    summary = make_reader(f).get_summary()
    if summary is None:
        return None
    stats = summary.statistics
    skipped = {cid for cid, ch in summary.channels.items() if ch.topic in exclude}
    count = (0 if stats is None else
             sum(int(n) for cid, n in stats.channel_message_counts.items() if cid not in skipped))
    if not skipped:
        return sum(int(ci.uncompressed_size) for ci in summary.chunk_indexes), count
    total = 0
    for ci in summary.chunk_indexes:
        if not ci.message_index_offsets:
            total += int(ci.uncompressed_size)
            continue
        entries: list[tuple[int, int]] = []  # (offset in the chunk, channel)
        f.seek(int(ci.chunk_start_offset) + int(ci.chunk_length))
        raw = f.read(int(ci.message_index_length))
        i = 0
        while i + 9 <= len(raw):
            opcode, length = raw[i], struct.unpack_from("<Q", raw, i + 1)[0]
            body = raw[i + 9:i + 9 + length]
            i += 9 + length
            if opcode != MESSAGE_INDEX_OPCODE or len(body) < 6:
                continue
            channel, n = struct.unpack_from("<HI", body, 0)
            for k in range(6, 6 + n - n % 16, 16):
                entries.append((struct.unpack_from("<Q", body, k + 8)[0], channel))
        entries.sort()
        ends = [o for o, _ in entries[1:]] + [int(ci.uncompressed_size)]
        total += sum(end - o for (o, ch), end in zip(entries, ends) if ch not in skipped)
    return total, count


def iter_messages(f: BinaryIO, topics: list[str] | None = None) -> Iterator[LabMessage]:
    """Decoded JSON messages in log-time order (ValueError for a non-JSON channel)."""
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages(topics=topics, log_time_order=True):
        if channel.message_encoding != "json":
            raise ValueError(f"channel {channel.topic} is {channel.message_encoding}, not json")
        yield LabMessage(channel.topic, schema.name if schema is not None else "",
                         message.log_time, json.loads(message.data), len(message.data))
