"""Attach the console to hardware: the device emulator (default), an in-process mock, or a port.

``serve.py --hardware emulator`` (the default) starts ``python -m hw_bridge.emulator`` on a
pseudo-terminal so every demo runs through the real serial stack; ``--hardware mock`` keeps the
device in-process (no serial); ``--port-path PATH`` talks to a real controller. The soft arm's
100 Hz loop runs in :class:`console.panels.control_process.ControlProcess` (its own process,
which starts the emulator itself); the extensible arm's loop is
:class:`hw_bridge.extensible_runner.ExtensibleRunner` on a :class:`hw_bridge.interface.SerialHardware`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

HardwareMode = Literal["emulator", "mock"]


@dataclasses.dataclass
class HardwareAttachment:
    """What :func:`attach` started, so :meth:`close` can stop it in order."""

    description: str
    closers: list[Any] = dataclasses.field(default_factory=list)

    def close(self) -> None:
        """Stop loops first, then links and the emulator process."""
        for close in self.closers:
            try:
                close()
            except Exception:  # noqa: BLE001 - shutting down: keep closing the rest
                pass
        self.closers.clear()


def describe(robot: Any, mode: HardwareMode, port_path: str | None) -> str:
    """One line for the console's status and the terminal: where the arm's commands go."""
    if port_path:
        return f"Hardware: controller on {port_path} (serial)"
    if mode == "emulator":
        return "Hardware: device emulator on a pseudo-terminal (real serial stack, simulated arm)"
    return "Hardware: in-process mock device (no serial)"


def mirrors_commands(robot: Any, mode: HardwareMode, port_path: str | None) -> bool:
    """Whether the arm view should show commands at once (True) or what the device measures."""
    return not (robot.kind == "delta" and (mode == "emulator" or port_path))


def attach(app: Any, mode: HardwareMode, port_path: str | None) -> HardwareAttachment:
    """Connect ``app`` to its hardware before the panels are built (they find it on ``app``).

    Sets ``app.soft_control`` (soft arm) or ``app.extensible_runner`` (extensible arm).
    """
    robot = app.robot
    out = HardwareAttachment(describe(robot, mode, port_path))
    if robot.kind == "planar":
        from console.panels.control_process import ControlProcess

        device = "emulator" if port_path or mode == "emulator" else "mock"
        ctl = ControlProcess(robot, device=device, port_path=port_path)
        app.soft_control = ctl
        out.closers.append(ctl.close)
        return out
    if mode == "mock" and not port_path:
        return out  # ExtensibleRunner.from_app falls back to an in-process MockHardware
    from hw_bridge.config import BridgeConfig
    from hw_bridge.extensible_runner import ExtensibleRunner, StoreLink
    from hw_bridge.interface import SerialHardware

    path = port_path
    if path is None:
        from hw_bridge.soft_arm_link import EmulatorProcess

        emulator = EmulatorProcess(["--robot", str(robot.source)])
        out.closers.append(emulator.stop)
        path = emulator.path
    hardware = SerialHardware(BridgeConfig.from_robot(robot), path)
    runner = ExtensibleRunner(robot, lambda: hardware, link=StoreLink(app.store), follow=False)
    app.extensible_runner = runner
    out.closers.insert(0, runner.close)
    runner.start()
    return out
