"""What the soft arm's control process drives: the simulated arm or hardware behind a link.

:class:`SimWorld` steps :class:`core.control.sim.SoftArmSim` inside the loop;
:class:`HardwareWorld` is a :class:`hw_bridge.soft_arm_link.SoftArmLink` (device emulator on a
pty, in-process mock, or a real port) with motion capture, whose link verbs are the
:class:`hw_bridge.link_supervisor.LinkSupervisor` both arms share (:class:`StackStrategy` says
what they mean for the soft arm's control stack). Both worlds offer :meth:`apply` (a bridge
command, run by the loop thread, the only writer to hardware) and ``scene`` (what the console
draws, with the link health and the fault) to :mod:`hw_bridge.soft_arm_process`'s child. Nothing
here re-arms by itself: after a link error or the operator's Disconnect only the operator's
Connect / Arm bring the arm back.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from hw_bridge.commands import Arm, BridgeCommand, Connect, Disarm, Disconnect
from hw_bridge.cpu_partition import CpuPartition
from hw_bridge.link_supervisor import (DISCONNECTED, NO_SERIAL_LINK, LinkRefused, LinkSupervisor,
                                       open_serial)
from hw_bridge.realtime import promote_new_threads


@dataclasses.dataclass(frozen=True)
class DeviceOptions:
    """Which device the child's loop drives (:class:`hw_bridge.soft_arm_process.ControlProcess`).

    Here, beside the worlds that read it, so this module needs nothing from the process module
    that imports it (no import circle).
    """

    kind: str = "sim"
    port_path: str | None = None
    emulator_args: tuple[str, ...] = ()
    cpus: CpuPartition | None = None  # the loop (and emulator) on .realtime, planner on .other


def _sim_health(note: str) -> Any:
    """A LinkHealth saying that the simulated arm has no link (for the Hardware panel)."""
    from hw_bridge.interface import LinkHealth
    return LinkHealth("unconfigured", "sim://", note, False, False, False, None, None, None,
                      0, 0, 0, 0, 0, 0, None)


class SimWorld:
    """device="sim": SoftArmSim stepped by the loop itself (SimDevice)."""

    kind = "sim"

    def __init__(self, robot: Any, seed: int):
        from core.control.sim import SoftArmSim
        from hw_bridge.loop_devices import SimDevice
        self.sim = SoftArmSim(robot, seed=seed)
        self.device = SimDevice(self.sim)
        self.link_note: str | None = None  # set once Connect / Disconnect was asked for

    def configure(self) -> None:
        pass

    def apply(self, cmd: BridgeCommand, stack: Any) -> None:
        """Loop thread: Arm / Disarm the stack; there is no serial link to (re)open or close,
        so Connect / Disconnect say so (health shows it too)."""
        if isinstance(cmd, Arm):
            stack.arm(self.sim.cylinders.copy())
        elif isinstance(cmd, Disarm):
            stack.disarm()
        else:
            self.link_note = NO_SERIAL_LINK
            raise RuntimeError(NO_SERIAL_LINK)

    def scene(self, runner: Any) -> tuple[Any, Any, bool, Any, Any, str | None]:
        sim = self.sim
        obj = sim.obj
        finger = sim.gripper_polyline() if sim.turn > 1e-3 else None
        health = None if self.link_note is None else _sim_health(self.link_note)
        return (None if obj is None else (float(obj.xy[0]), float(obj.xy[1])),
                None if obj is None else obj.radius, sim.captured, finger, health, None)

    def close(self) -> None:
        pass


class _Unplugged:
    """The loop's hardware after the operator's Disconnect: motion capture is still read (the
    arm is drawn as measured, the telemetry stays current) but nothing reaches a device."""

    def __init__(self, fault: str):
        self.fault = fault

    def read(self) -> Any:
        from hw_bridge.interface import ReturnType
        return ReturnType.OK

    def write(self, counts: Any) -> Any:
        from hw_bridge.interface import ReturnType
        return ReturnType.ERROR

    def positions(self) -> None:
        return None


class StackStrategy:
    """The soft arm's side of the link verbs (:class:`~hw_bridge.link_supervisor.ArmStrategy`):
    stopping disarms the control stack; holding points the loop's device at the link again and
    arms the stack at the measured cylinders."""

    def __init__(self, world: HardwareWorld, stack: Any) -> None:
        self.world, self.stack = world, stack

    def release(self, message: str) -> None:
        self.stack.disarm()

    def hold(self, hw: Any) -> None:
        device = self.world.device
        device.hw = hw  # (after a failed Connect the loop read motion capture only)
        device.fault = None
        self.stack.arm(device.cylinders())


class HardwareWorld:
    """device="emulator" / "port" / "mock": SerialHardware (or MockHardware) + mocap."""

    def __init__(self, robot: Any, seed: int, opts: DeviceOptions):
        from hw_bridge.soft_arm_link import open_link
        self.kind = opts.kind
        self.robot, self.seed, self.emulator_args = robot, seed, opts.emulator_args
        self.link = open_link(robot, opts.kind, port_path=opts.port_path, seed=seed,  # type: ignore[arg-type]
                              emulator_args=opts.emulator_args)
        self.device = self.link.device
        self.supervisor = LinkSupervisor(self.link.hw, open_serial(robot), promote_new_threads)
        self.radius: float | None = None

    def configure(self) -> None:
        """Before the loop starts: open the port, handshake (a failure shows as the fault)."""
        from hw_bridge.interface import ReturnType
        if self.link.hw.configure() is not ReturnType.OK:
            self.device.fault = self.link.hw.fault

    def revive_emulator(self, cmd: Connect) -> Connect:
        """Command thread, before a Connect runs: if the device emulator died (killed, or
        crashed), start a new one (same mocap port, a new scene channel) and connect to its
        pty instead of the dead one's. ``cmd`` as given otherwise."""
        from hw_bridge.soft_arm_link import start_emulator
        old = self.link.emulator
        if old is None or old.proc.poll() is None:
            return cmd
        old.stop()  # reaped
        emu, scene = start_emulator(self.robot, self.link.mocap.addr[1], self.seed,
                                    self.emulator_args)
        dead_scene, self.link.scene, self.link.emulator = self.link.scene, scene, emu
        if dead_scene is not None:
            dead_scene.close()
        port = emu.path if cmd.port in ("", old.path) else cmd.port
        return Connect(port, cmd.baud)

    def place_object(self, x: float, y: float, r: float) -> None:
        """Command thread: put the object into the simulated world (none for a real device)."""
        if self.link.scene is not None:
            self.link.scene.place_object(x, y, r)
        self.radius = r
        self.device.object_radius = r

    def apply(self, cmd: BridgeCommand, stack: Any) -> None:
        """Loop thread (an operator action, so it may block ~100 ms): run ``cmd`` through the
        link supervisor; a refusal raises (the command's Future carries it to the console)."""
        sup = self.supervisor
        try:
            sup.apply(cmd, StackStrategy(self, stack))
        except LinkRefused as exc:
            if isinstance(cmd, Connect) and exc.fault != str(exc):  # opened, configure failed:
                self.device.fault = None  # the loop reads motion capture only; Arm retries
                self.device.hw = _Unplugged(exc.fault or "not connected")
            raise
        else:
            if isinstance(cmd, Connect):
                self.device.hw, self.device.fault = sup.hw, None
            elif isinstance(cmd, Disconnect):
                self.device.hw = _Unplugged(DISCONNECTED)
        finally:
            self.link.hw = sup.hw  # (a Connect may have opened a new one: closed with the link)

    @property
    def disconnected(self) -> bool:
        return self.supervisor.disconnected

    def scene(self, runner: Any) -> tuple[Any, Any, bool, Any, Any, str | None]:
        hw = self.link.hw
        fault = hw.fault if hw.state.value == "unconfigured" else None
        if self.disconnected:
            fault = DISCONNECTED
        health = self.supervisor.health()
        sc = self.link.scene
        emu = self.link.emulator
        if emu is not None and emu.proc.poll() is not None:
            sc = None  # the emulator is gone: do not wait on its scene channel
        if sc is not None:
            try:
                s = sc.scene()
            except (RuntimeError, OSError):
                s = None
            if s is not None:
                obj, finger = s["object"], s["finger"]
                return (None if obj is None else (obj[0], obj[1]),
                        None if obj is None else obj[2], bool(s["captured"]),
                        None if finger is None else np.asarray(finger, float), health, fault)
        c = runner.snapshot.control
        xy = None if c is None or c.object_xy is None else (float(c.object_xy[0]),
                                                             float(c.object_xy[1]))
        return xy, self.radius if xy is not None else None, False, None, health, fault

    def close(self) -> None:
        self.link.close()
