"""The grasp session's waypoint inspection: step through the newest plan's waypoints, play them,
and show or clear the trail of those passed.

A mixin of :class:`console.core.grasp_session.GraspSession` (same lock and worker rules: every method
takes the session's lock, changes the inspection state and marks ``inspect`` dirty; the session's
worker steps playback on the session's clock and tells the views).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np


class WaypointInspection:
    """Waypoint inspection and playback of a grasp session (see the module docstring)."""

    _cond: threading.Condition
    _index: int
    _trail_from: int
    _trail: bool
    _playing: bool
    _speed: float
    _next_tick: float
    _clock: Callable[[], float]
    _outcome: object
    _n: Callable[[], int]
    _changed: Callable[..., None]

    def inspect(self, index: int | None = None, step: int = 0) -> None:
        """Inspect waypoint ``index`` (0-based) or move by ``step``; stops playback."""
        with self._cond:
            n = self._n()
            i = self._index + step if index is None else int(index)
            self._index = min(max(i, 0), max(n - 1, 0))
            self._trail_from = min(self._trail_from, self._index)
            self._playing = False
            self._changed("inspect")

    def play(self, playing: bool, speed: float | None = None) -> None:
        with self._cond:
            if speed is not None:
                self._speed = float(min(max(speed, 0.1), 50.0))
            if playing and self._index >= self._n() - 1:
                self._index = self._trail_from = 0
            self._playing = bool(playing) and self._n() > 1
            self._next_tick = self._clock() + 1.0 / self._speed
            self._changed("inspect")

    def set_trail(self, trail: bool) -> None:
        with self._cond:
            self._trail = bool(trail)
            self._changed("inspect")

    def clear_trail(self) -> None:
        """Hide the trail of the waypoints passed so far (it grows again from here)."""
        with self._cond:
            self._trail_from = self._index
            self._changed("inspect")

    def inspected_kappa(self) -> np.ndarray | None:
        with self._cond:
            if self._outcome is None or self._outcome.plan is None:
                return None
            return self._outcome.plan.kappas[self._index].copy()
