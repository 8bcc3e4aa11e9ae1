"""What the soft arm's control process drives: the simulated arm or hardware behind a link.

:class:`SimWorld` steps :class:`core.control.sim.SoftArmSim` inside the loop;
:class:`HardwareWorld` is a :class:`hw_bridge.soft_arm_link.SoftArmLink` (device emulator on a
pty, in-process mock, or a real port) with motion capture. Both offer the same operator verbs
to :mod:`hw_bridge.soft_arm_process`'s child: ``arm`` / ``disarm`` / ``connect`` /
``disconnect`` (run by the loop thread, the only writer to hardware) and ``scene`` (what the
console draws, with the link health and the fault). Nothing here re-arms by itself: after a
link error or the operator's Disconnect only the operator's Connect / Arm bring the arm back.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from hw_bridge.soft_arm_process import DeviceOptions


NO_SERIAL_LINK = "simulated arm: no serial link (Connect / Disconnect do nothing)"
DISCONNECTED = "disconnected by the operator: Connect, then Arm, to command the arm again"


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
        from hw_bridge.loop import SimDevice
        self.sim = SoftArmSim(robot, seed=seed)
        self.device = SimDevice(self.sim)
        self.link_note: str | None = None  # set once Connect / Disconnect was asked for

    def configure(self) -> None:
        pass

    def arm(self, stack: Any) -> None:  # loop thread
        stack.arm(self.sim.cylinders.copy())

    def disarm(self, stack: Any) -> None:  # loop thread
        stack.disarm()

    def connect(self, stack: Any, port: str, baud: int) -> None:
        """Loop thread: there is no serial link to (re)open; say so (health shows it too)."""
        self.link_note = NO_SERIAL_LINK
        raise RuntimeError(NO_SERIAL_LINK)

    def disconnect(self, stack: Any) -> None:
        self.connect(stack, "", 0)

    def scene(self, runner: Any) -> tuple[Any, Any, bool, Any, Any, str | None]:
        sim = self.sim
        obj = sim.obj
        finger = sim.gripper_polyline() if sim.turn > 1e-3 else None
        health = None if self.link_note is None else _sim_health(self.link_note)
        return (None if obj is None else (float(obj.xy[0]), float(obj.xy[1])),
                None if obj is None else obj.radius, sim.captured, finger, health, None)

    def close(self) -> None:
        pass


def _promote_new_threads() -> None:
    """Loop thread, after a (re)configure started a new receive thread: make it real-time like
    the loop's other helper threads (:mod:`hw_bridge.realtime`, just below the loop), or a
    descheduled GIL holder stalls the loop past the link timeout on a loaded machine."""
    import os

    from hw_bridge.realtime import helper_priority, promote_threads, thread_policy
    try:
        if thread_policy() == os.SCHED_FIFO:
            promote_threads(helper_priority(os.sched_getparam(0).sched_priority))
    except (OSError, AttributeError):  # no real-time scheduling here: nothing to match
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


class HardwareWorld:
    """device="emulator" / "port" / "mock": SerialHardware (or MockHardware) + mocap."""

    def __init__(self, robot: Any, seed: int, opts: DeviceOptions):
        from hw_bridge.soft_arm_link import open_link
        self.kind = opts.kind
        self.link = open_link(robot, opts.kind, port_path=opts.port_path, seed=seed,  # type: ignore[arg-type]
                              emulator_args=opts.emulator_args)
        self.device = self.link.device
        self.radius: float | None = None
        self.disconnected = False  # the operator's Disconnect: no implicit reconnect on Arm

    def configure(self) -> None:
        """Before the loop starts: open the port, handshake (a failure shows as the fault)."""
        from hw_bridge.interface import ReturnType
        if self.link.hw.configure() is not ReturnType.OK:
            self.device.fault = self.link.hw.fault

    def place_object(self, x: float, y: float, r: float) -> None:
        """Command thread: put the object into the simulated world (none for a real device)."""
        if self.link.scene is not None:
            self.link.scene.place_object(x, y, r)
        self.radius = r
        self.device.object_radius = r

    def arm(self, stack: Any) -> None:
        """Loop thread (an operator action, so it may block ~100 ms): (re)connect, ARM, arm."""
        from hw_bridge.interface import LifecycleState, ReturnType
        hw = self.link.hw
        if self.disconnected:
            hw.fault = f"arm refused: {DISCONNECTED}"  # shown by the Hardware panel too
            raise RuntimeError(hw.fault)
        if hw.state is LifecycleState.UNCONFIGURED:
            ok = hw.configure() is ReturnType.OK
            _promote_new_threads()
            if not ok:
                raise RuntimeError(f"arm refused: {hw.fault}")
        if hw.state is LifecycleState.INACTIVE and hw.activate() is not ReturnType.OK:
            raise RuntimeError(f"arm refused: {hw.fault}")
        self.device.hw = hw  # (after a failed Connect the loop read motion capture only)
        self.device.fault = None
        stack.arm(self.device.cylinders())

    def disarm(self, stack: Any) -> None:  # loop thread
        from hw_bridge.interface import LifecycleState
        stack.disarm()
        if self.link.hw.state is LifecycleState.ACTIVE:
            self.link.hw.deactivate()

    def disconnect(self, stack: Any) -> None:
        """Loop thread (operator's Disconnect): stop commanding, DISARM, close the port."""
        stack.disarm()
        self.link.hw.cleanup()
        self.disconnected = True
        self.device.hw = _Unplugged(DISCONNECTED)

    def connect(self, stack: Any, port: str, baud: int) -> None:
        """Loop thread (operator's Connect): close the link, open ``port`` at ``baud`` (0: the
        robot file's) with a new SerialHardware and configure it: INACTIVE, telemetry only.

        The mock device has no port: ``mock://`` (or an empty port) reconfigures it; its mocap
        comes from that in-process device, so any other port is refused.
        """
        from hw_bridge.interface import ReturnType, SerialHardware
        old = self.link.hw
        port = port.strip() or (old.port if self.kind == "mock" else "")
        if not port:
            old.fault = "connect refused: no port given"
            raise RuntimeError(old.fault)
        if self.kind == "mock" and port != old.port:
            old.fault = (f"connect refused: the mock device is {old.port} (in-process); "
                         f"start serve.py with --port-path {port} for a real controller")
            raise RuntimeError(old.fault)
        stack.disarm()
        old.cleanup()
        hw = old if self.kind == "mock" else SerialHardware(old.config, port, baud or None)
        self.link.hw = hw
        self.disconnected = False
        self.device.fault = None
        ok = hw.configure() is ReturnType.OK
        _promote_new_threads()
        if not ok:
            self.device.hw = _Unplugged(hw.fault or "not connected")  # Arm retries configure
            raise RuntimeError(f"connect refused: {hw.fault}")
        self.device.hw = hw

    def scene(self, runner: Any) -> tuple[Any, Any, bool, Any, Any, str | None]:
        hw = self.link.hw
        fault = hw.fault if hw.state.value == "unconfigured" else None
        if self.disconnected:
            fault = DISCONNECTED
        health = hw.health()
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
