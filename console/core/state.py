"""Thread-safe application state, so GUI callbacks only enqueue and one thread renders.

Two latest-value mailboxes (no queues: only the newest value matters):

* ``command`` -- the configuration the operator (or a planner) asks for. Written by
  :meth:`StateStore.request` / :meth:`StateStore.edit` from any thread (viser runs plain callbacks
  in a thread pool); every request is validated (bad input raises ``ValueError`` and changes
  nothing) and clamped to the robot's limits by the :class:`~console.core.model.ArmModel`.
* ``display`` -- the configuration drawn in the 3D view and shown in readouts. Without hardware
  (``mirror_commands=True``) it follows ``command`` at once (kinematic simulation). With a
  hardware bridge the bridge's control thread reads ``command`` (``wait_command``) and reports
  what the robot measured with :meth:`StateStore.report`, which is then what gets drawn.

Readers block on ``wait_display`` / ``wait_command`` with a sequence number and get only the
newest state, so a slow reader skips intermediate states instead of falling behind.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Callable

import numpy as np
import numpy.typing as npt

from console.core.model import ArmModel

Array = npt.NDArray[np.float64]
EditFn = Callable[[Array], "tuple[Array, tuple[str, ...] | str | None] | Array"]


@dataclasses.dataclass(frozen=True)
class ArmState:
    """One immutable configuration snapshot.

    Attributes:
        q: Configuration (soft arm: curvatures (N,); extensible: deltas (n, 3)); read-only.
        seq: Increasing sequence number across all states of a store.
        source: Who set it ("init", "jog", "straighten", "planner", "hardware", ...).
        notes: Human-readable clamp messages produced while applying the request.
        stamp: ``time.perf_counter()`` when it was set.
    """

    q: Array
    seq: int
    source: str
    notes: tuple[str, ...] = ()
    stamp: float = 0.0


def _frozen(q: Array) -> Array:
    q = np.array(q, dtype=float)
    q.flags.writeable = False
    return q


class StateStore:
    """Latest commanded and displayed :class:`ArmState`, safe to use from any thread."""

    def __init__(self, model: ArmModel, initial: npt.ArrayLike | None = None, *,
                 mirror_commands: bool = True) -> None:
        self.model = model
        self.mirror_commands = mirror_commands
        q0 = model.initial() if initial is None else model.validate(initial)
        q0, notes = model.clamp(q0)
        self._cond = threading.Condition()
        self._seq = 0
        self._command = ArmState(_frozen(q0), 0, "init", notes, time.perf_counter())
        self._display = self._command

    @property
    def command(self) -> ArmState:
        """Latest commanded state."""
        with self._cond:
            return self._command

    @property
    def display(self) -> ArmState:
        """Latest state to draw."""
        with self._cond:
            return self._display

    def request(self, q: npt.ArrayLike, source: str) -> ArmState:
        """Command configuration ``q`` (clamped to the limits); returns the commanded state.

        Raises:
            ValueError: ``q`` has the wrong shape or is not finite; nothing changes.
        """
        q = self.model.validate(q)
        return self.edit(lambda _: self.model.clamp(q), source)

    def edit(self, fn: EditFn, source: str) -> ArmState:
        """Atomically replace the command by ``fn(current q)``.

        ``fn`` runs under the store's lock, so concurrent edits (e.g. two sliders moved at once)
        never lose each other's changes; keep it cheap. It returns the new q, or ``(q, notes)``
        with notes a string, a tuple of strings or None. The result is validated and clamped.

        Raises:
            ValueError: the result is not a valid configuration; nothing changes.
        """
        with self._cond:
            current = np.array(self._command.q)
            result = fn(current)
            notes: tuple[str, ...] = ()
            if isinstance(result, tuple):
                result, extra = result
                notes = (extra,) if isinstance(extra, str) else tuple(extra or ())
            q, clamp_notes = self.model.clamp(self.model.validate(result))
            self._seq += 1
            state = ArmState(_frozen(q), self._seq, source, notes + clamp_notes,
                             time.perf_counter())
            self._command = state
            if self.mirror_commands:
                self._display = state
            self._cond.notify_all()
            return state

    def report(self, q: npt.ArrayLike, source: str = "hardware") -> ArmState:
        """Set the displayed configuration from measurements (hardware bridges call this).

        Measured states are drawn as measured, never clamped; they must still be finite and
        of the right shape (ValueError otherwise).
        """
        q = self.model.validate(q)
        with self._cond:
            self._seq += 1
            self._display = ArmState(_frozen(q), self._seq, source, (), time.perf_counter())
            self._cond.notify_all()
            return self._display

    def wait_display(self, after_seq: int, timeout: float | None = None) -> ArmState | None:
        """The display state once its seq exceeds ``after_seq``; None on timeout."""
        with self._cond:
            if self._cond.wait_for(lambda: self._display.seq > after_seq, timeout):
                return self._display
            return None

    def wait_command(self, after_seq: int, timeout: float | None = None) -> ArmState | None:
        """The command state once its seq exceeds ``after_seq``; None on timeout."""
        with self._cond:
            if self._cond.wait_for(lambda: self._command.seq > after_seq, timeout):
                return self._command
            return None
