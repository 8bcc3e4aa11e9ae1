"""The tip target's solving thread: only the newest target is solved, live ones throttled.

The Tip target panel (:class:`console.panels.extensible.target.TargetPanel`) hands every target
to a :class:`TargetIKWorker`; its one daemon thread solves the newest (a final solve is never
downgraded by a later live one), at most ``LIVE_HZ`` live solves a second, and between requests
checks every ``ARRIVAL_POLL_S`` whether the arm arrived (``TargetPanel.check_arrival``) and
whether the console core stopped motion since (then pending targets are dropped and the panel
says so, ``TargetPanel.on_stopped``; a solve under way cannot move the arm either: its move
carries the core's stop generation, :attr:`TargetIKWorker.stops`). The worker knows the panel
only as a :class:`TargetSolver`, so it does not import the panel back.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
LIVE_HZ = 30.0
ARRIVAL_POLL_S = 0.05


class TargetSolver(Protocol):
    """What the worker's thread calls (the Tip target panel implements it)."""

    def solve(self, target: Array, final: bool, client_id: int, generation: int) -> None:
        """IK to ``target`` and move there; ``generation`` tells stale requests apart."""

    def check_arrival(self) -> None:
        """Between requests: whether the arm reached the set-point."""

    def report_error(self, message: str) -> None:
        """Show ``message`` (a solve raised)."""


class TargetIKWorker:
    """Latest-value mailbox + one daemon thread: solves only the newest target."""

    def __init__(self, panel: TargetSolver) -> None:
        self.panel = panel
        self._cond = threading.Condition()
        self._request: tuple[Array, bool, int] | None = None
        self.generation = 0  # bumped by cancel(): results of older requests are dropped
        self.stops = panel.app.core.stop_generation  # the core's stops this worker has seen
        threading.Thread(target=self._run, name="target-ik", daemon=True).start()

    def submit(self, target: Array, final: bool, client_id: int) -> None:
        with self._cond:
            # A pending final solve is not downgraded by a live one.
            final = final or (self._request is not None and self._request[1])
            self._request = (np.array(target, dtype=float), final, client_id)
            self._cond.notify()

    def cancel(self) -> None:
        with self._cond:
            self._request = None
            self.generation += 1

    def _run(self) -> None:
        last = 0.0
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._request is not None, ARRIVAL_POLL_S)
            stops = self.panel.app.core.stop_generation
            if stops != self.stops:  # STOP, a lost lease...: nothing asked before it moves
                self.stops = stops
                self.cancel()
                self.panel.on_stopped()
            with self._cond:
                request, self._request = self._request, None
                generation = self.generation
            self.panel.check_arrival()
            if request is None:
                continue
            target, final, client_id = request
            if not final:  # throttle live solves; a newer target replaces this one meanwhile
                wait = last + 1.0 / LIVE_HZ - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
                    with self._cond:
                        if self._request is not None:
                            continue
            last = time.perf_counter()
            try:
                self.panel.solve(target, final, client_id, generation, stops)
            except Exception as exc:  # noqa: BLE001 - report, keep the worker alive
                self.panel.report_error(str(exc))

