"""Device emulator on a pseudo-terminal, so the whole serial stack runs without hardware.

``python -m hw_bridge.emulator --robot extensible|soft-arm [--baud B] [--drop P] [--corrupt P]
[--stall-after S] [--disconnect-after S [--disconnect-for D]] [--motors N] [--mocap-port P]
[--seed S] [--object X Y R] [--control-port P]``

* stdout line 1: the pty slave path (open it with pyserial); later lines: JSON events
  (``{"event": "watchdog_tripped", "t": ..., "positions": [...]}``, armed, disarmed,
  link_cut, link_restored, stalled, status on SIGUSR1, exit).
* Wire time at ``--baud``: each direction is a serial line delivering ``10/baud`` s per byte
  (``--baud 0``: no wire model, like the Due's native USB port).
* Faults: ``--drop P`` / ``--corrupt P`` drop or bit-flip each outgoing frame and each incoming
  chunk with probability P; ``--stall-after S`` freezes the device (no processing, no output,
  like a hung MCU); ``--disconnect-after S`` cuts the wire (bytes lost both ways, the device
  keeps running so its watchdog acts) for ``--disconnect-for D`` s (default: for good).
* SIGUSR2 toggles the hardware e-stop input. SIGTERM/SIGINT exit cleanly.

Soft arm: the plant is :class:`core.control.sim.EmulatorPlant` (the console's seeded soft-arm
sim: stick-slip, pre-pressure stiffening, object and gripper, marker noise and occlusions)
driven by the encoder positions; every tick one UDP motion-capture frame goes to
``127.0.0.1:--mocap-port``: base, segment ends (NaN while occluded, ``valid`` false), then the
object centre while an object is present. ``--object X Y R`` places a disc at start.
``--control-port P`` (0: any free port) opens a scene channel on ``127.0.0.1:P`` (stdout event
``{"event": "control", "port": N}``); datagrams are JSON, each answered to the sender with
``{"ok": true, ...}`` or ``{"ok": false, "error": ...}``:
``{"cmd": "place_object", "x": X, "y": Y, "r": R}``, ``{"cmd": "remove_object"}``,
``{"cmd": "scene"}`` (answer: ``object`` [x, y, r] or null, ``captured``, ``finger`` polyline
or null). It stands in for moving the real object by hand.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import queue
import random
import select
import signal
import socket
import sys
import threading
import time
import tty
from typing import Any, Callable

from core.robots import ExtensibleArm, Robot, load
from hw_bridge.config import BridgeConfig, EmulatorConfig
from hw_bridge.device import DeviceCore
from hw_bridge.device_events import EventSink, HostWatch
from hw_bridge.mocap import encode_mocap_packet
from hw_bridge.plants import MotorBank


_SINK = EventSink.from_env()  # stdout, + log file and stderr when a console started us


def _emit(event: str, **fields: Any) -> None:
    _SINK.emit(event, **fields)


class _Writer(threading.Thread):
    """TX line: one frame at a time, each taking len*10/baud seconds before it reaches the host."""

    def __init__(self, fd: int, baud: int, connected: Callable[[], bool]):
        super().__init__(daemon=True, name="emulator-tx")
        self.fd, self.baud, self.connected = fd, baud, connected
        self.q: queue.Queue[bytes | None] = queue.Queue()
        self.dropped_overflow = 0

    def run(self) -> None:
        while (data := self.q.get()) is not None:
            if self.baud:
                time.sleep(len(data) * 10 / self.baud)
            if not self.connected():
                continue  # nobody has the port open: the bytes go nowhere
            try:
                os.write(self.fd, data)
            except BlockingIOError:
                self.dropped_overflow += 1  # nobody reads the pty: drop, like a UART
            except OSError:
                return


class Emulator:
    """Device process state: pty, wire model, faults, the DeviceCore and the plants."""

    def __init__(self, robot: Robot, args: argparse.Namespace):
        self.args = args
        self.rng = random.Random(args.seed)
        self.bridge = BridgeConfig.from_robot(robot, n_motors=args.motors)
        emu = EmulatorConfig.from_robot(robot)
        self.baud = self.bridge.baud if args.baud is None else args.baud
        self.master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(slave)
        # Close our slave end: while no host has the port open the master reads EIO ("cable
        # unplugged") and output is dropped instead of piling up stale frames in the pty.
        os.close(slave)
        self.host_present = False
        now = time.monotonic()
        self.t0 = now
        self.core = DeviceCore(MotorBank(self.bridge.n_motors, emu.motor_speed_counts),
                               self.bridge.watchdog_s, self.bridge.period_s, now=now)
        self.plant: Any = None  # core.control.sim.EmulatorPlant for the soft arm
        self.udp: socket.socket | None = None
        self.control: socket.socket | None = None
        if not isinstance(robot, ExtensibleArm):
            from core.control.sim import EmulatorPlant
            self.plant = EmulatorPlant(robot, seed=0 if args.seed is None else args.seed)
            if args.object is not None:
                self.plant.sim.place_object(*args.object)
            self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.mocap_addr = ("127.0.0.1", args.mocap_port or emu.mocap_port)
            self.mocap_seq = 0
            if args.control_port is not None:
                self.control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self.control.bind(("127.0.0.1", args.control_port))
                self.control.setblocking(False)
        elif args.object is not None or args.control_port is not None:
            raise ValueError("--object and --control-port need the soft arm")
        self.writer = _Writer(self.master, self.baud, lambda: self.host_present)
        self.rx_pending: list[tuple[float, bytes]] = []
        self.rx_busy_until = now
        self.stop = False
        self.stalled = False
        self.cut = False
        self.requests: set[str] = set()  # filled by signal handlers, served by the loop

    # -- wire ---------------------------------------------------------------------------------
    def _fault(self, data: bytes) -> bytes | None:
        if self.args.drop and self.rng.random() < self.args.drop:
            return None
        if self.args.corrupt and self.rng.random() < self.args.corrupt and data:
            b = bytearray(data)
            b[self.rng.randrange(len(b))] ^= 1 << self.rng.randrange(8)
            return bytes(b)
        return data

    def _on_readable(self, now: float) -> None:
        try:
            data = os.read(self.master, 4096)
        except BlockingIOError:
            return
        except OSError:  # EIO: the host closed the port
            self._set_host(False)
            return
        self._set_host(True)
        if self.cut or self.stalled or not data:
            return True
        data = self._fault(data)
        if data is None:
            return
        start = max(now, self.rx_busy_until)
        self.rx_busy_until = start + (len(data) * 10 / self.baud if self.baud else 0.0)
        self.rx_pending.append((self.rx_busy_until, data))

    def _set_host(self, present: bool) -> None:
        if present != self.host_present:
            self.host_present = present
            self.rx_pending.clear()
            _emit("host_connected" if present else "host_disconnected")

    def _check_host(self) -> None:
        po = select.poll()
        po.register(self.master, select.POLLIN)
        self._set_host(not any(ev & select.POLLHUP for _, ev in po.poll(0)))
    def _deliver(self, now: float) -> None:
        while self.rx_pending and self.rx_pending[0][0] <= now:
            _, data = self.rx_pending.pop(0)
            self.core.receive(data, now)
        self._flush_output()

    def _flush_output(self) -> None:
        for frame in self.core.take_output():
            if self.cut or self.stalled or not self.host_present:
                continue
            frame = self._fault(frame)
            if frame is not None:
                self.writer.q.put(frame)

    # -- timer --------------------------------------------------------------------------------
    def _tick(self, now: float) -> None:
        elapsed = now - self.t0
        a = self.args
        if a.stall_after is not None and elapsed >= a.stall_after and not self.stalled:
            self.stalled = True
            _emit("stalled")
        if self.stalled:
            return
        if a.disconnect_after is not None:
            cut = elapsed >= a.disconnect_after and (
                a.disconnect_for is None or elapsed < a.disconnect_after + a.disconnect_for)
            if cut != self.cut:
                self.cut = cut
                self.rx_pending.clear()
                _emit("link_cut" if cut else "link_restored")
        self.core.tick(now)
        ev = self.core.take_events()
        pos = [int(c) for c in self.core.motors.encoders]
        if ev.watchdog_tripped:
            _emit("watchdog_tripped", positions=pos)
        if ev.armed:
            _emit("armed", positions=pos)
        if ev.disarmed:
            _emit("disarmed", positions=pos)
        if self.plant is not None and self.udp is not None:
            self.plant.step(self.core.motors.position, self.bridge.period_s)
            self.mocap_seq += 1
            pts, valid = self.plant.mocap_frame()
            try:
                self.udp.sendto(encode_mocap_packet(self.mocap_seq, now, pts, valid),
                                self.mocap_addr)
            except OSError:
                pass
        self._flush_output()

    # -- scene channel (soft arm) --------------------------------------------------------------
    def _serve_control(self) -> None:
        """Answer waiting scene datagrams (non-blocking; see the module docstring)."""
        assert self.control is not None
        while True:
            try:
                data, addr = self.control.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            try:
                reply = self._scene_command(json.loads(data))
            except Exception as exc:  # noqa: BLE001 - bad input: answer, change nothing
                reply = {"ok": False, "error": str(exc)}
            try:
                self.control.sendto(json.dumps(reply).encode(), addr)
            except OSError:
                pass

    def _scene_command(self, msg: dict[str, Any]) -> dict[str, Any]:
        sim = self.plant.sim
        cmd = msg.get("cmd") if isinstance(msg, dict) else None
        if cmd == "place_object":
            x, y, r = (float(msg[k]) for k in ("x", "y", "r"))
            if not all(map(math.isfinite, (x, y, r))):
                raise ValueError("object x, y, r must be finite")
            sim.place_object(x, y, r)
            _emit("object_placed", xy=[x, y], r=r)
            return {"ok": True}
        if cmd == "remove_object":
            sim.remove_object()
            return {"ok": True}
        if cmd == "scene":
            obj = sim.obj
            finger = sim.gripper_polyline().tolist() if sim.turn > 1e-3 else None
            return {"ok": True, "captured": sim.captured, "finger": finger,
                    "object": None if obj is None else [*map(float, obj.xy), obj.radius]}
        raise ValueError(f"unknown scene command {cmd!r}")

    def status(self) -> None:
        """Print a status event (SIGUSR1)."""
        _emit("status", armed=self.core.armed, tripped=self.core.tripped, estop=self.core.estop,
              positions=[int(c) for c in self.core.motors.encoders],
              rx_bad_frames=self.core.decoder.stats.bad_frames,
              tx_overflow=self.writer.dropped_overflow, path=self.path)

    def _serve_requests(self, now: float) -> None:
        requests, self.requests = self.requests, set()
        if "status" in requests:
            self.status()
        if "estop" in requests:
            self.core.set_estop(not self.core.estop, now)
            _emit("estop", pressed=self.core.estop)

    def run(self) -> None:
        self.writer.start()
        priority = getattr(self.args, "sched_priority", 0)
        keeper = None
        cpus = getattr(self.args, "cpus", None)
        if priority:  # a dedicated MCU is never preempted: neither is its stand-in, nor its wire
            from hw_bridge.realtime import TtyWorkerKeeper, promote_threads, thread_policy
            keeper = TtyWorkerKeeper(max(1, priority - 1)).start()  # (the pty's kworkers;
            # started before the move below, so its start-up runs where this one's did)
        if cpus:
            from hw_bridge.cpu_partition import pin_process
            pin_process(cpus)
        if priority:
            promote_threads(priority)
            _emit("scheduling", policy="SCHED_FIFO" if thread_policy() == os.SCHED_FIFO
                  else "default", priority=priority, tty_workers=keeper.promoted)
        try:
            self._serve()
        finally:  # hand the kernel workers back even if serving failed
            if keeper is not None:
                keeper.stop()
        self.writer.q.put(None)
        _emit("exit")
        try:
            os.close(self.master)
        except OSError:
            pass
        for sock in (self.udp, self.control):
            if sock is not None:
                sock.close()

    def _serve(self) -> None:
        """Serve the protocol until :attr:`stop`."""
        period = self.bridge.period_s
        next_tick = time.monotonic() + period
        host_watch = HostWatch(_SINK)  # host died: log the watchdog's trip, then exit
        while not self.stop and not host_watch.poll(time.monotonic(), self.core):
            now = time.monotonic()
            wake = next_tick if not self.rx_pending else min(next_tick, self.rx_pending[0][0])
            if self.host_present:
                ready, _, _ = select.select([self.master], [], [], max(0.0, wake - now))
            else:  # a hung-up master is always readable: sleep, then look again
                time.sleep(max(0.0, wake - now))
                self._check_host()
                ready = [self.master] if self.host_present else []
            now = time.monotonic()
            if ready:
                self._on_readable(now)
            if not self.stalled:
                self._deliver(now)
            if self.requests:
                self._serve_requests(now)
            if self.control is not None:
                self._serve_control()
            if now >= next_tick:
                self._tick(now)
                next_tick += period
                if next_tick <= now:  # overrun: skip, do not catch up
                    next_tick = now + period


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m hw_bridge.emulator", description=__doc__.split("\n")[0])
    ap.add_argument("--robot", required=True, help="robot name (extensible, soft-arm) or TOML path")
    ap.add_argument("--baud", type=int, default=None, help="wire model baud rate (0: none); "
                    "default [bridge].baud")
    ap.add_argument("--drop", type=float, default=0.0, help="probability of dropping a frame")
    ap.add_argument("--corrupt", type=float, default=0.0, help="probability of flipping a bit")
    ap.add_argument("--stall-after", type=float, default=None, metavar="S")
    ap.add_argument("--disconnect-after", type=float, default=None, metavar="S")
    ap.add_argument("--disconnect-for", type=float, default=None, metavar="D")
    ap.add_argument("--motors", type=int, default=None, help="override the channel count")
    ap.add_argument("--mocap-port", type=int, default=None, help="UDP port (soft arm)")
    ap.add_argument("--seed", type=int, default=None,
                    help="random seed of fault injection and of the soft-arm sim (default 0)")
    ap.add_argument("--object", type=float, nargs=3, default=None, metavar=("X", "Y", "R"),
                    help="soft arm: place a disc of radius R (m) at (X, Y) on the table")
    ap.add_argument("--control-port", type=int, default=None, metavar="P",
                    help="soft arm: UDP scene channel on 127.0.0.1:P (0: any free port)")
    ap.add_argument("--sched-priority", type=int, default=0, metavar="P",
                    help="run the device under SCHED_FIFO at priority P (1-99; 0: normal), like "
                         "a dedicated microcontroller that nothing else on the machine delays")
    ap.add_argument("--cpus", default=None, metavar="LIST",
                    help="run on these CPUs (comma-separated), moved there once started up, "
                         "e.g. the real-time CPU of hw_bridge.cpu_partition")
    args = ap.parse_args(argv)
    if args.cpus is not None:
        from hw_bridge.cpu_partition import parse_cpus
        try:
            args.cpus = parse_cpus(args.cpus)
        except ValueError as exc:
            ap.error(f"--cpus: {exc}")
    if not 0 <= args.sched_priority <= 99:
        ap.error("--sched-priority must be in 0..99")
    if args.object is not None and (not all(map(math.isfinite, args.object))
                                    or not args.object[2] > 0):
        ap.error("--object needs finite X Y and a radius R > 0")
    if args.control_port is not None and not 0 <= args.control_port <= 65535:
        ap.error("--control-port must be in 0..65535")
    for name in ("drop", "corrupt"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            ap.error(f"--{name} must be a probability in [0, 1]")
    if args.motors is not None and not 1 <= args.motors <= 32:
        ap.error("--motors must be in 1..32")
    if args.baud is not None and args.baud < 0:
        ap.error("--baud must be >= 0")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        robot = load(args.robot)
        emu = Emulator(robot, args)
    except Exception as exc:  # noqa: BLE001 - report any setup failure plainly
        print(f"emulator: {exc}", file=sys.stderr)
        return 2
    print(emu.path, flush=True)
    if emu.control is not None:
        _emit("control", port=emu.control.getsockname()[1])

    def _stop(signum: int, frame: object) -> None:
        emu.stop = True

    def _flag(name: str) -> Any:
        return lambda signum, frame: emu.requests.add(name)

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    signal.signal(signal.SIGUSR1, _flag("status"))
    signal.signal(signal.SIGUSR2, _flag("estop"))
    emu.run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
