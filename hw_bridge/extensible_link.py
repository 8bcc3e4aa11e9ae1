"""The extensible runner's hardware: the loop Device over the arm's one supervised link.

:class:`HardwareLink` is the :class:`hw_bridge.loop.Device` of
:class:`hw_bridge.extensible_runner.ExtensibleRunner`: the loop thread (the only one that touches
the hardware) calls :meth:`HardwareLink.read` / :meth:`HardwareLink.write` every tick. Each
:meth:`~HardwareLink.read` first applies the operator's queued bridge commands
(:class:`hw_bridge.controls.QueuedBridgeControls`: the GUI only enqueues) through the
:class:`hw_bridge.link_supervisor.LinkSupervisor` both arms share, then reads the encoders, and
publishes the link's :class:`~hw_bridge.interface.LinkHealth` a few times a second (and at once
after a command or a fault). What Arm holds and what stopping means here is
:class:`StreamerStrategy`: the streamer holds where the encoders are and the console's command
is set to that posture.
"""

from __future__ import annotations

import queue
from typing import Any, Callable

import numpy as np

from core.robots import ExtensibleArm
from hw_bridge.commands import Arm, BridgeCommand, Connect
from hw_bridge.controls import QueuedBridgeControls
from hw_bridge.extensible_jobs import ARM_FIRST, Array, Counts
from hw_bridge.interface import HardwareInterface, LifecycleState, ReturnType
from hw_bridge.link_supervisor import LinkRefused, LinkSupervisor, open_serial

NOT_CONNECTED: Counts = np.zeros(0, dtype=np.int64)


class StreamerStrategy:
    """The extensible arm's side of the link verbs (:class:`~hw_bridge.link_supervisor.
    ArmStrategy`): stopping ends the streamer's job; holding arms it at the encoders and makes
    the console's command that posture (unless it is already armed)."""

    def __init__(self, streamer: Any) -> None:
        self.streamer = streamer

    def release(self, message: str) -> None:
        self.streamer.disarmed(message)

    def hold(self, hw: HardwareInterface) -> None:
        if self.streamer.armed:
            return
        pos = hw.positions()
        assert pos is not None  # LinkSupervisor.arm checked
        self.streamer.connected(pos, follow=False)
        self.streamer.settle_link()


class HardwareLink:
    """:class:`hw_bridge.loop.Device` over a HardwareInterface that may come and go.

    Args:
        robot: The extensible arm (its ``[bridge]`` settings build new links).
        factory: The runner's hardware factory (:meth:`ExtensibleRunner.connect` uses it);
            an operator's Connect replaces it by the newly opened link.
        health_every: Publish the link health every this many ticks (10: 10 Hz at 100 Hz).
        on_new_link: Called after every configure (a new receive thread): the runner's own
            process makes it real-time (:func:`hw_bridge.realtime.promote_new_threads`).
    """

    def __init__(self, robot: ExtensibleArm, factory: Callable[[], HardwareInterface],
                 health_every: int = 10,
                 on_new_link: Callable[[], None] = lambda: None) -> None:
        self.robot = robot
        self.factory = factory
        self.health_every = max(1, health_every)
        self.supervisor = LinkSupervisor(None, open_serial(robot), on_new_link)
        self.fault: str | None = None
        self.controls = QueuedBridgeControls()
        self.streamer: Any = None  # the runner's Streamer (set by the runner)
        self._ticks = 0

    @property
    def hw(self) -> HardwareInterface | None:
        """The current link (None before the first connect)."""
        return self.supervisor.hw

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
        """Make the link's health visible to ``controls.health()`` (loop thread)."""
        health = self.supervisor.health()
        if health is not None:
            self.controls.publish(health)

    # -- lifecycle (loop thread) ---------------------------------------------------------------
    def open_link(self) -> str | None:
        """Runner connect: close the link, take a new one from the factory and configure it,
        disarmed (arming is the operator's Arm, :class:`StreamerStrategy`). Returns the fault,
        or None."""
        stack = self.streamer
        stack.disarmed("reconnecting")  # a running job ends here
        hw = self.supervisor.adopt(self.factory())
        self.fault = None
        stack.fault, stack.message = None, "connecting"
        ok = hw.configure() is ReturnType.OK
        self.supervisor.on_new_link()
        if not ok:
            stack.fault = hw.fault or "configure failed"
            stack.message = f"fault: {stack.fault}"
            self.publish()
            return stack.fault
        stack.disarmed(f"connected to {getattr(hw, 'port', '') or 'the device'}; disarmed: "
                       f"{ARM_FIRST}")
        self.publish()
        return None

    def close(self) -> None:
        """Disarm and close the link (loop thread, or after the loop stopped)."""
        self.supervisor.close()

    # -- operator commands (loop thread) -------------------------------------------------------
    def _apply_commands(self) -> bool:
        applied = False
        while True:
            try:
                cmd = self.controls.commands.get_nowait()
            except queue.Empty:
                return applied
            applied = True
            self.apply(cmd)

    def apply(self, cmd: BridgeCommand) -> None:
        """Run one operator bridge command through the link supervisor (loop thread)."""
        before = self.supervisor.hw
        try:
            self.supervisor.apply(cmd, StreamerStrategy(self.streamer))
        except LinkRefused as exc:
            self.fault = exc.fault
            if exc.fault != str(exc):  # the device failed (not a refusal): the streamer says so
                failed = f"connect failed: {exc.fault}" if isinstance(cmd, Connect) else str(exc)
                self.streamer.disarmed(failed, exc.fault)
        else:
            if isinstance(cmd, (Connect, Arm)):
                self.fault = None
            if isinstance(cmd, Connect):
                self.streamer.disarmed(f"connected to {getattr(self.hw, 'port', '')}; "
                                       f"disarmed: {ARM_FIRST}")
        hw = self.supervisor.hw
        if hw is not before and hw is not None:  # a Connect opened it: the runner's from now on
            self.factory = lambda: hw
