"""The soft arm's hardware side for the control process: emulator, real port or in-process mock.

:func:`open_link` builds a :class:`SoftArmLink`: the :class:`~hw_bridge.interface.SerialHardware`
(or :class:`~hw_bridge.mock.MockHardware`), a motion-capture source and the loop's
:class:`~hw_bridge.loop_devices.HardwareDevice`, plus a *scene* handle that places the object in the
simulated world (emulator: its UDP scene channel on 127.0.0.1; mock: the in-process sim; a real
device has none - the object is put down by hand). :meth:`SoftArmLink.close` tears it all down,
including the emulator process (which also exits, after logging its watchdog's trip, if this
process dies: :mod:`hw_bridge.device_events`).

* ``"emulator"``: spawns ``python -m hw_bridge.emulator --robot R --mocap-port P
  --control-port 0 --seed S``, reads the pty path from its first stdout line and the
  scene port from its ``control`` event; mocap is a :class:`~hw_bridge.mocap.UdpMocapReceiver`.
* ``"port"``: a real device at ``port_path``; mocap on the robot's ``[emulator].mocap_port``.
* ``"mock"``: MockHardware; :class:`MockPlantMocap` steps the same
  :class:`core.control.sim.EmulatorPlant` from the mock's motor positions at 100 Hz.
"""

from __future__ import annotations

import json
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Literal

from hw_bridge.config import BridgeConfig, EmulatorConfig
from hw_bridge.mocap import MocapFrame, UdpMocapReceiver
from hw_bridge.parent_watch import child_env, quiesce_blas_on_fork

DeviceKind = Literal["emulator", "port", "mock"]
_ROOT = Path(__file__).resolve().parent.parent


class EmulatorProcess:
    """``python -m hw_bridge.emulator`` as a subprocess with its stdout events pumped.

    The emulator stands in for a microcontroller, which nothing on the host can delay: it runs
    under ``SCHED_FIFO`` at ``sched_priority`` (below the control loop's 50; ignored without the
    permission), so a loaded machine does not make the link look lost (> 40 ms silent).
    It watches this process (``HW_BRIDGE_PARENT_PID``): if this one dies, even by SIGKILL, it
    waits for its watchdog to trip, logs that (stderr, the event log) and exits within 0.4 s.
    """

    command: tuple[str, ...] = ("-m", "hw_bridge.emulator")  # what the interpreter runs

    def __init__(self, args: list[str], start_timeout: float = 10.0, sched_priority: int = 45):
        if sched_priority and "--sched-priority" not in args:
            args = [*args, "--sched-priority", str(sched_priority)]
        self.realtime = _arg(args, "--sched-priority") not in (None, "0")
        self.proc = subprocess.Popen([sys.executable, *self.command, *args],
                                     cwd=_ROOT, stdout=subprocess.PIPE, text=True,
                                     env=child_env(), preexec_fn=quiesce_blas_on_fork)
        assert self.proc.stdout is not None
        self.path = self.proc.stdout.readline().strip()
        if not self.path.startswith("/dev/"):
            self.stop()
            raise RuntimeError(f"emulator did not start (first line {self.path!r})")
        self.events: queue.Queue[dict[str, Any]] = queue.Queue()
        self.last: dict[str, dict[str, Any]] = {}
        threading.Thread(target=self._pump, daemon=True, name="emulator-events").start()

    def _pump(self) -> None:  # also keeps the pipe drained so the emulator never blocks
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                ev = json.loads(line)
            except ValueError:
                continue
            self.last[ev.get("event", "?")] = ev
            self.events.put(ev)

    def wait_event(self, name: str, timeout: float) -> dict[str, Any]:
        end = time.monotonic() + timeout
        while True:
            remaining = end - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"emulator sent no {name!r} event within {timeout} s")
            try:
                ev = self.events.get(timeout=remaining)
            except queue.Empty:
                continue
            if ev.get("event") == name:
                return ev

    @property
    def pid(self) -> int:
        return self.proc.pid

    def stop(self, timeout: float = 3.0) -> int | None:
        """SIGTERM, wait, then SIGKILL; returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout)
        return self.proc.returncode


def _arg(args: Any, flag: str) -> str | None:
    """The value after ``flag`` in a command line, or None."""
    args = list(args)
    return args[args.index(flag) + 1] if flag in args[:-1] else None


class UdpScene:
    """Client of the emulator's scene channel (JSON datagrams, one answer each)."""

    def __init__(self, port: int, timeout: float = 0.2, tries: int = 3):
        self.addr = ("127.0.0.1", port)
        self.timeout, self.tries = timeout, tries
        self._lock = threading.Lock()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.settimeout(timeout)

    def request(self, **msg: Any) -> dict[str, Any]:
        """Send and wait for the answer (retried); RuntimeError on refusal or silence."""
        data = json.dumps(msg).encode()
        with self._lock:
            for _ in range(self.tries):
                self._sock.sendto(data, self.addr)
                try:
                    reply = json.loads(self._sock.recv(65536))
                except (socket.timeout, ValueError):
                    continue
                if not reply.get("ok"):
                    raise RuntimeError(f"emulator refused {msg.get('cmd')}: {reply.get('error')}")
                return reply
        raise RuntimeError(f"emulator scene channel {self.addr} did not answer {msg.get('cmd')}")

    def place_object(self, x: float, y: float, r: float) -> None:
        self.request(cmd="place_object", x=x, y=y, r=r)

    def remove_object(self) -> None:
        self.request(cmd="remove_object")

    def scene(self) -> dict[str, Any]:
        return self.request(cmd="scene")

    def close(self) -> None:
        self._sock.close()


