"""Every 100 Hz loop tick as lab data, so a lab can identify its arm and debug its controller.

The console's view of the arm is sampled at its render rate (~20-30 Hz); the loop itself runs
at 100 Hz. A :class:`TickRing` is filled by the loop thread at the end of every tick (a few
numbers written into a preallocated row: no allocation to speak of, no lock, never blocks) and
drained by another thread (the loop process's publisher) into a :class:`TickBatch`, a small
picklable block of rows that goes to the console with the published view. The console's
recorder writes each row as one message of the arm's tick channel (:data:`SOFT_ARM_TICKS`,
:data:`EXTENSIBLE_TICKS`; :func:`tick_messages`); ``python -m core.labdata export`` turns it
back into a table (:func:`tick_columns`).

A row (float64): tick index (from 1), loop time (s), armed, the phase's code, the tick's
timing (ms: late, period, work, read, update, write; missed deadlines) and the arm's own
values (:class:`SoftArmTicks`, :class:`ExtensibleTicks`). A value that is not known (no
measurement, no timing on a loop without one) is NaN in the row and omitted from the message.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from core.labdata.schemas import EXTENSIBLE_TICK, SOFT_ARM_TICK, Schema

Array = npt.NDArray[np.float64]

#: Row columns every arm shares (before the arm's own values).
TICK, T, ARMED, PHASE, LATE, PERIOD, WORK, READ, UPDATE, WRITE, MISSED = range(11)
COMMON = 11
TIMING_KEYS = ("late_ms", "period_ms", "work_ms", "read_ms", "update_ms", "write_ms")
NAN = float("nan")


class TickLayout(Protocol):
    """One arm's part of a tick row: how wide, how it is filled and how it is written."""

    arm: str
    width: int

    def fill(self, row: Array, reading: Any, commands: Any, control: Any) -> tuple[bool, str]:
        """Write the arm's values into ``row`` (its own columns, NaN when unknown); returns
        (armed, phase). Runs on the loop thread: cheap, never raises for a missing value."""
        ...

    def fields(self, row: Array) -> dict[str, Any]:
        """The arm's message fields of a filled ``row`` (unknown values omitted)."""
        ...

    def columns(self) -> list[str]:
        """The export table's column names of the arm's values, with units."""
        ...


def _put(row: Array, at: int, n: int, values: Any) -> None:
    """``row[at:at+n] = values`` (NaN when None or of another size); the loop thread's
    per-tick cost, so no array is made here."""
    if values is None:
        row[at:at + n] = NAN
        return
    if isinstance(values, np.ndarray) and values.ndim != 1:
        values = values.reshape(-1)
    try:
        if len(values) != n:  # (numpy would broadcast a single value over the slot)
            raise ValueError
        row[at:at + n] = values
    except (ValueError, TypeError):
        row[at:at + n] = NAN


def _values(row: Array, at: int, n: int, digits: int) -> list[float] | None:
    part = row[at:at + n]
    if n == 0 or not np.all(np.isfinite(part)):
        return None
    return [round(float(v), digits) for v in part]


class SoftArmTicks:
    """The soft arm's values (``core.control.stack.Telemetry``): target, reference and measured
    curvature per segment (1/m) and the command written to the device (cylinder volume counts,
    2N+1 channels)."""

    arm = "soft_arm"

    def __init__(self, n_segments: int, n_commands: int | None = None) -> None:
        self.n = int(n_segments)
        self.m = int(2 * self.n + 1 if n_commands is None else n_commands)
        self.width = COMMON + 3 * self.n + self.m

    def fill(self, row: Array, reading: Any, commands: Any, control: Any) -> tuple[bool, str]:
        n, at = self.n, COMMON
        if control is None:
            row[at:self.width] = NAN
            return False, "none"
        _put(row, at, n, getattr(control, "kappa_target", None))
        _put(row, at + n, n, getattr(control, "kappa_ref", None))
        _put(row, at + 2 * n, n, getattr(control, "kappa_meas", None))
        _put(row, at + 3 * n, self.m, commands)  # what was written (None: nothing this tick)
        return bool(getattr(control, "armed", False)), str(getattr(control, "phase", "none"))

    def fields(self, row: Array) -> dict[str, Any]:
        n, at, out = self.n, COMMON, {}
        for i, key in enumerate(("kappa_target_1_per_m", "kappa_reference_1_per_m",
                                 "kappa_measured_1_per_m")):
            v = _values(row, at + i * n, n, 6)
            if v is not None:
                out[key] = v
        v = _values(row, at + 3 * n, self.m, 3)
        if v is not None:
            out["command_counts"] = v
        return out

    def columns(self) -> list[str]:
        cols = [f"seg{i + 1}_{key}" for key in ("kappa_target_1_per_m", "kappa_reference_1_per_m",
                                                "kappa_measured_1_per_m")
                for i in range(self.n)]
        return cols + [f"cmd{j + 1}_counts" for j in range(self.m)]

    def field_columns(self) -> list[tuple[str, int]]:
        """(message field, length) in column order."""
        return [("kappa_target_1_per_m", self.n), ("kappa_reference_1_per_m", self.n),
                ("kappa_measured_1_per_m", self.n), ("command_counts", self.m)]


