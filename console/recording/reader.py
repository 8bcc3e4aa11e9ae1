"""Reads a session recording back for the replay panel and the HTML export, within a budget.

:func:`load_recording` reads a recording (:mod:`console.recording.recorder` has the format;
``.mcap`` goes through :func:`console.recording.mcap_format.load_mcap`) into a
:class:`~console.recording.timeline.Recording` with a timeline. It streams within a
:class:`~console.recording.timeline.ReadBudget` (uncompressed bytes, records, one line's length,
event bytes) and checks every record as it goes, so a huge or corrupt file is refused quickly
with the line that is wrong. What both readers return and the file-format constants the writer
and both readers share live in :mod:`console.recording.timeline`;
``console.recording.recorder`` re-exports every public name.
"""

from __future__ import annotations

import gzip
import json
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from console.core.model import ArmModel
from console.recording.mcap_format import load_mcap
from console.recording.timeline import (FORMAT, MCAP_SUFFIX, Array, Event, ReadBudget, Recording,
                                        describe_record)


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
        return load_mcap(path, model, budget)
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
                                        describe_record(rec), rec.get("data")))
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
