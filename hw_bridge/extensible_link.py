"""The extensible runner's hardware: one link that the operator may connect, arm, disarm, drop.

:class:`HardwareLink` is the :class:`hw_bridge.loop.Device` of
:class:`hw_bridge.extensible_runner.ExtensibleRunner`: the loop thread (the only one that touches
the hardware) calls :meth:`HardwareLink.read` / :meth:`HardwareLink.write` every tick. Each
:meth:`~HardwareLink.read` first applies the operator's queued bridge commands
(:class:`hw_bridge.controls.QueuedBridgeControls`: the GUI only enqueues), then reads the
encoders, and publishes the link's :class:`~hw_bridge.interface.LinkHealth` a few times a second
(and at once after a command or a fault).

Commands (see :attr:`ExtensibleRunner.bridge_controls`):

* ``connect(port, baud)``: stop commanding, close the link, open ``port`` with a new
  :class:`~hw_bridge.interface.SerialHardware` (the current link's settings, else the robot's
  ``[bridge]``, with ``baud``; 0 keeps the current one; over
  :class:`~hw_bridge.transport.SerialTransport`, whose writes do not
  fail on a GIL stall) and configure it: telemetry flows, nothing is armed. An empty port
  reconnects to the current one. The in-process mock has no port: only ``mock://`` (or empty)
  reconnects it, any other port is refused with the reason.
* ``disconnect()``: stop commanding, DISARM, close the port; Arm is refused until a Connect.
* ``arm()``: activate (configuring first if a fault closed the link); the arm then holds where
  the encoders are and the console's command is set to that posture. Only ever on request:
  nothing re-arms after a fault.
* ``disarm()``: stop commanding and DISARM (the device holds and stops); telemetry goes on.
"""

from __future__ import annotations

import dataclasses
import queue
from typing import Any, Callable

import numpy as np

from core.robots import ExtensibleArm
from hw_bridge.controls import BridgeCommand, QueuedBridgeControls
from hw_bridge.extensible_jobs import Array, Counts
from hw_bridge.interface import HardwareInterface, LifecycleState, ReturnType, SerialHardware

NOT_CONNECTED: Counts = np.zeros(0, dtype=np.int64)
MOCK_PORT = "mock://"
DISCONNECTED = "disconnected by the operator: Connect, then Arm, to command the arm again"


