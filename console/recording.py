"""Session recording and replay, so a lab session can be kept, reviewed and shared.

Recordings live in ``<data-dir>/recordings/``. New ones are MCAP files (``.mcap``: typed
channels that Foxglove and Lichtblick open, see ``core.labdata`` and ``console.recording_mcap``);
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
encodes and writes); :func:`load_recording` reads a file back into a :class:`Recording` with a
timeline for the replay panel and the HTML export. It streams within a :class:`ReadBudget`
(uncompressed bytes, records, one line's length, event bytes) and checks every record as it
goes, so a huge or corrupt file is refused quickly with the line that is wrong.
"""

from __future__ import annotations

import bisect
import dataclasses
import gzip
import json
import logging
import queue
import threading
import time
import zlib
from pathlib import Path
from typing import Any, Callable

import numpy as np
import numpy.typing as npt

from console.datadir import DataDir
from console.model import ArmModel
from console.state import ArmState

log = logging.getLogger(__name__)

Array = npt.NDArray[np.float64]
SUFFIX = ".jsonl.gz"  # the older format (still read, and written with suffix=SUFFIX)
MCAP_SUFFIX = ".mcap"
SUFFIXES = (MCAP_SUFFIX, SUFFIX)
FORMAT = "softarm-console-recording/1"
MAX_DECOMPRESSED = 256 * 1024 * 1024


@dataclasses.dataclass(frozen=True)
class ReadBudget:
    """What :func:`load_recording` reads at most before refusing a file.

    A recording stores one state per render tick (about 150 bytes at 30 Hz: 16 MB and 110 000
    records an hour), so the defaults hold about 9 hours; a longer session is several files.
    """

    max_bytes: int = MAX_DECOMPRESSED       # uncompressed bytes
    max_records: int = 1_000_000
    max_line_bytes: int = 1024 * 1024       # one record (a plan overlay is a few kB)
    max_event_bytes: int = 64 * 1024 * 1024  # non-state records, kept as parsed JSON


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
        cid = None if client is None else getattr(client, "client_id", client)
        self._put({"kind": kind, "who": self.name_of(client), "client": cid, "data": payload})

    def action(self, what: str, client: Any = None, **extra: Any) -> None:
        """Record something a person did (or was refused): ``what`` in words."""
        cid = None if client is None else getattr(client, "client_id", client)
        self._put({"kind": "action", "who": self.name_of(client), "client": cid, "what": what,
                   **extra})

    def on_state(self, state: ArmState, command: ArmState | None = None) -> None:
        """Record a drawn state (the render thread calls this every frame) and, if given, the
        newest commanded state (with hardware the drawn one is the measurement)."""
        if self._queue is not None or self.taps:
            record: dict[str, Any] = {"kind": "state", "q": np.asarray(state.q).tolist(),
                                      "seq": state.seq, "source": state.source}
            if command is not None:
                record["command"] = np.asarray(command.q).tolist()
            self._put(record)

    def add_tap(self, fn: Callable[[dict[str, Any], int], None]) -> None:
        """Also hand every record, recording or not, to ``fn(record, ns)`` (ns: the console's
        clock, ns since the epoch); ``fn`` runs on the caller's thread and must only enqueue."""
        self.taps.append(fn)

    def _put(self, record: dict[str, Any]) -> None:
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
            from console.recording_mcap import write_queue
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
        i = bisect.bisect_right([e.t for e in self.events], t)
        return self.events[max(0, i - k):i]

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


def _describe(rec: dict[str, Any]) -> str:
    if rec.get("kind") == "action":
        return str(rec.get("what", ""))
    data = rec.get("data")
    text = json.dumps(data, default=str) if data is not None else ""
    return text if len(text) <= 80 else text[:77] + "..."


def _finite_time(rec: dict[str, Any], where: str) -> float:
    t = rec.get("t")
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t):
        raise ValueError(f"{where}: 't' is {json.dumps(t)[:40]}, not a finite number of seconds")
    return float(t)


