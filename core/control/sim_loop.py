"""The control cycle on a simulated clock, thread-free, so headless runs need nothing from hw_bridge.

:class:`SimLoop` steps the simulated soft arm and a control stack in the order and timing of
``hw_bridge.loop.LoopRunner`` on its ``SimClock`` (``run_sim``): tick ``k`` is at
``t = k * period``; queued operator commands run first (:meth:`SimLoop.submit`), then read
(the physics is stepped to ``t`` in sub-steps of at most ``max_step`` under the last written
demands, then measured), update, write. An update that raises is handed to the stack's
``device_fault`` as the loop runner does. Nothing here sleeps, spawns or locks: it runs as fast
as the CPU allows and is deterministic for a seeded simulator.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Callable, Protocol

import numpy as np
import numpy.typing as npt

from core.control.stack import Telemetry

Array = npt.NDArray[np.float64]
log = logging.getLogger(__name__)


class SimulatedArm(Protocol):
    """What the cycle needs of the simulator (:class:`core.control.sim.SoftArmSim`)."""

    demands: Array
    cylinders: Array

    def step(self, demands: npt.ArrayLike, dt: float) -> None: ...

    def measure(self) -> Any: ...


class SteppedStack(Protocol):
    """What the cycle updates (:class:`core.control.stack.ControlStack`)."""

    armed: bool

    def update(self, reading: Any, t: float, periods: int = 1) -> tuple[Array | None, Any]: ...

    def device_fault(self, t: float, reason: str) -> Any | None: ...


@dataclasses.dataclass(frozen=True)
class SimLoopStats:
    """Tick count and per-tick work (read + update + write and the queued commands), ms."""

    ticks: int
    update_failures: int
    work_ms_p50: float
    work_ms_p99: float


class SimLoop:
    """read -> update -> write every ``period_s`` of simulated time.

    Args:
        sim: The simulated arm (stepped and measured here; the only one that touches it).
        stack: The control stack.
        period_s: Control period (s).
        max_step: Longest physics sub-step (s).
        timer_ns: Clock for the work timings only (real CPU time by default).
    """

    def __init__(self, sim: SimulatedArm, stack: SteppedStack, period_s: float = 0.01,
                 max_step: float = 0.01, timer_ns: Callable[[], int] = time.perf_counter_ns):
        self.sim, self.stack = sim, stack
        self.period_ns = round(period_s * 1e9)
        self.max_step = max_step
        self.timer_ns = timer_ns
        self.demands = np.array(sim.demands, dtype=float)
        self.ticks = 0
        self.update_failures = 0
        self.fault: str | None = None
        self.control: Telemetry | None = None  # the last tick's telemetry
        self._sim_t: float | None = None
        self._pending: list[Callable[[Any, float], Any]] = []
        self._work_ns: list[int] = []

    @property
    def t(self) -> float:
        """Simulated time of the next tick (s)."""
        return self.ticks * self.period_ns / 1e9

    # -- operator commands: run at the start of the next tick, like the loop runner's queue ----
    def submit(self, fn: Callable[[Any, float], Any]) -> None:
        """Run ``fn(stack, t)`` at the start of the next tick (errors propagate from that tick)."""
        self._pending.append(fn)

    def arm(self) -> None:
        self.submit(lambda s, t: s.arm(self.sim.cylinders.copy()))

    def start_task(self) -> None:
        self.submit(lambda s, t: s.start(t))

    def goto(self, kappa: npt.ArrayLike) -> None:
        self.submit(lambda s, t: s.goto(kappa, t))

    # -- the cycle ---------------------------------------------------------------------------
    def _read(self, t: float) -> Any:
        if self._sim_t is None:
            self._sim_t = t
        while t - self._sim_t > 1e-12:
            h = min(self.max_step, t - self._sim_t)
            self.sim.step(self.demands, h)
            self._sim_t += h
        return self.sim.measure()

    def tick(self) -> Telemetry | None:
        """One read -> update -> write at ``t = ticks * period``; returns its telemetry."""
        w0 = self.timer_ns()
        t = self.ticks * self.period_ns / 1e9
        pending, self._pending = self._pending, []
        for fn in pending:
            fn(self.stack, t)
        reading = self._read(t)
        commands = None
        try:
            commands, control = self.stack.update(reading, t, 1)
        except Exception as exc:  # noqa: BLE001 - a failing part must not end the run
            log.exception("control update failed at t = %.2f s", t)
            self.update_failures += 1
            self.fault = f"control update failed: {type(exc).__name__}: {exc}"
            control = self.stack.device_fault(t, self.fault) or self.control
        if commands is not None:
            self.demands = np.asarray(commands, dtype=float).copy()
        self.control = control
        self._work_ns.append(self.timer_ns() - w0)
        self.ticks += 1
        return control

    def run(self, seconds: float, until: Callable[[Telemetry | None], bool] | None = None) -> int:
        """Tick for ``seconds`` of simulated time, or until ``until(telemetry)``; returns ticks."""
        n = round(seconds * 1e9 / self.period_ns)
        for i in range(n):
            control = self.tick()
            if until is not None and until(control):
                return i + 1
        return n

    def stats(self) -> SimLoopStats:
        """Work-time percentiles over every tick so far."""
        if not self._work_ns:
            return SimLoopStats(0, self.update_failures, 0.0, 0.0)
        ms = np.asarray(self._work_ns, dtype=float) / 1e6
        return SimLoopStats(self.ticks, self.update_failures, float(np.percentile(ms, 50)),
                            float(np.percentile(ms, 99)))
