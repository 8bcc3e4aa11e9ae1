"""Session recording and replay, so a lab session can be kept, reviewed and shared.

Recordings live in ``<data-dir>/recordings/``. New ones are MCAP files (``.mcap``: typed
channels that Foxglove and Lichtblick open, see ``core.labdata`` and ``console.recording.mcap_format``);
:func:`load_recording` reads those and the older gzip'd JSON-lines files (``.jsonl.gz``), which
``python -m core.labdata convert`` turns into MCAP. Both hold the same records. In a JSON-lines
file the first line is a header (robot, configuration shape, who started it, wall-clock start);
every other line has ``t`` (s since the start), ``kind`` and, for things people did, ``who`` and
``client``:

* ``state`` -- the displayed configuration once per render tick: ``q``, ``seq``, ``source``
  (and ``command``, the newest commanded configuration, when the caller passes it).
* ``action`` -- an operator action or a refusal (``what``), e.g. "took control", "STOP".
* anything else panels log with ``app.recorder.log(kind, payload, client)`` -- ``plan``,
  ``objects``, ``telemetry``, ... -- stored as ``data`` (numpy arrays become lists). Records of
  kind ``overlay`` with ``data = {"name": str, "points": [[x, y, z], ...], "color": [r, g, b]}``
  are also drawn as polylines when the run is replayed or exported.

:class:`Recorder` is cheap to call from any thread (``log`` only enqueues; a writer thread
encodes and writes); :func:`load_recording` (:mod:`console.recording.reader`, re-exported here)
reads a file back into a :class:`Recording` with a timeline for the replay panel and the HTML
export. It streams within a :class:`ReadBudget` (uncompressed bytes, records, one line's length,
event bytes) and checks every record as it goes, so a huge or corrupt file is refused quickly
with the line that is wrong.
"""

from __future__ import annotations

import dataclasses
import gzip
import json
import logging
import queue
import threading
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from console.core.access import client_id_of
from console.core.datadir import DataDir
from console.core.model import ArmModel
from console.recording.reader import load_recording
from console.recording.timeline import (FORMAT, MAX_DECOMPRESSED, MCAP_SUFFIX, SUFFIX, SUFFIXES,
                                        Event, ReadBudget, Recording)
from console.core.state import ArmState
from core.labdata.channels import latch_key

__all__ = ["FORMAT", "MAX_DECOMPRESSED", "MCAP_SUFFIX", "SUFFIX", "SUFFIXES", "Event",
           "ReadBudget", "Recorder", "Recording", "load_recording"]

log = logging.getLogger(__name__)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    if isinstance(obj, (Path, set, tuple)):
        return list(obj) if not isinstance(obj, Path) else str(obj)
    return repr(obj)