ARMED_STATES = ("holding", "following", "running", "settling")


class ExtensibleTicks:
    """The extensible arm's values (``hw_bridge.extensible_jobs.RunnerSnapshot`` and the
    encoder reading): the demand written to the motors and the encoders read (counts, the
    target and measured configuration in motor space), the measured Δ of every segment
    (dx, dy, dL in m) and the measured tip (m)."""

    arm = "extensible"

    def __init__(self, n_segments: int, n_motors: int | None = None) -> None:
        self.n = int(n_segments)
        self.m = int(3 * self.n if n_motors is None else n_motors)
        self.width = COMMON + 2 * self.m + 3 * self.n + 3

    def fill(self, row: Array, reading: Any, commands: Any, control: Any) -> tuple[bool, str]:
        m, n, at = self.m, self.n, COMMON
        _put(row, at, m, commands)
        _put(row, at + m, m, reading)
        _put(row, at + 2 * m, 3 * n, getattr(control, "measured_delta", None))
        _put(row, at + 2 * m + 3 * n, 3, getattr(control, "measured_tip", None))
        state = str(getattr(control, "state", "none"))
        return state in ARMED_STATES, state

    def fields(self, row: Array) -> dict[str, Any]:
        m, n, at, out = self.m, self.n, COMMON, {}
        for key, start, size, digits in (("demand_counts", at, m, 0),
                                         ("encoder_counts", at + m, m, 0),
                                         ("delta_measured_m", at + 2 * m, 3 * n, 7),
                                         ("tip_measured_m", at + 2 * m + 3 * n, 3, 7)):
            v = _values(row, start, size, digits)
            if v is not None:
                out[key] = [int(x) for x in v] if digits == 0 else v
        return out

    def columns(self) -> list[str]:
        cols = [f"motor{j + 1}_demand_counts" for j in range(self.m)]
        cols += [f"motor{j + 1}_encoder_counts" for j in range(self.m)]
        cols += [f"seg{i + 1}_{c}_measured_m" for i in range(self.n) for c in ("dx", "dy", "dL")]
        return cols + [f"tip_{c}_measured_m" for c in "xyz"]

    def field_columns(self) -> list[tuple[str, int]]:
        return [("demand_counts", self.m), ("encoder_counts", self.m),
                ("delta_measured_m", 3 * self.n), ("tip_measured_m", 3)]


@dataclasses.dataclass(frozen=True)
class TickBatch:
    """Rows drained from a :class:`TickRing`: consecutive ticks unless some were ``dropped``
    (the ring overflowed before a drain: their indices are missing, and say so).

    Attributes:
        arm: ``"soft_arm"`` or ``"extensible"`` (which channel).
        rows: (k, width) float64, oldest first.
        phases: The phase names; column :data:`PHASE` holds an index into it.
        dropped: Ticks lost before this batch (0 in a healthy loop).
    """

    arm: str
    rows: Array
    phases: tuple[str, ...]
    dropped: int = 0


class TickRing:
    """A fixed ring of tick rows: one writer (the loop thread), one reader (:meth:`drain`).

    ``capacity - 1`` ticks are kept between drains (4096: 41 s at 100 Hz; the writer may be
    writing the slot after them while a drain copies); older ones are counted as dropped. Writing is a handful of stores into a preallocated row; the count is bumped
    last, so a reader never sees a half-written row.
    """

    def __init__(self, layout: TickLayout, capacity: int = 4096) -> None:
        self.layout = layout
        self.capacity = int(capacity)
        self._rows = np.full((self.capacity, layout.width), NAN)
        self._phases: dict[str, int] = {}
        self._names: list[str] = []
        self.written = 0  # rows ever written
        self._read = 0  # rows ever drained (or dropped)

    def add(self, tick: int, t: float, reading: Any, commands: Any, control: Any,
            timing: tuple[float, ...] | None = None, missed: int = 0) -> None:
        """Loop thread: one tick (``timing``: late, period, work, read, update, write in ms)."""
        row = self._rows[self.written % self.capacity]
        armed, phase = self.layout.fill(row, reading, commands, control)
        code = self._phases.get(phase)
        if code is None:
            code = self._phases[phase] = len(self._names)
            self._names.append(phase)
        row[TICK], row[T], row[ARMED], row[PHASE] = tick, t, armed, code
        if timing is None:
            row[LATE:MISSED + 1] = NAN
        else:
            row[LATE:WRITE + 1] = timing
            row[MISSED] = missed
        self.written += 1

    def drain(self) -> TickBatch | None:
        """Reader: the rows written since the last drain (None: none)."""
        end = self.written
        start = self._read
        dropped = max(0, end - start - (self.capacity - 1))  # the writer may be at one more
        start += dropped
        if end <= start:
            self._read = end
            return None
        idx = np.arange(start, end) % self.capacity
        rows = self._rows[idx]
        self._read = end
        return TickBatch(self.layout.arm, rows, tuple(self._names), dropped)


