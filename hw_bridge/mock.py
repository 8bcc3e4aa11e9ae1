"""In-process hardware for ``--hardware mock``: the real host stack against an in-memory device.

:class:`MockHardware` is a :class:`~hw_bridge.interface.SerialHardware` whose transport is a
:class:`DeviceTransport`: bytes written go straight into a :class:`~hw_bridge.device.DeviceCore`
that runs on its own 100 Hz timer thread (:class:`DeviceRunner`), like a board that keeps
running while the host disconnects. So the mock exercises the same framing, lifecycle and
watchdog code as the serial path, minus the wire and the plant lag.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

from core.robots import Robot
from hw_bridge.config import BridgeConfig, EmulatorConfig
from hw_bridge.device import DeviceCore
from hw_bridge.interface import SerialHardware
from hw_bridge.plants import MotorBank
from hw_bridge.transport import TransportError


class DeviceRunner:
    """Ticks a DeviceCore on a daemon thread and routes its output to the attached transport."""

    def __init__(self, device: DeviceCore, clock: Callable[[], float] = time.perf_counter):
        self.device = device
        self.clock = clock
        self.lock = threading.Lock()
        self.attached: "DeviceTransport | None" = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="mock-device")
        self._thread.start()

    def _run(self) -> None:
        period = self.device.period_s
        nxt = self.clock() + period
        while not self._stop.is_set():
            time.sleep(max(0.0, nxt - self.clock()))
            with self.lock:
                now = self.clock()
                self.device.tick(now)
                self.route_output()
            nxt += period
            if nxt <= now:  # overrun: skip, do not catch up
                nxt = now + period

    def route_output(self) -> None:
        """Move device output to the attached transport (dropped when nobody listens). Locked."""
        frames = self.device.take_output()
        t = self.attached
        if t is not None and t.connected and not t.closed:
            for f in frames:
                t.rx += f

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)


class DeviceTransport:
    """A Transport whose far end is a DeviceRunner's device.

    ``connected = False`` simulates a cut cable (writes vanish, nothing arrives).
    """

    def __init__(self, runner: DeviceRunner, read_timeout: float = 0.005):
        self.runner = runner
        self.read_timeout = read_timeout
        self.connected = True
        self.closed = False
        self.rx = bytearray()
        with runner.lock:
            runner.attached = self

    def read_chunk(self) -> bytes:
        deadline = time.perf_counter() + self.read_timeout
        while True:
            with self.runner.lock:
                if self.closed:
                    raise TransportError("mock transport is closed")
                if self.rx or time.perf_counter() >= deadline:
                    out, self.rx = bytes(self.rx), bytearray()
                    return out
            time.sleep(0.0005)

    def write(self, data: bytes) -> None:
        with self.runner.lock:
            if self.closed:
                raise TransportError("mock transport is closed")
            if self.connected:
                self.runner.device.receive(data, self.runner.clock())
                self.runner.route_output()

    def reset_input(self) -> None:
        with self.runner.lock:
            self.rx.clear()

    def close(self) -> None:
        with self.runner.lock:
            self.closed = True
            if self.runner.attached is self:
                self.runner.attached = None


class MockHardware(SerialHardware):
    """SerialHardware wired to an in-process device emulating ``robot``.

    The device persists across reconnects (like a real board), so a tripped watchdog stays
    latched until the next ARM. Call :meth:`shutdown` to stop the device thread.

    Args:
        robot: The robot whose motors the device emulates.
        n_motors: Overrides the robot's motor count.
        clock: Monotonic seconds, read by the host side and the device alike (tests pass a
            clock they can stop, to check the link's timeouts without the wall clock).
    """

    def __init__(self, robot: Robot, n_motors: int | None = None,
                 clock: Callable[[], float] = time.perf_counter):
        config = BridgeConfig.from_robot(robot, n_motors=n_motors)
        emu = EmulatorConfig.from_robot(robot)
        self.device = DeviceCore(MotorBank(config.n_motors, emu.motor_speed_counts),
                                 config.watchdog_s, config.period_s, now=clock())
        self.runner = DeviceRunner(self.device, clock)
        self.transport: DeviceTransport | None = None
        super().__init__(config, "mock://", transport_factory=self._open, clock=clock)

    def _open(self, port: str, baud: int) -> DeviceTransport:
        self.transport = DeviceTransport(self.runner)
        return self.transport

    def shutdown(self) -> None:
        """Disconnect and stop the device thread."""
        self.cleanup()
        self.runner.stop()
