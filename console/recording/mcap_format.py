"""MCAP recordings in the console: the Recorder's writer loop and loading one for replay.

``console.recording.recorder.Recorder`` writes ``.mcap`` (the default) through :func:`write_queue`, on its
writer thread, with :class:`core.labdata.mcap_file.McapLog`; :func:`load_recording` of a
``.mcap`` file comes here (:func:`load_mcap`) and returns the same
:class:`~console.recording.recorder.Recording` as an old ``.jsonl.gz`` file does: the configuration
timeline from ``/arm/configuration``, events from ``/operator/actions`` and the typed and
``/console/*`` record channels.
"""

from __future__ import annotations

import json
import queue
from pathlib import Path
from typing import Any, Callable

import numpy as np

from console.core.model import ArmModel
from console.recording.timeline import (MAX_DECOMPRESSED, Event, ReadBudget, Recording,
                                        describe_record)
from core.labdata.channels import TICK_CHANNELS, ArmGeometry, record_from_message
from core.labdata.mcap_file import McapLog, iter_messages, read_header, stored_size

SUFFIX = ".mcap"
TICK_TOPICS = tuple(spec.topic for spec in TICK_CHANNELS)


def _replayed_topics(f: Any) -> list[str] | None:
    """The file's topics but the tick channels (None: all, when the file has no summary)."""
    from mcap.reader import make_reader

    summary = make_reader(f).get_summary()
    if summary is None:
        return None
    return [ch.topic for ch in summary.channels.values() if ch.topic not in TICK_TOPICS]


def write_queue(path: Path, q: queue.Queue[dict[str, Any] | None], header: dict[str, Any],
                start_ns: int, model: ArmModel, counted: Callable[[], None]) -> None:
    """Write records from ``q`` until ``None`` (the Recorder's writer thread runs this).

    The file is finished (summary and index written) when ``None`` arrives; a crash before
    that leaves the chunks written so far, which ``mcap recover`` restores.
    """
    # McapLog stamps its own format id (core.labdata.mcap_file.FORMAT); the JSON-lines id
    # (console.recording.timeline.FORMAT) is not this file's.
    log = McapLog(path, {k: v for k, v in header.items() if k not in ("kind", "t", "format")},
                  start_ns, ArmGeometry(model.robot))
    try:
        while True:
            try:
                record = q.get(timeout=0.5)
            except queue.Empty:
                continue
            if record is None:
                break
            log.record(record)
            counted()
    finally:
        log.close()


def load_mcap(path: Path, model: ArmModel, budget: ReadBudget | None = None) -> Recording:
    """Read a console MCAP recording for ``model``'s robot (see :func:`load_recording`).

    Within ``budget``: the file's summary (its chunk index and statistics) is checked before any
    message is decompressed (uncompressed bytes, message count); a file without a summary (a
    recording cut short) is counted message by message as it is read.

    Raises:
        ValueError: not a console recording, another robot's, unreadable or past the budget;
            says which.
    """
    budget = budget or ReadBudget()
    if path.stat().st_size > MAX_DECOMPRESSED:
        raise ValueError(f"{path.name}: larger than {MAX_DECOMPRESSED >> 20} MB")
    arm = ArmGeometry(model.robot)
    times: list[float] = []
    qs: list[np.ndarray] = []
    sources: list[str] = []
    events: list[Event] = []
    try:
        with open(path, "rb") as f:
            meta = read_header(f)
            header: dict[str, Any] = {}
            for key, value in meta.items():
                try:
                    header[key] = json.loads(value) if key in ("shape",) else value
                except json.JSONDecodeError:
                    header[key] = value
            if header.get("robot_kind") != model.kind or \
                    tuple(header.get("shape", ())) != model.shape:
                raise ValueError(f"{path.name} was recorded on '{header.get('robot')}' "
                                 f"({header.get('robot_kind')}), not on this console's "
                                 f"'{model.robot.name}'")
            start = int(header.get("start_ns", "0"))
            # The replay reads every channel but the 100 Hz ticks (it shows what the console
            # drew; the ticks are for the lab's tools), so only those count against the budget:
            # from the summary and message indexes before anything is decompressed, and again
            # as they are read (a file without a summary).
            f.seek(0)
            size = stored_size(f, exclude=TICK_TOPICS)  # None without a summary
            if size is not None and size[0] > budget.max_bytes:
                raise ValueError(f"{path.name}: larger than {budget.max_bytes >> 20} MB "
                                 "uncompressed (the replay limit)")
            if size is not None and size[1] > budget.max_records:
                raise ValueError(f"{path.name}: more than {budget.max_records:,} records (the "
                                 "replay limit)")
            f.seek(0)
            read = 0
            topics = _replayed_topics(f)
            f.seek(0)
            for n, m in enumerate(iter_messages(f, topics), 1):
                if m.topic in TICK_TOPICS:  # a file without a summary: read, not counted
                    continue
                read += m.size
                if read > budget.max_bytes:
                    raise ValueError(f"{path.name}: larger than {budget.max_bytes >> 20} MB "
                                     "uncompressed (the replay limit)")
                if n > budget.max_records:
                    raise ValueError(f"{path.name}: more than {budget.max_records:,} records "
                                     "(the replay limit)")
                rec = record_from_message(m.topic, m.message)
                if rec is None:
                    continue
                t = (m.log_time - start) / 1e9
                if rec["kind"] == "state":
                    qs.append(arm.q_of(rec["measured"]))
                    times.append(t)
                    sources.append(str(rec.get("source", "")))
                else:
                    events.append(Event(t, rec["kind"], str(rec.get("who", "")),
                                        describe_record(rec), rec.get("data")))
    except ValueError:
        raise
    except Exception as exc:  # mcap raises its own errors for truncated or foreign files
        raise ValueError(f"{path.name}: cannot read ({type(exc).__name__}: {exc})") from None
    header.setdefault("kind", "header")
    if not times:
        raise ValueError(f"{path.name} holds no arm states")
    arr = np.array(qs, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{path.name}: states are not finite")
    return Recording(path.name, header, np.array(times), arr, sources, events)