class Recorder:
    """Writes one recording at a time (see the module docstring); thread-safe.

    Args:
        data: The console's data folder (or a function returning it, called on start).
        model: The arm model (header: robot name, kind, configuration shape).
        name_of: ``name_of(client)`` -> display name of a viser client (or None).
        max_queue: Lines buffered for the writer before new ones are dropped (and counted).
        suffix: ``.mcap`` (default) or ``.jsonl.gz`` (the older format).
    """

    def __init__(self, data: DataDir | Callable[[], DataDir], model: ArmModel,
                 name_of: Callable[[Any], str] = lambda c: "server" if c is None else str(c),
                 max_queue: int = 20000, suffix: str = MCAP_SUFFIX) -> None:
        if suffix not in SUFFIXES:
            raise ValueError(f"suffix must be one of {SUFFIXES}, got {suffix!r}")
        self.suffix = suffix
        self.taps: list[Callable[[dict[str, Any], int], None]] = []
        self._start_hooks: list[Callable[[], None]] = []
        self.data = data
        self.model = model
        self.name_of = name_of
        self.dropped = 0
        self.lines = 0
        self._max_queue = max_queue
        self._lock = threading.Lock()
        self._queue: queue.Queue[dict[str, Any] | None] | None = None
        self._thread: threading.Thread | None = None
        self._t0 = 0.0
        self._start_ns = 0
        self.path: Path | None = None
        self._tick_offset_ns: int | None = None  # on_ticks: log ns of the loop's t = 0
        self._tick_last = 0.0  # on_ticks: the newest tick index recorded
        self._latched: dict[str, dict[str, Any]] = {}  # newest state record per latch_key
        self._latch_lock = threading.Lock()

    @property
    def recording(self) -> bool:
        return self._queue is not None

    def elapsed(self) -> float:
        return time.perf_counter() - self._t0 if self.recording else 0.0

    def start(self, stem: str = "", client: Any = None) -> Path:
        """Start a new recording named from ``stem`` (cleaned) and the time; returns its path.

        Raises:
            RuntimeError: a recording is already running.
        """
        with self._lock:
            if self._queue is not None:
                name = self.path.name if self.path is not None else "?"
                raise RuntimeError(f"already recording to {name}")
            data = self.data if isinstance(self.data, DataDir) else self.data()
            name = data.new_name("recordings", stem, self.suffix)
            path = data.path("recordings", name, self.suffix)
            q: queue.Queue[dict[str, Any] | None] = queue.Queue(self._max_queue)
            robot = self.model.robot
            header = {"kind": "header", "format": FORMAT, "robot": robot.name,
                      "robot_kind": self.model.kind, "shape": list(self.model.shape),
                      "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                      "by": self.name_of(client), "t": 0.0}
            self._t0 = time.perf_counter()
            self._start_ns = time.time_ns()  # log time of t = 0 (the console's clock)
            if self.suffix == SUFFIX:
                q.put(header)
            self.path, self._queue, self.dropped, self.lines = path, q, 0, 0
            for record in self.latched():  # the scene as it is now, at t = 0
                record["t"] = 0.0
                if self.suffix == MCAP_SUFFIX:
                    record["ns"] = self._start_ns
                q.put_nowait(record)
            self._tick_offset_ns, self._tick_last = None, 0.0
            self._thread = threading.Thread(target=self._write, args=(path, q, header),
                                            name="console-recorder", daemon=True)
            self._thread.start()
        for hook in list(self._start_hooks):
            try:
                hook()
            except Exception:  # a panel's hook must never stop a recording from starting
                log.exception("recording start hook failed")
        return path

    def add_start_hook(self, fn: Callable[[], None]) -> None:
        """Call ``fn()`` right after every :meth:`start` (e.g. to log the current obstacle
        scene, which is otherwise logged only when it changes)."""
        self._start_hooks.append(fn)

    def stop(self) -> Path | None:
        """Finish the recording (flushes and closes the file); returns its path."""
        with self._lock:
            q, thread, path = self._queue, self._thread, self.path
            self._queue = self._thread = None
        if q is None:
            return None
        q.put(None)
        if thread is not None:
            thread.join(10.0)
        return path

    def log(self, kind: str, payload: Any = None, client: Any = None) -> None:
        """Append a record of ``kind`` (no-op when not recording); ``payload`` JSON-able."""
        if kind in ("header", "state"):
            raise ValueError(f"kind {kind!r} is reserved")
        cid = client_id_of(client)
        self._put({"kind": kind, "who": self.name_of(client), "client": cid, "data": payload})

    def action(self, what: str, client: Any = None, **extra: Any) -> None:
        """Record something a person did (or was refused): ``what`` in words."""
        cid = client_id_of(client)
        self._put({"kind": "action", "who": self.name_of(client), "client": cid, "what": what,
                   **extra})

    def on_state(self, state: ArmState, command: ArmState | None = None) -> None:
        """Record a drawn state (the render thread calls this every frame) and, if given, the
        newest commanded state (with hardware the drawn one is the measurement)."""
        record: dict[str, Any] = {"kind": "state", "q": np.asarray(state.q).tolist(),
                                  "seq": state.seq, "source": state.source}
        if command is not None:
            record["command"] = np.asarray(command.q).tolist()
        if self._queue is not None or self.taps:
            self._put(record)
        else:  # kept all the same: a recording started later begins with the arm as drawn now
            with self._latch_lock:
                self._latched["state"] = record

    def on_ticks(self, batch: Any) -> None:
        """Record a batch of the arm loop's ticks (``core.labdata.ticks.TickBatch``, from the
        loop process's reader thread): MCAP recordings only, never the live taps.

        A tick's log time is the loop's own time plus one offset per loop run (fixed by the
        first batch: the arrival time less its newest tick's loop time; again after a restart
        of the loop), so the ticks keep the loop's 10 ms spacing."""
        q = self._queue
        if q is None or self.suffix != MCAP_SUFFIX or len(batch.rows) == 0:
            return
        t_last = float(batch.rows[-1, 1])
        first_tick = float(batch.rows[0, 0])
        if self._tick_offset_ns is None or first_tick <= self._tick_last:  # new loop run
            self._tick_offset_ns = time.time_ns() - int(t_last * 1e9)
        self._tick_last = float(batch.rows[-1, 0])
        try:
            q.put_nowait({"kind": "ticks", "batch": batch, "offset_ns": self._tick_offset_ns})
        except queue.Full:
            self.dropped += 1

    def add_tap(self, fn: Callable[[dict[str, Any], int], None], latched: bool = False) -> None:
        """Also hand every record, recording or not, to ``fn(record, ns)`` (ns: the console's
        clock, ns since the epoch); ``fn`` runs on the caller's thread and must only enqueue.

        With ``latched``, ``fn`` first gets a copy of every latched record (:meth:`latched`)
        in the same step as it joins, so no state logged meanwhile by another thread is missed
        (one logged just then may come twice). Read apart, a record logged between
        :meth:`latched` and joining reached neither (a late Foxglove viewer's table stayed
        empty, issue 29)."""
        with self._latch_lock:
            if latched:
                ns = time.time_ns()
                for r in self._latched.values():
                    fn({k: v for k, v in r.items() if k not in ("t", "ns")}, ns)
            self.taps.append(fn)

    def latched(self) -> list[dict[str, Any]]:
        """Copies of the newest record of every latched kind
        (``core.labdata.channels.latch_key``), in the order they were first seen: what a new recording or live viewer starts with."""
        with self._latch_lock:
            return [{k: v for k, v in r.items() if k not in ("t", "ns")}
                    for r in self._latched.values()]

    def _put(self, record: dict[str, Any]) -> None:
        key = latch_key(record)
        if key is not None:
            with self._latch_lock:
                self._latched[key] = dict(record)
        for tap in self.taps:
            try:
                tap(dict(record), time.time_ns())
            except Exception:  # a live viewer must never break recording or the caller
                log.debug("recorder tap failed", exc_info=True)
        q = self._queue
        if q is None:
            return
        elapsed = time.perf_counter() - self._t0
        record["t"] = round(elapsed, 4)
        if self.suffix == MCAP_SUFFIX:  # exact log time (the console's clock, ns)
            record["ns"] = self._start_ns + int(elapsed * 1e9)
        try:
            q.put_nowait(record)
        except queue.Full:
            self.dropped += 1

    def _write(self, path: Path, q: queue.Queue[dict[str, Any] | None],
               header: dict[str, Any]) -> None:
        if path.name.endswith(MCAP_SUFFIX):
            from console.recording.mcap_format import write_queue
            write_queue(path, q, header, self._start_ns, self.model, self._count)
            return
        last_flush = time.monotonic()
        with gzip.open(path, "wt", encoding="utf-8", compresslevel=6) as f:
            while True:
                try:
                    record = q.get(timeout=0.5)
                except queue.Empty:
                    record = {}
                if record is None:
                    break
                if record:
                    f.write(json.dumps(record, default=_json_default, separators=(",", ":")))
                    f.write("\n")
                    self._count()
                if time.monotonic() - last_flush > 1.0:  # a crash loses at most ~1 s
                    f.flush()
                    last_flush = time.monotonic()

    def _count(self) -> None:
        self.lines += 1