def layout_for(robot: Any) -> TickLayout:
    """The tick layout of ``robot`` (a ``core.robots`` soft or extensible arm)."""
    if getattr(robot, "kind", None) == "delta":
        return ExtensibleTicks(robot.n_segments, robot.n_motors)
    return SoftArmTicks(robot.n_segments)


# -- channel messages and tables ---------------------------------------------------------------

TOPICS = {"soft_arm": "/control/ticks", "extensible": "/control/extensible_ticks"}
SCHEMAS: dict[str, Schema] = {"soft_arm": SOFT_ARM_TICK, "extensible": EXTENSIBLE_TICK}
ARM_OF_TOPIC = {topic: arm for arm, topic in TOPICS.items()}


def _layout_of(batch: TickBatch) -> TickLayout:
    width = batch.rows.shape[1] - COMMON
    if batch.arm == "soft_arm":  # width = 3n + (2n + 1)
        return SoftArmTicks((width - 1) // 5)
    n = (width - 3) // 9  # width = 2 * 3n + 3n + 3
    return ExtensibleTicks(n)


def _ms(v: float) -> float:
    return round(float(v), 4)


def tick_message(layout: TickLayout, row: Array, phases: tuple[str, ...],
                 stamp_ns: int) -> dict[str, Any]:
    """One row as a message of the tick channel (see the schemas)."""
    ns = int(stamp_ns)
    code = int(row[PHASE])
    msg: dict[str, Any] = {"timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
                           "tick": int(row[TICK]), "t_s": round(float(row[T]), 6),
                           "phase": phases[code] if 0 <= code < len(phases) else "unknown",
                           "armed": bool(row[ARMED])}
    if math.isfinite(row[LATE]):
        for key, col in zip(TIMING_KEYS, range(LATE, WRITE + 1)):
            msg[key] = _ms(row[col])
        msg["missed"] = int(row[MISSED])
    msg.update(layout.fields(row))
    return msg


def tick_messages(batch: TickBatch, ns_of_t: Any) -> list[tuple[str, int, dict[str, Any]]]:
    """``(topic, log ns, message)`` of every row; ``ns_of_t(t)`` maps loop time to log time."""
    layout = _layout_of(batch)
    topic = TOPICS[batch.arm]
    out = []
    for row in batch.rows:
        ns = int(ns_of_t(float(row[T])))
        out.append((topic, ns, tick_message(layout, row, batch.phases, ns)))
    return out


def tick_columns(messages: list[dict[str, Any]], arm: str) -> dict[str, list[Any]]:
    """The tick channel's messages as a table: column name (with its unit) -> values.

    Arrays are spread over one column per element (``seg1_kappa_measured_1_per_m``, ...); a
    value a message omitted is None (an empty cell)."""
    if not messages:
        return {}
    sizes = {k: len(v) for m in messages for k, v in m.items() if isinstance(v, list)}
    if arm == "soft_arm":
        n = max(sizes.get("kappa_target_1_per_m", 0), sizes.get("kappa_measured_1_per_m", 0))
        layout: Any = SoftArmTicks(n, sizes.get("command_counts"))
    else:
        n = sizes.get("delta_measured_m", 0) // 3
        layout = ExtensibleTicks(n, sizes.get("demand_counts", sizes.get("encoder_counts")))
    cols: dict[str, list[Any]] = {"log_time_ns": [], "tick": [], "t_s": [], "phase": [],
                                  "armed": []}
    for key in (*TIMING_KEYS, "missed"):
        cols[key] = []
    names = layout.columns()
    for name in names:
        cols[name] = []
    spread = layout.field_columns()
    for m in messages:
        ts = m.get("timestamp") or {}
        cols["log_time_ns"].append(int(ts.get("sec", 0)) * 1_000_000_000 + int(ts.get("nsec", 0)))
        for key in ("tick", "t_s", "phase", "armed", *TIMING_KEYS, "missed"):
            cols[key].append(m.get(key))
        i = 0
        for key, size in spread:
            vals = m.get(key)
            for j in range(size):
                cols[names[i + j]].append(None if vals is None or j >= len(vals) else vals[j])
            i += size
    return cols
