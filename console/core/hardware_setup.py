"""Attach the console to hardware: the device emulator (default), an in-process mock, or a port.

``serve.py --hardware emulator`` (the default) starts ``python -m hw_bridge.emulator`` on a
pseudo-terminal so every demo runs through the real serial stack; ``--hardware mock`` keeps the
device in-process (no serial); ``--port-path PATH`` talks to a real controller. The soft arm's
100 Hz loop runs in :class:`hw_bridge.soft_arm_process.ControlProcess` (its own process,
which starts the emulator itself); the extensible arm's loop is
:class:`hw_bridge.extensible_process.ExtensibleProcess` (its own process too) on a
:class:`hw_bridge.interface.SerialHardware` to the emulator's pty or the controller (or, with
``--hardware mock``, on an in-process MockHardware in that process, ``mock://``). Both arms
start connected and disarmed: only the operator's Arm arms.

:func:`attach` returns the :class:`console.core.services.ConsoleServices` the app is built with: the
loop, and its :class:`hw_bridge.controls.BridgeControls` (connect / disconnect / arm / disarm /
health, all enqueue-only) for the Hardware panel (``console.panels.common.hardware``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from console.core.hardware_attachment import HardwareAttachment, LinkKind
from console.core.services import ConsoleServices

if TYPE_CHECKING:
    from console.core.state import StateStore
    from hw_bridge.cpu_partition import CpuPartition

HardwareMode = Literal["emulator", "mock"]


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


def report_device_log(data_root: Path) -> list[str]:
    """Point the emulator's event log at ``<data-dir>/device-events.jsonl`` and say what it
    logged after the previous console's last start: a host that died and whether the device
    watchdog tripped (printed to the terminal; ``serve.py`` adds the last to the status line).
    Returns those lines."""
    import os
    import sys

    from hw_bridge.device_events import (EVENT_LOG_ENV, EVENT_LOG_NAME, describe_loss,
                                         unreported_host_losses)
    log = Path(data_root) / EVENT_LOG_NAME
    os.environ[EVENT_LOG_ENV] = str(log)  # inherited by the control process and the emulator
    lines = [describe_loss(ev) for ev in unreported_host_losses(log)]
    for line in lines:
        print(f"serve.py: device log {log}: {line}", file=sys.stderr, flush=True)
    return lines


def attach(robot: Any, store: StateStore, mode: HardwareMode, port_path: str | None,
           cpus: CpuPartition | None | Literal["auto"] = "auto",
           slip: float | None = None) -> ConsoleServices:
    """Start ``robot``'s control loop on its hardware, before the app and its panels exist.

    Returns the services with ``hardware`` (what to close), ``soft_control`` (soft arm) or
    ``extensible_runner`` (extensible arm; ``store`` is the console's command/report channel),
    ``bridge_controls`` and ``cpu_partition``.
    ``slip`` (extensible arm on the emulator only): the emulator's racks slip on their pinions
    by that fraction (``--slip``) and stream the tip, read by ``tip_sensor``.

    Raises:
        ValueError: ``slip`` for another arm or hardware than the extensible arm's emulator.
    """
    if slip is not None and (robot.kind != "delta" or port_path or mode != "emulator"):
        raise ValueError("--slip needs the extensible arm on the device emulator")
    from hw_bridge.config import BridgeConfig

    out = HardwareAttachment(describe(robot, mode, port_path), kind=link_kind(mode, port_path),
                             port_path=port_path or None,
                             baud=BridgeConfig.from_robot(robot).baud)
    if robot.kind == "planar":
        from hw_bridge import soft_arm_process

        device = "emulator" if port_path or mode == "emulator" else "mock"
        ctl = soft_arm_process.ControlProcess(robot, device=device, port_path=port_path, cpus=cpus)
        out.closers.append(ctl.close)
        return ConsoleServices(hardware=out, soft_control=ctl, bridge_controls=ctl.bridge_controls,
                               cpu_partition=None if cpus == "auto" else cpus)
    from hw_bridge import extensible_process
    from hw_bridge.cpu_partition import CpuPartition, format_cpus

    part = CpuPartition.default() if cpus == "auto" else cpus
    if mode == "mock" and not port_path:
        # A MockHardware in the runner's process (``mock://``), connected at start like every
        # link and, like every link, armed only by the operator's Arm (the Hardware panel's).
        runner = extensible_process.ExtensibleProcess(robot, store, "mock", cpus=part)
        out.closers.insert(0, runner.close)
        out.port_path = "mock://"
        runner.start()
        return ConsoleServices(hardware=out, extensible_runner=runner,
                               bridge_controls=runner.bridge_controls, cpu_partition=part)
    path = port_path
    tip_sensor = None  # serve.py --slip: the emulator's tip stream
    if path is None:
        from hw_bridge import soft_arm_link

        on_cpus = () if part is None else ("--cpus", format_cpus(part.realtime))
        slip_args: tuple[str, ...] = ()
        if slip is not None:
            from hw_bridge.extensible_closed_loop import TipSensor
            from hw_bridge.mocap import UdpMocapReceiver
            receiver = UdpMocapReceiver(0)
            receiver.start()
            out.closers.append(receiver.stop)
            tip_sensor = TipSensor(receiver)
            slip_args = ("--slip", str(slip), "--tip-port", str(receiver.addr[1]))
        emulator_args = ["--robot", str(robot.source), *on_cpus, *slip_args, "--mid-range"]
        emulator = soft_arm_link.EmulatorProcess(emulator_args)
        path = emulator.path
        out.port_path = path
    # Connecting never arms and arming never moves: Arm holds where the encoders are and makes
    # that the console's command. The emulator's racks start at the console's start pose
    # (--mid-range: console.core.model.ExtensibleModel.initial), so nothing needs to move there.
    runner = extensible_process.ExtensibleProcess(robot, store, "port", path, cpus=part)
    out.closers.insert(0, runner.close)
    runner.start()
    controls: Any = runner.bridge_controls
    if port_path is None:  # our emulator: a reconnect brings a dead one back
        from hw_bridge.reviving_controls import RevivingControls

        def new_path(path: str) -> None:
            out.port_path = path
            runner.use_port(path)

        controls = RevivingControls(controls, emulator,
                                    lambda: soft_arm_link.EmulatorProcess(emulator_args),
                                    new_path)
        out.closers.append(controls.stop)
    return ConsoleServices(hardware=out, extensible_runner=runner, bridge_controls=controls,
                           cpu_partition=part, tip_sensor=tip_sensor)