class MockPlantMocap:
    """Mock mode: steps an EmulatorPlant from MockHardware's motors; a mocap source and a scene."""

    def __init__(self, hardware: Any, plant: Any, period_s: float):
        self.hw, self.plant, self.period = hardware, plant, period_s
        self._lock = threading.Lock()
        self._latest: MocapFrame | None = None
        self._stop = threading.Event()
        self._seq = 0
        self._thread = threading.Thread(target=self._run, daemon=True, name="mock-plant")

    def _run(self) -> None:
        nxt = time.monotonic()
        while not self._stop.wait(max(0.0, nxt - time.monotonic())):
            with self.hw.runner.lock:
                pos = self.hw.device.motors.position.copy()
            with self._lock:
                self.plant.step(pos, self.period)
                pts, valid = self.plant.mocap_frame()
            now = time.monotonic()
            self._seq += 1
            self._latest = MocapFrame(self._seq, now, now, pts, valid)
            nxt += self.period
            if nxt <= now:
                nxt = now + self.period

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(1.0)

    def latest(self) -> MocapFrame | None:
        return self._latest

    def place_object(self, x: float, y: float, r: float) -> None:
        with self._lock:
            self.plant.sim.place_object(x, y, r)

    def remove_object(self) -> None:
        with self._lock:
            self.plant.sim.remove_object()

    def scene(self) -> dict[str, Any]:
        with self._lock:
            sim = self.plant.sim
            obj = sim.obj
            return {"captured": sim.captured,
                    "finger": sim.gripper_polyline().tolist() if sim.turn > 1e-3 else None,
                    "object": None if obj is None else [*map(float, obj.xy), obj.radius]}


class SoftArmLink:
    """Hardware + mocap + HardwareDevice (+ scene, + emulator process) for one soft arm."""

    def __init__(self, kind: DeviceKind, hardware: Any, mocap: Any, device: Any,
                 scene: Any | None, emulator: EmulatorProcess | None):
        self.kind, self.hw, self.mocap, self.device = kind, hardware, mocap, device
        self.scene, self.emulator = scene, emulator

    def close(self) -> None:
        """Disarm and close the port, stop mocap, end the emulator (idempotent)."""
        for step in (self.hw.cleanup, getattr(self.hw, "shutdown", None), self.mocap.stop,
                     getattr(self.scene, "close", None),
                     None if self.emulator is None else self.emulator.stop):
            if step is None:
                continue
            try:
                step()
            except Exception:  # noqa: BLE001 - teardown continues whatever failed before
                pass


def start_emulator(robot: Any, mocap_port: int, seed: int = 0,
                   emulator_args: tuple[str, ...] = ()) -> tuple[EmulatorProcess, UdpScene]:
    """Start the soft arm's device emulator (mocap to ``mocap_port``) and open its scene
    channel, once it serves; also how a dead emulator is replaced on a reconnect."""
    emu = EmulatorProcess(["--robot", str(robot.source), "--mocap-port", str(mocap_port),
                           "--control-port", "0", "--seed", str(seed), *emulator_args])
    try:
        scene = UdpScene(int(emu.wait_event("control", 10.0)["port"]))
    except Exception:
        emu.stop()
        raise
    if emu.realtime:  # it serves once its pty keeper (a Python process) has started: under
        try:  # load that took longer than the first HELLO's 500 ms ("no HELLO answer" at start)
            emu.wait_event("scheduling", 30.0)  # (its last event before serving)
        except TimeoutError:
            pass  # then the first configure may fail; the operator's Arm configures again
    return emu, scene


def open_link(robot: Any, kind: DeviceKind, *, port_path: str | None = None, seed: int = 0,
              mocap_port: int | None = None, emulator_args: tuple[str, ...] = ()) -> SoftArmLink:
    """Build the link (not configured yet: the caller's control thread configures it).

    Args:
        robot: The soft arm (``robot.source`` is passed to the emulator).
        kind: ``"emulator"``, ``"port"`` (needs ``port_path``) or ``"mock"``.
        port_path: Serial device of a real controller.
        seed: Seed of the simulated arm (emulator / mock).
        mocap_port: UDP port to receive on (default: any free port for the emulator, the
            robot's ``[emulator].mocap_port`` for a real device).
        emulator_args: Extra emulator arguments (fault injection, ``--baud``).
    """
    from hw_bridge.interface import SerialHardware
    from hw_bridge.loop_devices import HardwareDevice

    n = robot.n_segments
    radius = robot.capture.nominal_object_radius
    if kind == "mock":
        from core.control.sim import EmulatorPlant
        from hw_bridge.mock import MockHardware
        hw = MockHardware(robot)
        src = MockPlantMocap(hw, EmulatorPlant(robot, seed=seed), hw.config.period_s)
        src.start()
        return SoftArmLink(kind, hw, src, HardwareDevice(hw, src, n, radius), src, None)
    config = BridgeConfig.from_robot(robot)
    if kind == "port":
        if not port_path:
            raise ValueError("device 'port' needs port_path (the controller's serial device)")
        rx = UdpMocapReceiver(EmulatorConfig.from_robot(robot).mocap_port if mocap_port is None
                              else mocap_port)
        rx.start()
        hw = SerialHardware(config, port_path)
        return SoftArmLink(kind, hw, rx, HardwareDevice(hw, rx, n, radius), None, None)
    if kind != "emulator":
        raise ValueError(f"unknown device {kind!r}: expected 'emulator', 'port' or 'mock'")
    rx = UdpMocapReceiver(0 if mocap_port is None else mocap_port)
    rx.start()
    try:
        emu, scene = start_emulator(robot, rx.addr[1], seed, emulator_args)
    except Exception:
        rx.stop()
        raise
    hw = SerialHardware(config, emu.path)
    return SoftArmLink(kind, hw, rx, HardwareDevice(hw, rx, n, radius), scene, emu)