class HardwareLink:
    """:class:`hw_bridge.loop.Device` over a HardwareInterface that may come and go.

    Args:
        robot: The extensible arm (its ``[bridge]`` settings build new links).
        factory: The runner's hardware factory (:meth:`ExtensibleRunner.connect` uses it);
            an operator's Connect replaces it by the newly opened link.
        health_every: Publish the link health every this many ticks (10: 10 Hz at 100 Hz).
    """

    def __init__(self, robot: ExtensibleArm, factory: Callable[[], HardwareInterface],
                 health_every: int = 10) -> None:
        self.robot = robot
        self.factory = factory
        self.health_every = max(1, health_every)
        self.hw: HardwareInterface | None = None
        self.fault: str | None = None
        self.controls = QueuedBridgeControls()
        self.streamer: Any = None  # the runner's Streamer (set by the runner)
        self.disconnected = False
        self._ticks = 0

    # -- loop Device ---------------------------------------------------------------------------
    def read(self, t: float) -> Counts | None:
        """Apply queued operator commands, then encoder counts: empty when not connected, None
        on a hardware ERROR (the loop then stops the streamer if it was armed)."""
        if self._apply_commands():
            self.publish()
        self._ticks += 1
        hw = self.hw
        if hw is None or hw.state is LifecycleState.UNCONFIGURED:
            if self._ticks % self.health_every == 0:
                self.publish()
            return NOT_CONNECTED
        if hw.read() is not ReturnType.OK:
            self.fault = hw.fault or "hardware read failed"
            if self.streamer is not None and not self.streamer.armed:
                self.streamer.disarmed(f"fault: {self.fault}", self.fault)
            self.publish()
            return None
        if self._ticks % self.health_every == 0:
            self.publish()
        pos = hw.positions()
        return NOT_CONNECTED if pos is None else pos

    def write(self, commands: Counts, t: float) -> bool:
        hw = self.hw
        if hw is None or hw.write(commands) is not ReturnType.OK:
            self.fault = (hw.fault if hw else None) or "hardware write failed"
            self.publish()
            return False
        return True

    def cylinders(self) -> Array | None:
        pos = None if self.hw is None else self.hw.positions()
        return None if pos is None else np.asarray(pos, dtype=float)

    def publish(self) -> None:
        """Make the link's health visible to ``controls.health()`` (loop thread).

        ``armed`` is the device's last reported status only while the link is ACTIVE: after a
        fault or a Disconnect the last STATE received may still say ARMED, but nothing is.
        """
        hw = self.hw
        if hw is not None:
            health = hw.health()
            if health.armed and hw.state is not LifecycleState.ACTIVE:
                health = dataclasses.replace(health, armed=False)
            self.controls.publish(health)

    # -- lifecycle (loop thread) ---------------------------------------------------------------
    def open_and_arm(self, follow: bool) -> str | None:
        """Runner connect: close the link, take a new one from the factory, configure and
        activate it; the streamer then holds (or follows). Returns the fault, or None."""
        stack = self.streamer
        stack.disarmed("reconnecting")  # a running job ends here
        if self.hw is not None:
            self.hw.cleanup()
        hw = self.hw = self.factory()
        self.disconnected, self.fault = False, None
        stack.fault, stack.message = None, "connecting"
        for step in (hw.configure, hw.activate):
            if step() is not ReturnType.OK:
                stack.fault = hw.fault or f"{step.__name__} failed"
                stack.message = f"fault: {stack.fault}"
                self.publish()
                return stack.fault
        pos = hw.positions()
        assert pos is not None
        stack.connected(pos, follow)
        self.publish()
        return None

    def close(self) -> None:
        """Disarm and close the link (loop thread, or after the loop stopped)."""
        if self.hw is not None:
            self.hw.cleanup()

    # -- operator commands (loop thread) -------------------------------------------------------
    def _apply_commands(self) -> bool:
        applied = False
        while True:
            try:
                cmd = self.controls.commands.get_nowait()
            except queue.Empty:
                return applied
            applied = True
            getattr(self, f"_{cmd.action}")(cmd)

    def _refuse(self, reason: str) -> None:
        if self.hw is not None:
            self.hw.fault = reason
        self.fault = reason

    def _connect(self, cmd: BridgeCommand) -> None:
        old = self.hw
        old_port = getattr(old, "port", "") if old is not None else ""
        port = cmd.port.strip() or old_port
        if not port:
            self._refuse("connect refused: no port given")
            return
        if old_port == MOCK_PORT and port != MOCK_PORT:
            self._refuse(f"connect refused: the mock device is {MOCK_PORT} (in-process); start "
                         f"serve.py with --port-path {port} for a real controller")
            return
        self.streamer.disarmed(f"connecting to {port}")
        if old is not None:
            old.cleanup()
        if old is not None and old_port == MOCK_PORT:
            hw: HardwareInterface = old
        else:
            from hw_bridge.config import BridgeConfig
            config = getattr(old, "config", None) or BridgeConfig.from_robot(self.robot)
            if cmd.baud:
                config = dataclasses.replace(config, baud=cmd.baud)
            hw = SerialHardware(config, port, config.baud)
        self.hw, self.factory = hw, (lambda: hw)
        self.disconnected, self.fault = False, None
        if hw.configure() is ReturnType.OK:
            self.streamer.disarmed(f"connected to {port}; disarmed (Arm to command the arm)")
        else:
            self.fault = hw.fault
            self.streamer.disarmed(f"connect failed: {hw.fault}", hw.fault)

    def _disconnect(self, cmd: BridgeCommand) -> None:
        self.streamer.disarmed(DISCONNECTED)
        if self.hw is not None:
            self.hw.cleanup()
        self.disconnected = True

    def _arm(self, cmd: BridgeCommand) -> None:
        hw = self.hw
        if hw is None or self.disconnected:
            self._refuse(f"arm refused: {DISCONNECTED if self.disconnected else 'not connected'}")
            return
        if hw.state is LifecycleState.ACTIVE:
            return
        ok = hw.state is LifecycleState.INACTIVE or hw.configure() is ReturnType.OK
        ok = ok and hw.activate() is ReturnType.OK
        pos = hw.positions() if ok else None
        if pos is None:
            self.fault = hw.fault or "arm failed"
            self.streamer.disarmed(f"arm refused: {self.fault}", self.fault)
            return
        self.fault = None
        self.streamer.connected(pos, follow=False)
        self.streamer.settle_link()  # the console's command becomes the held posture

    def _disarm(self, cmd: BridgeCommand) -> None:
        hw = self.hw
        if hw is None or hw.state is not LifecycleState.ACTIVE:
            return
        self.streamer.disarmed("disarmed by the operator; Arm to command the arm again")
        if hw.deactivate() is ReturnType.ERROR:
            hw.cleanup()
