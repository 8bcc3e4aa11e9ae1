"""One supervisor of the hardware link for both arms: connect, disconnect, arm, disarm, health.

The operator's bridge commands (:mod:`hw_bridge.commands`: :class:`~hw_bridge.commands.Connect`,
:class:`~hw_bridge.commands.Disconnect`, :class:`~hw_bridge.commands.Arm`,
:class:`~hw_bridge.commands.Disarm`) mean the same on the soft arm and the extensible arm, so
their lifecycle logic lives here once, run by the arm's loop thread (the only writer to the
hardware); what differs per arm is a small :class:`ArmStrategy` (what "stop commanding" and "hold
where the arm is" mean for its control stack):

* ``connect(port, baud)``: stop commanding, close the link, open ``port`` with a new
  :class:`~hw_bridge.interface.SerialHardware` (the current link's settings, else the robot's
  ``[bridge]``; ``baud`` 0 keeps the current rate) and configure it: telemetry flows, nothing is
  armed. An empty port reconnects the current one. The in-process mock has no port: only
  :data:`MOCK_PORT` (or empty) reconnects it, any other port is refused with the reason.
* ``disconnect()``: stop commanding, DISARM, close the port; Arm is refused (:data:`DISCONNECTED`)
  until a Connect.
* ``arm()``: configure (if a fault closed the link) and activate, then the strategy holds where
  the arm is. Only ever on request: nothing here re-arms after a fault.
* ``disarm()``: stop commanding and DISARM (the device holds and stops); telemetry goes on.

A refused command raises :class:`LinkRefused` (its text is the reason; the link's ``fault``
carries it too, so the Hardware panel shows it).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Protocol

from hw_bridge.commands import Arm, BridgeCommand, Connect, Disarm, Disconnect
from hw_bridge.interface import HardwareInterface, LifecycleState, LinkHealth, ReturnType

MOCK_PORT = "mock://"
DISCONNECTED = "disconnected by the operator: Connect, then Arm, to command the arm again"
DISARMED = "disarmed by the operator; Arm to command the arm again"
NO_SERIAL_LINK = "simulated arm: no serial link (Connect / Disconnect do nothing)"


class LinkRefused(RuntimeError):
    """An operator's bridge command the link refused or could not carry out.

    ``str(exc)`` is the message for the operator (``"arm refused: ..."``); :attr:`fault` is the
    link's fault behind it (the same text for a refusal, the device's reason for a failure).
    """

    def __init__(self, message: str, fault: str | None = None) -> None:
        super().__init__(message)
        self.fault = fault or message


class ArmStrategy(Protocol):
    """What one arm's control stack does when the link changes (loop thread)."""

    def release(self, message: str) -> None:
        """Stop commanding (the link is about to close, reconnect or DISARM)."""

    def hold(self, hw: HardwareInterface) -> None:
        """The link was just activated: command the posture the arm is in now."""


def open_serial(robot: Any) -> Callable[[str, int, HardwareInterface | None], HardwareInterface]:
    """How Connect opens a link: the mock stays itself, anything else is a new SerialHardware
    with the current link's settings (else the robot's ``[bridge]``) at ``baud`` (0: unchanged)."""

    def open_link(port: str, baud: int, old: HardwareInterface | None) -> HardwareInterface:
        from hw_bridge.config import BridgeConfig
        from hw_bridge.interface import SerialHardware
        if old is not None and getattr(old, "port", "") == MOCK_PORT:
            return old
        config = getattr(old, "config", None) or BridgeConfig.from_robot(robot)
        if baud:
            config = dataclasses.replace(config, baud=baud)
        return SerialHardware(config, port, config.baud)
    return open_link


