"""What the 100 Hz loop drives: the simulated arm stepped in the loop, or hardware plus mocap."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from core.control.sim import MocapReading

Array = npt.NDArray[np.float64]


class SimDevice:
    """The simulated arm: ``read(t)`` steps the physics to ``t`` (sub-steps <= ``max_step``)
    under the last written demands, then measures; works on either clock."""

    def __init__(self, sim: Any, max_step: float = 0.01):
        self.sim = sim
        self.max_step = max_step
        self.demands = sim.demands.copy()
        self._t: float | None = None

    def read(self, t: float) -> Any:
        if self._t is None:
            self._t = t
        while t - self._t > 1e-12:
            h = min(self.max_step, t - self._t)
            self.sim.step(self.demands, h)
            self._t += h
        return self.sim.measure()

    def write(self, commands: Array, t: float) -> bool:
        self.demands = np.asarray(commands, dtype=float).copy()
        return True

    def cylinders(self) -> Array | None:
        return self.sim.cylinders.copy()


class HardwareDevice:
    """``hw_bridge`` hardware (MockHardware / SerialHardware) plus a motion-capture source.

    The mocap frame's points are [x, y, theta] of the base and the N segment ends; a further
    point, if present, is the object centre (its radius is ``object_radius``). A stale or
    invalid frame gives NaN markers, which the stack treats as tracking lost.
    """

    def __init__(self, hardware: Any, mocap: Any, n_segments: int, object_radius: float | None = None):
        self.hw, self.mocap, self.n = hardware, mocap, n_segments
        self.object_radius = object_radius
        self.fault: str | None = None

    def read(self, t: float) -> MocapReading | None:
        from hw_bridge.interface import ReturnType
        from hw_bridge.mocap import frame_health
        if self.hw.read() is not ReturnType.OK:
            self.fault = self.hw.fault
            return None
        frame = self.mocap.latest()
        if frame_health(frame) != "ok" or frame.points.shape[0] < self.n + 1:
            return MocapReading(t, np.full((self.n, 2), np.nan), None, self.object_radius)
        obj = frame.points[self.n + 1, :2].copy() if frame.points.shape[0] > self.n + 1 else None
        return MocapReading(t, frame.points[1:self.n + 1, :2].copy(), obj, self.object_radius)

    def write(self, commands: Array, t: float) -> bool:
        from hw_bridge.interface import ReturnType
        ok = self.hw.write(commands) is ReturnType.OK
        if not ok:
            self.fault = self.hw.fault
        return ok

    def cylinders(self) -> Array | None:
        pos = self.hw.positions()
        return None if pos is None else np.asarray(pos, dtype=float)