def _state_q(rec: dict[str, Any], shape: tuple[int, ...], where: str) -> Array:
    if "q" not in rec:
        raise ValueError(f"{where}: a state without 'q'")
    try:
        q = np.asarray(rec["q"], dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: 'q' is not a list of numbers") from None
    if q.shape != shape:
        raise ValueError(f"{where}: 'q' has shape {q.shape}, this arm's is {shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{where}: 'q' holds NaN or infinite values")
    return q


def _lines(f: Any, name: str, budget: ReadBudget) -> Any:
    """Lines of a binary stream within the budget (never reads more than one line ahead)."""
    total = 0
    n = 0
    while True:
        line = f.readline(budget.max_line_bytes + 1)
        if not line:
            return
        n += 1
        total += len(line)
        if len(line) > budget.max_line_bytes:
            raise ValueError(f"{name}: line {n} is longer than "
                             f"{budget.max_line_bytes >> 10} kB: not a console recording")
        if total > budget.max_bytes:
            raise ValueError(f"{name}: larger than {budget.max_bytes >> 20} MB uncompressed "
                             "(the replay limit)")
        if n > budget.max_records:
            raise ValueError(f"{name}: more than {budget.max_records:,} records (the replay "
                             "limit)")
        yield n, line


def load_recording(path: Path, model: ArmModel, budget: ReadBudget | None = None) -> Recording:
    """Read a recording for ``model``'s robot, streaming within ``budget``.

    Every record is checked as it is read (``t`` a finite number; a state's ``q`` of this arm's
    shape and finite), so a corrupt file is refused with the line that is wrong and nothing of
    it is replayed; a huge file is refused once it passes the budget, without reading further.

    Raises:
        ValueError: not a console recording, one of another robot, a corrupt record, or past
            the budget; the message says which.
    """
    if path.name.endswith(MCAP_SUFFIX):
        from console.recording_mcap import load_mcap
        return load_mcap(path, model)
    budget = budget or ReadBudget()
    shape = tuple(model.shape)
    times = np.empty(1024)
    qs = np.empty((1024, *shape))
    lines = np.empty(1024, dtype=np.int64)  # line number of each state, for messages
    n_states = 0
    sources: list[str] = []
    known: dict[str, str] = {}  # one string object per distinct source
    events: list[Event] = []
    event_bytes = 0
    header: dict[str, Any] | None = None
    name = path.name
    try:
        with gzip.open(path, "rb") as f:
            for n, raw in _lines(f, name, budget):
                where = f"{name}: line {n}"
                rec = json.loads(raw)
                if not isinstance(rec, dict):
                    raise ValueError(f"{where} is not an object")
                if n == 1:
                    if rec.get("kind") != "header" or rec.get("format") != FORMAT:
                        raise ValueError(f"{name} is not a console recording")
                    if (rec.get("robot_kind") != model.kind
                            or tuple(rec.get("shape", ())) != shape):
                        raise ValueError(f"{name} was recorded on '{rec.get('robot')}' "
                                         f"({rec.get('robot_kind')}), not on this console's "
                                         f"'{model.robot.name}'")
                    header = rec
                    continue
                t = _finite_time(rec, where)
                if rec.get("kind") == "state":
                    if n_states == len(times):  # grow by doubling: no per-record lists
                        times = np.resize(times, 2 * len(times))
                        qs = np.resize(qs, (2 * len(qs), *shape))
                        lines = np.resize(lines, 2 * len(lines))
                    q = rec.get("q")
                    try:  # fast path: a list of this arm's length copied into the row
                        if not isinstance(q, list) or len(q) != shape[0]:
                            raise ValueError
                        qs[n_states] = q
                    except (ValueError, TypeError):
                        qs[n_states] = _state_q(rec, shape, where)  # says what is wrong
                    times[n_states] = t
                    lines[n_states] = n
                    n_states += 1
                    source = rec.get("source", "")
                    sources.append(known.setdefault(source, str(source)) if isinstance(
                        source, str) else str(source))
                else:
                    event_bytes += len(raw)
                    if event_bytes > budget.max_event_bytes:
                        raise ValueError(f"{name}: more than {budget.max_event_bytes >> 20} MB "
                                         "of events (the replay limit)")
                    events.append(Event(t, str(rec.get("kind")), str(rec.get("who", "")),
                                        _describe(rec), rec.get("data")))
    except (OSError, EOFError, zlib.error, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{name}: cannot read ({exc})") from None
    except RecursionError:
        raise ValueError(f"{name}: a record is nested too deeply") from None
    if header is None:
        raise ValueError(f"{name} is empty")
    if not n_states:
        raise ValueError(f"{name} holds no arm states")
    finite = np.isfinite(qs[:n_states].reshape(n_states, -1)).all(axis=1)
    if not finite.all():
        bad = int(lines[int(np.argmin(finite))])
        raise ValueError(f"{name}: line {bad}: 'q' holds NaN or infinite values")
    order = np.argsort(times[:n_states], kind="stable")
    return Recording(name, header, times[:n_states][order], qs[:n_states][order],
                     [sources[i] for i in order], sorted(events, key=lambda e: e.t))
