"""Attach the console to hardware: the device emulator (default), an in-process mock, or a port.

``serve.py --hardware emulator`` (the default) starts ``python -m hw_bridge.emulator`` on a
pseudo-terminal so every demo runs through the real serial stack; ``--hardware mock`` keeps the
device in-process (no serial); ``--port-path PATH`` talks to a real controller. The soft arm's
100 Hz loop runs in :class:`console.panels.control_process.ControlProcess` (its own process,
which starts the emulator itself); the extensible arm's loop is
:class:`hw_bridge.extensible_runner.ExtensibleRunner` on a :class:`hw_bridge.interface.SerialHardware`.

:func:`attach` also sets ``app.bridge_controls``: the loop's
:class:`hw_bridge.controls.BridgeControls` (connect / disconnect / arm / disarm / health, all
enqueue-only) for the Hardware panel (``console.panels.hardware``), or None when the loop has
none to offer (the extensible arm's lazily built in-process mock; a loop without the property).
"""

from __future__ import annotations

import dataclasses
import html
from pathlib import Path
from typing import Any, Literal

HardwareMode = Literal["emulator", "mock"]
LinkKind = Literal["emulator", "mock", "port"]


@dataclasses.dataclass
class HardwareAttachment:
    """What :func:`attach` started, so :meth:`close` can stop it in order.

    Attributes:
        description: One line for the status bar and the terminal.
        kind: ``"emulator"`` (device emulator on a pty), ``"mock"`` (in-process device, no
            serial) or ``"port"`` (a real controller).
        port_path: The serial device the console uses, when known here: ``--port-path``, or the
            extensible arm's emulator pty. None for the soft arm's emulator (its control process
            starts it; the Hardware panel takes the path from the link health) and for the mock.
        baud: The link's baud rate (``[bridge] baud`` of the robot file).
    """

    description: str
    kind: LinkKind = "mock"
    port_path: str | None = None
    baud: int = 1_000_000
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


def link_kind(mode: HardwareMode, port_path: str | None) -> LinkKind:
    """What the link is: a real port (``--port-path`` wins), the emulator, or the mock."""
    return "port" if port_path else mode


def report_device_log(app: Any) -> list[str]:
    """Point the emulator's event log at ``<data-dir>/device-events.jsonl`` and say what it
    logged after the previous console's last start: a host that died and whether the device
    watchdog tripped (terminal and the status line). Returns those lines."""
    import os
    import sys

    from hw_bridge.device_events import (EVENT_LOG_ENV, EVENT_LOG_NAME, describe_loss,
                                         unreported_host_losses)
    data = getattr(app, "data", None)
    if data is None:
        return []
    log = Path(data.root) / EVENT_LOG_NAME
    os.environ[EVENT_LOG_ENV] = str(log)  # inherited by the control process and the emulator
    lines = [describe_loss(ev) for ev in unreported_host_losses(log)]
    for line in lines:
        print(f"serve.py: device log {log}: {line}", file=sys.stderr, flush=True)
    status = getattr(app, "status", None)
    if lines and status is not None:
        status.content += "<br><small><b>Device log:</b> " + html.escape(lines[-1]) + "</small>"
    return lines


def attach(app: Any, mode: HardwareMode, port_path: str | None) -> HardwareAttachment:
    """Connect ``app`` to its hardware before the panels are built (they find it on ``app``).

    Sets ``app.soft_control`` (soft arm) or ``app.extensible_runner`` (extensible arm), and
    ``app.bridge_controls`` (the loop's ``bridge_controls``, or None when it has none).
    """
    from hw_bridge.config import BridgeConfig

    robot = app.robot
    out = HardwareAttachment(describe(robot, mode, port_path), kind=link_kind(mode, port_path),
                             port_path=port_path or None,
                             baud=BridgeConfig.from_robot(robot).baud)
    app.bridge_controls = None
    if mode == "emulator" and not port_path:
        report_device_log(app)
    if robot.kind == "planar":
        from console.panels.control_process import ControlProcess

        device = "emulator" if port_path or mode == "emulator" else "mock"
        ctl = ControlProcess(robot, device=device, port_path=port_path,
                             cpus=getattr(app, "cpu_partition", "auto"))
        app.soft_control = ctl
        app.bridge_controls = getattr(ctl, "bridge_controls", None)
        out.closers.append(ctl.close)
        return out
    if mode == "mock" and not port_path:
        # ExtensibleRunner.from_app builds an in-process MockHardware runner on first use: no
        # serial link to manage, the Hardware panel says so.
        return out
    from hw_bridge.extensible_runner import ExtensibleRunner, StoreLink
    from hw_bridge.interface import SerialHardware

    path = port_path
    if path is None:
        from hw_bridge.soft_arm_link import EmulatorProcess

        emulator = EmulatorProcess(["--robot", str(robot.source)])
        out.closers.append(emulator.stop)
        path = emulator.path
        out.port_path = path
    hardware = SerialHardware(BridgeConfig.from_robot(robot), path)
    runner = ExtensibleRunner(robot, lambda: hardware, link=StoreLink(app.store), follow=False)
    app.extensible_runner = runner
    app.bridge_controls = getattr(runner, "bridge_controls", None)
    out.closers.insert(0, runner.close)
    runner.start()
    return out
