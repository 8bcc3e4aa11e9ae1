"""The soft arm's control stack with a row of objects on it, for a loop that runs on its own.

:class:`core.control.row.ObjectRow` is bookkeeping that a driver must call after every tick
(:func:`core.control.row.run_row` does so on a simulated loop). The control process's loop
(:class:`hw_bridge.loop.LoopRunner`) only calls ``stack.update``; :class:`RowControlStack` is a
:class:`~core.control.stack.ControlStack` whose :meth:`~RowControlStack.update` also looks at the
row after the period, hands each object whose turn begins to a ``place`` callback (which puts it
into the simulated world), and whose :meth:`~RowControlStack.stop` goes through
:meth:`ObjectRow.stop <core.control.row.ObjectRow.stop>` while a row runs (so the operator's STOP
ends the row with the rest skipped, rather than looking like a failure of the current object).
:meth:`~RowControlStack.row_report` is a small frozen snapshot for the console.

Pure like the stack: no threads, no I/O, no clock; called from the loop thread only.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

from core.control.params import BinParams
from core.control.row import ObjectOutcome, ObjectRow, RowObject, RowState
from core.control.stack import ControlStack, Reading, Telemetry

ROW_RUNNING = "a row of objects is running (object {k} of {n}): press STOP first"


@dataclasses.dataclass(frozen=True)
class RowReport:
    """What the console shows of a row: its id, state, the current object, every outcome."""

    row_id: int
    state: RowState
    current: int | None  # 0-based index of the object being taken, while running
    n: int
    outcomes: tuple[ObjectOutcome, ...]
    reason: str | None  # why the row stopped early (None while running or when done)

    @property
    def running(self) -> bool:
        return self.state == "running"

    @property
    def released(self) -> int:
        return sum(o.released for o in self.outcomes)


class RowControlStack(ControlStack):
    """A :class:`ControlStack` that can take a queue of objects to a bin, one after another.

    Args: as :class:`ControlStack`.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.row: ObjectRow | None = None
        self.row_id = 0
        self._place: Callable[[RowObject], None] | None = None
        self._report: RowReport | None = None
        self._as_row_sees_it = _PlainStack(self)

    # -- operator commands (loop thread only) -------------------------------------------------
    @property
    def row_running(self) -> bool:
        return self.row is not None and self.row.state == "running"

    def require_no_row(self) -> None:
        """Refuse another task while a row runs (RuntimeError with what to do)."""
        row = self.row
        if row is not None and row.state == "running":
            raise RuntimeError(ROW_RUNNING.format(k=(row.current or 0) + 1, n=len(row.objects)))

    def start_row(self, row_id: int, objects: Sequence[RowObject], bin_params: BinParams | None,
                  t: float, place: Callable[[RowObject], None] | None = None) -> None:
        """Start taking ``objects`` to ``bin_params`` (None: the robot's bin) in order.

        ``place(obj)`` is called for every object whose turn begins after the first (the caller
        has put the first one into the world before); it must not block the loop.
        """
        self.require_no_row()
        row = ObjectRow(objects, bin_params)  # validates: at least one object
        row.start(self._plain(), t)  # refuses while disarmed, before anything is kept
        self.row, self.row_id, self._place = row, int(row_id), place
        self._snapshot()

    def stop(self, t: float, reason: str = "operator STOP") -> None:
        """The operator's STOP; while a row runs it ends the row (the rest is skipped)."""
        row = self.row
        if row is not None and row.state == "running":
            row.stop(self._plain(), t, reason)
            self._snapshot()
        else:
            super().stop(t, reason)

    # -- the period ----------------------------------------------------------------------------
    def update(self, reading: Reading, t: float, periods: int = 1) -> tuple[Any, Telemetry]:
        commands, telemetry = super().update(reading, t, periods)
        row = self.row
        if row is not None and row.state == "running":
            nxt = row.after_tick(self._plain(), t)
            if nxt is not None and self._place is not None:
                self._place(nxt)
            if nxt is not None or row.state != "running":
                self._snapshot()
        return commands, telemetry

    def row_report(self) -> RowReport | None:
        """The newest row's snapshot (None before the first row); safe to read from any thread
        (a reference to a frozen value, replaced by the loop thread)."""
        return self._report

    # -- helpers -------------------------------------------------------------------------------
    def _plain(self) -> _PlainStack:
        """This stack as the row sees it: ``stop`` is the stack's own (no recursion)."""
        return self._as_row_sees_it

    def _snapshot(self) -> None:
        row = self.row
        if row is None:
            return
        self._report = RowReport(self.row_id, row.state, row.current, len(row.objects),
                                 tuple(row.outcomes), row.reason)


class _PlainStack:
    """What :class:`ObjectRow` calls on a stack (armed, machine, start, stop), with ``stop``
    the plain :meth:`ControlStack.stop`."""

    def __init__(self, stack: RowControlStack) -> None:
        self._stack = stack

    @property
    def armed(self) -> bool:
        return self._stack.armed

    @property
    def machine(self) -> Any:
        return self._stack.machine

    def start(self, t: float) -> None:
        self._stack.start(t)

    def stop(self, t: float, reason: str = "operator STOP") -> None:
        ControlStack.stop(self._stack, t, reason)
