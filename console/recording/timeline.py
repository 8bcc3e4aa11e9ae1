"""What a loaded recording is, apart from reading one: its timeline, events and read budget.

:class:`Recording` (the configuration timeline with its events and overlays), :class:`Event`,
:class:`ReadBudget` and the file-format constants are shared by the writer
(:mod:`console.recording.recorder`) and both readers (:mod:`console.recording.reader` for
``.jsonl.gz``, :mod:`console.recording.mcap_format` for ``.mcap``); they live below all three,
so no reader imports another back.
"""

from __future__ import annotations

import bisect
import dataclasses
import json
from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
SUFFIX = ".jsonl.gz"  # the older format (still read, and written with suffix=SUFFIX)
MCAP_SUFFIX = ".mcap"
SUFFIXES = (MCAP_SUFFIX, SUFFIX)
FORMAT = "softarm-console-recording/1"
MAX_DECOMPRESSED = 256 * 1024 * 1024


@dataclasses.dataclass(frozen=True)
class ReadBudget:
    """What :func:`console.recording.reader.load_recording` reads at most before refusing a file.

    A recording stores one state per render tick (about 150 bytes at 30 Hz: 16 MB and 110 000
    records an hour), so the defaults hold about 9 hours; a longer session is several files.
    """

    max_bytes: int = MAX_DECOMPRESSED       # uncompressed bytes
    max_records: int = 1_000_000
    max_line_bytes: int = 1024 * 1024       # one record (a plan overlay is a few kB)
    max_event_bytes: int = 64 * 1024 * 1024  # non-state records, kept as parsed JSON


@dataclasses.dataclass(frozen=True)
class Event:
    """A non-state record of a recording, at time ``t``."""

    t: float
    kind: str
    who: str
    text: str
    data: Any = None


@dataclasses.dataclass
class Recording:
    """A loaded recording: the configuration timeline plus events and overlays."""

    name: str
    header: dict[str, Any]
    times: Array
    qs: Array
    sources: list[str]
    events: list[Event]

    _event_times: list[float] = dataclasses.field(init=False, repr=False, default_factory=list)
    _by_kind: dict[str, tuple[list[float], list[dict[str, Any]]]] = dataclasses.field(
        init=False, repr=False, default_factory=dict)

    def __post_init__(self) -> None:
        self.events.sort(key=lambda e: e.t)  # stable: records logged at one time keep order
        self._event_times = [e.t for e in self.events]
        for e in self.events:  # records with dict data, per kind (the table, the plan, ...)
            if isinstance(e.data, dict):
                times, datas = self._by_kind.setdefault(e.kind, ([], []))
                times.append(e.t)
                datas.append(e.data)

    @property
    def duration(self) -> float:
        return float(self.times[-1]) if len(self.times) else 0.0

    def index_at(self, t: float) -> int:
        """Index of the last state at or before ``t`` (0 before the first)."""
        return max(0, int(np.searchsorted(self.times, t, side="right")) - 1)

    def q_at(self, t: float) -> Array:
        return self.qs[self.index_at(t)]

    def events_until(self, t: float, k: int = 5) -> list[Event]:
        """The last ``k`` events at or before ``t``."""
        i = bisect.bisect_right(self._event_times, t)
        return self.events[max(0, i - k):i]

    def latest(self, kind: str, t: float) -> dict[str, Any] | None:
        """The data of the newest record of ``kind`` at or before ``t`` whose data is a dict
        (None before any): the table (``objects``) or the plan (``plan``) as it was then."""
        times, datas = self._by_kind.get(kind, ((), ()))
        i = bisect.bisect_right(times, t)
        return datas[i - 1] if i else None

    def obstacles_until(self, t: float) -> dict[str, Any] | None:
        """The newest ``objects`` record at or before ``t`` that lists obstacles (its data:
        ``obstacles`` [{name, x, y, r}] and ``clearance``), or None before any."""
        found = None
        for e in self.events:
            if e.t > t:
                break
            if e.kind == "objects" and isinstance(e.data, dict) and "obstacles" in e.data:
                found = e.data
        return found

    def overlays_until(self, t: float) -> dict[str, dict[str, Any]]:
        """Newest ``overlay`` record per name at or before ``t``."""
        out: dict[str, dict[str, Any]] = {}
        for e in self.events:
            if e.t > t:
                break
            if e.kind == "overlay" and isinstance(e.data, dict) and "name" in e.data:
                out[str(e.data["name"])] = e.data
        return out


def describe_record(rec: dict[str, Any]) -> str:
    """A non-state record in a few words for the replay's event list (at most 80 characters)."""
    if rec.get("kind") == "action":
        return str(rec.get("what", ""))
    data = rec.get("data")
    text = json.dumps(data, default=str) if data is not None else ""
    return text if len(text) <= 80 else text[:77] + "..."