class LinkSupervisor:
    """The link of one arm's loop, changed only by the operator's bridge commands.

    Args:
        hw: The link to start with (None: not connected yet).
        open_link: Builds the link a Connect opens (``open_link(port, baud, old)``; see
            :func:`open_serial`); called after the old link was cleaned up.
        on_new_link: Called after every configure that may have started a new receive thread
            (the soft arm's process makes it real-time like its other helper threads).
    """

    def __init__(self, hw: HardwareInterface | None,
                 open_link: Callable[[str, int, HardwareInterface | None], HardwareInterface],
                 on_new_link: Callable[[], None] = lambda: None) -> None:
        self.hw = hw
        self.open_link = open_link
        self.on_new_link = on_new_link
        self.disconnected = False  # the operator's Disconnect: no implicit reconnect on Arm

    def apply(self, cmd: BridgeCommand, arm: ArmStrategy) -> None:
        """Run one bridge command (loop thread); raises :class:`LinkRefused` if refused."""
        if isinstance(cmd, Connect):
            self.connect(cmd.port, cmd.baud, arm)
        elif isinstance(cmd, Disconnect):
            self.disconnect(arm)
        elif isinstance(cmd, Arm):
            self.arm(arm)
        elif isinstance(cmd, Disarm):
            self.disarm(arm)
        else:
            raise TypeError(f"not a bridge command: {cmd!r}")

    def refuse(self, reason: str) -> LinkRefused:
        """Record ``reason`` as the link's fault (the Hardware panel shows it); the error."""
        if self.hw is not None:
            self.hw.fault = reason
        return LinkRefused(reason)

    def connect(self, port: str, baud: int, arm: ArmStrategy) -> HardwareInterface:
        """Close the link and open ``port`` (configured, not armed); the new link."""
        old = self.hw
        old_port = getattr(old, "port", "") if old is not None else ""
        port = port.strip() or old_port
        if not port:
            raise self.refuse("connect refused: no port given")
        if old_port == MOCK_PORT and port != MOCK_PORT:
            raise self.refuse(f"connect refused: the mock device is {MOCK_PORT} (in-process); "
                              f"start serve.py with --port-path {port} for a real controller")
        arm.release(f"connecting to {port}")
        if old is not None:
            old.cleanup()
        hw = self.hw = self.open_link(port, int(baud), old)
        self.disconnected = False
        ok = hw.configure() is ReturnType.OK
        self.on_new_link()
        if not ok:
            raise LinkRefused(f"connect refused: {hw.fault}", hw.fault)
        return hw

    def disconnect(self, arm: ArmStrategy) -> None:
        """Stop commanding, DISARM and close the port; Arm is refused until a Connect."""
        arm.release(DISCONNECTED)
        if self.hw is not None:
            self.hw.cleanup()
        self.disconnected = True

    def arm(self, arm: ArmStrategy) -> None:
        """Configure if needed, activate, and let the strategy hold where the arm is."""
        hw = self.hw
        if hw is None or self.disconnected:
            raise self.refuse(
                f"arm refused: {DISCONNECTED if self.disconnected else 'not connected'}")
        if hw.state is LifecycleState.UNCONFIGURED:
            ok = hw.configure() is ReturnType.OK
            self.on_new_link()
            if not ok:
                raise LinkRefused(f"arm refused: {hw.fault}", hw.fault)
        if hw.state is LifecycleState.INACTIVE and hw.activate() is not ReturnType.OK:
            raise LinkRefused(f"arm refused: {hw.fault or 'activate failed'}", hw.fault)
        if hw.positions() is None:
            raise LinkRefused(f"arm refused: {hw.fault or 'no encoder reading'}", hw.fault)
        arm.hold(hw)

    def disarm(self, arm: ArmStrategy) -> None:
        """Stop commanding and DISARM (a link that cannot DISARM is closed); nothing to do
        unless the link is ACTIVE (a fault already stopped the commanding)."""
        hw = self.hw
        if hw is None or hw.state is not LifecycleState.ACTIVE:
            return
        arm.release(DISARMED)
        if hw.deactivate() is ReturnType.ERROR:
            hw.cleanup()

    def adopt(self, hw: HardwareInterface) -> HardwareInterface:
        """Close the current link and take ``hw`` instead (not configured here): a loop's own
        reconnect (the extensible runner's ``connect``), which also ends a Disconnect."""
        self.close()
        self.hw, self.disconnected = hw, False
        return hw

    def close(self) -> None:
        """DISARM and close the link (loop thread, or after the loop stopped)."""
        if self.hw is not None:
            self.hw.cleanup()

    def health(self) -> LinkHealth | None:
        """The link's health; ``armed`` only while ACTIVE (after a fault or a Disconnect the
        last STATE received may still say ARMED, but nothing is)."""
        hw = self.hw
        if hw is None:
            return None
        health = hw.health()
        if health.armed and hw.state is not LifecycleState.ACTIVE:
            health = dataclasses.replace(health, armed=False)
        return health
