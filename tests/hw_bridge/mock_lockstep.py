"""MockHardware on a clock the test can stop: the link's timeouts checked without the wall clock.

The handshake (:meth:`SerialHardware.configure`) needs the device's timer to send STATE, so it
runs in real time with the device thread running (it only waits, with 500 ms of patience).
Then :meth:`Lockstep.freeze` stops the device thread and the clock: from there the test moves
time by whole periods (:meth:`Lockstep.step` ticks the device at the new time and waits, in
real time with a generous deadline, until the host's receive thread has taken every STATE the
device sent). Ages, timeouts and the device's watchdog then count simulated time only, so a
2-core box that stalls a thread for 50 ms changes nothing that is asserted.
"""

from __future__ import annotations

import time

import numpy as np

from core.robots import Robot
from hw_bridge.interface import LifecycleState, ReturnType
from hw_bridge.mock import DeviceRunner, MockHardware

SETTLE_S = 20.0  # real seconds a receive thread may take to pass on a STATE (expected: < 1 ms)


class StoppableClock:
    """``time.perf_counter`` until :meth:`freeze`; then a time moved by :meth:`advance` only;
    :meth:`resume` goes on in real time from where the frozen time stood (never backwards)."""

    def __init__(self) -> None:
        self._offset = 0.0
        self._frozen: float | None = None

    def __call__(self) -> float:
        frozen = self._frozen
        return frozen if frozen is not None else time.perf_counter() + self._offset

    @property
    def frozen(self) -> bool:
        """Whether the time stands still (moved by :meth:`advance` only)."""
        return self._frozen is not None

    def freeze(self) -> None:
        """Stop the time where it is now."""
        self._frozen = self()

    def advance(self, dt: float) -> None:
        """Move the frozen time on by ``dt`` seconds."""
        assert self._frozen is not None, "advance() needs a frozen clock"
        self._frozen += dt

    def resume(self) -> None:
        """Run in real time again, from the frozen time on."""
        assert self._frozen is not None
        self._offset = self._frozen - time.perf_counter()
        self._frozen = None


class Lockstep:
    """A :class:`MockHardware` whose device and link the test steps on a stoppable clock.

    Args:
        robot: The robot the mock device emulates.
    """

    def __init__(self, robot: Robot) -> None:
        self.clock = StoppableClock()
        self.hw = MockHardware(robot, clock=self.clock)

    @property
    def period(self) -> float:
        """The link's period (10 ms)."""
        return self.hw.config.period_s

    def freeze(self) -> None:
        """Stop the device's timer thread, then the clock."""
        runner = self.hw.runner
        runner.stop()
        deadline = time.monotonic() + SETTLE_S
        while runner._thread.is_alive():  # noqa: SLF001 -- stop() joins for 1 s only
            assert time.monotonic() < deadline, "the mock device's thread did not end"
            time.sleep(0.01)
        self.clock.freeze()

    def thaw(self) -> None:
        """Run the clock in real time again and the device on a new timer thread."""
        self.clock.resume()
        self.hw.runner = DeviceRunner(self.hw.device, self.clock)

    def connect_and_arm(self) -> None:
        """Configure in real time, then freeze and activate (ARMED comes back on the echo)."""
        if self.clock.frozen:
            self.thaw()
        assert self.hw.configure() is ReturnType.OK, self.hw.fault
        self.freeze()
        assert self.hw.activate() is ReturnType.OK, self.hw.fault
        self.settle()

    def step(self) -> None:
        """One period later: the device ticks (watchdog, motors, STATE) and the host receives."""
        assert self.clock.frozen
        self.clock.advance(self.period)
        runner = self.hw.runner
        with runner.lock:
            self.hw.device.tick(self.clock())
            runner.route_output()
        self.settle()

    def settle(self) -> None:
        """Wait (real time) until the host's link holds the device's latest STATE, if connected."""
        t = self.hw.transport
        link = self.hw.link
        if t is None or link is None or not t.connected or t.closed:
            return
        deadline = time.monotonic() + SETTLE_S
        while link.last_state is None or link.last_state.seq != self.hw.device._seq:  # noqa: SLF001
            if t.closed or self.hw.state is LifecycleState.UNCONFIGURED:
                return
            assert time.monotonic() < deadline, "the receive thread did not pass the STATE on"
            time.sleep(0.0005)

    def run(self, target: np.ndarray, cycles: int) -> list[ReturnType]:
        """``cycles`` periods of the 100 Hz read -> write loop; the read() results."""
        results = []
        for _ in range(cycles):
            self.step()
            r = self.hw.read()
            results.append(r)
            if r is ReturnType.OK and self.hw.state is LifecycleState.ACTIVE:
                self.hw.write(target)
                # The DEMAND's echo STATE is sent at once: let the host take it now, or a
                # receive thread held up by a loaded box stamps it a period or more later.
                self.settle()
        return results

    def shutdown(self) -> None:
        """Disconnect and end the device thread (if running)."""
        self.hw.shutdown()
