"""The device emulator on a pseudo-terminal, so the whole serial stack runs without hardware.

:class:`Emulator` is the device process's state and loop: a pty whose slave end the host opens
with pyserial, a wire model at the configured baud rate (each direction a serial line delivering
``10/baud`` s per byte; baud 0: none), fault injection (drop / bit-flip frames, stall, cut the
wire for a while), the firmware's :class:`~hw_bridge.device.DeviceCore` with its motor bank and,
for the soft arm, the seeded :class:`core.control.sim.EmulatorPlant` sending one UDP
motion-capture frame per tick and an optional UDP scene channel (place/remove the object, read
the scene: :class:`hw_bridge.emulator_scene.SceneChannel`); for the extensible arm, optionally racks that slip on their pinions and a noisy tip
stream (``--slip``, ``--tip-port``: :mod:`core.control.rack_slip`). What it does is reported through an :data:`EventSink` (the command line prints
each event as a JSON line). :class:`EmulatorOptions` are its settings.

Command line, stdout protocol and scene channel: ``python -m hw_bridge.emulator``
(:mod:`hw_bridge.emulator`).
"""

from __future__ import annotations

import collections
import dataclasses
import os
import random
import select
import socket
import time
import tty
from typing import Any, Callable

from core.robots import ExtensibleArm, Robot
from hw_bridge.config import BridgeConfig, EmulatorConfig
from hw_bridge.device import DeviceCore
from hw_bridge.emulator_scene import SceneChannel
from hw_bridge.mocap import encode_mocap_packet
from hw_bridge.plants import MotorBank

EventSink = Callable[..., None]
"""``emit(event, **fields)``: one event (``"armed"``, ``"watchdog_tripped"``, ...) and its data."""

SUPERSEDED_EVENT = 3
"""A tick that finds this many DEMANDs or more replaced unacted (the emulator stalled, or the pty
delivered late: 30 ms of a 100 Hz host's demands) logs ``demands_superseded``; one or two come
from ordinary jitter between the host's and the device's periods."""


@dataclasses.dataclass(frozen=True)
class EmulatorOptions:
    """The emulator's settings (see ``python -m hw_bridge.emulator --help``); None: the robot
    file's value."""

    baud: int | None = None
    drop: float = 0.0
    corrupt: float = 0.0
    stall_after: float | None = None
    disconnect_after: float | None = None
    disconnect_for: float | None = None
    motors: int | None = None
    mocap_port: int | None = None
    seed: int | None = None
    object: tuple[float, float, float] | None = None
    control_port: int | None = None
    sched_priority: int = 0
    cpus: frozenset[int] | None = None
    slip: float | None = None
    slip_jitter: float = 0.015
    tip_noise: float = 0.002
    tip_port: int | None = None
    mid_range: bool = False  # extensible arm: racks start at mid-range, not retracted


class Emulator:
    """Device process state: pty, wire model, faults, the DeviceCore and the plants."""

    def __init__(self, robot: Robot, options: EmulatorOptions, emit: EventSink):
        self.options = options
        self.emit = emit
        if (options.slip is not None or options.tip_port is not None) and not isinstance(
                robot, ExtensibleArm):
            raise ValueError("--slip and --tip-port need the extensible arm")
        # Set by the command line: a hw_bridge.device_events.HostWatch whose poll() is true once
        # the host process died and the watchdog's outcome was logged (the emulator then exits).
        self.host_watch: Any = None
        self.rng = random.Random(options.seed)
        self.bridge = BridgeConfig.from_robot(robot, n_motors=options.motors)
        emu = EmulatorConfig.from_robot(robot)
        self.baud = self.bridge.baud if options.baud is None else options.baud
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
        self.scene: SceneChannel | None = None  # the scene channel on ``control``
        if not isinstance(robot, ExtensibleArm):
            from core.control.sim import EmulatorPlant
            self.plant = EmulatorPlant(robot, seed=0 if options.seed is None else options.seed)
            if options.object is not None:
                self.plant.sim.place_object(*options.object)
            self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.mocap_addr = ("127.0.0.1", options.mocap_port or emu.mocap_port)
            self.mocap_seq = 0
            if options.control_port is not None:
                self.control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self.control.bind(("127.0.0.1", options.control_port))
                self.control.setblocking(False)
                self.scene = SceneChannel(self.control, self.plant.sim, emit)
        elif options.object is not None or options.control_port is not None:
            raise ValueError("--object and --control-port need the soft arm")
        self.racks: Any = None  # core.control.rack_slip.SlippingRacks (extensible arm)
        self.tip_udp: socket.socket | None = None
        self.tip_seq = 0
        if options.slip is not None or options.tip_port is not None:
            self._slip_setup(robot, options)
        if options.mid_range:
            self._start_mid_range(robot)
        self.rx_pending: list[tuple[float, bytes]] = []
        self.rx_busy_until = now
        # TX line: frames leave one after another, each ``len * 10 / baud`` s on the wire, and
        # are written to the pty by this loop when their last byte is due (no writer thread).
        self.tx_pending: collections.deque[tuple[float, bytes]] = collections.deque()
        self.tx_busy_until = now
        self.dropped_overflow = 0  # frames a full pty buffer refused (nobody reads): dropped
        self.stop = False
        self.stalled = False
        self.cut = False
        self.requests: set[str] = set()  # filled by signal handlers, served by the loop

    def _slip_setup(self, robot: Robot, options: EmulatorOptions) -> None:
        """Extensible arm: racks that slip on their pinions (``--slip``) and the tip stream."""
        assert isinstance(robot, ExtensibleArm)
        if self.bridge.n_motors != robot.n_motors:
            raise ValueError(f"--slip needs the arm's {robot.n_motors} motors")
        from core.control.rack_slip import SlipModel, SlippingRacks
        model = SlipModel(fraction=options.slip or 0.0,
                          jitter=options.slip_jitter if options.slip is not None else 0.0,
                          tip_noise=options.tip_noise,
                          seed=0 if options.seed is None else options.seed)
        self.racks = SlippingRacks(robot, model)
        if options.tip_port is not None:
            self.tip_udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.tip_addr = ("127.0.0.1", options.tip_port)

    def _start_mid_range(self, robot: Robot) -> None:
        """Extensible arm: the motors (and racks) start at the console's start pose
        (:func:`core.kinematics.delta.mid_range_delta`), so arming moves nothing."""
        if not isinstance(robot, ExtensibleArm):
            raise ValueError("--mid-range needs the extensible arm")
        from hw_bridge.extensible_jobs import mid_range_counts
        counts = mid_range_counts(robot).astype(float)
        motors = self.core.motors
        if counts.shape != motors.position.shape:
            raise ValueError(f"--mid-range needs the arm's {robot.n_motors} motors")
        motors.position[:] = counts
        motors.target[:] = counts
        if self.racks is not None:  # the racks are there already: no slipping move
            travel = counts.reshape(robot.n_segments, 3) / robot.counts_per_metre
            self.racks.encoder_m = travel.copy()
            self.racks.actual_m = travel.copy()

    def _step_racks(self, now: float) -> None:
        """The racks follow the motors (slipping); send the measured tip (one point x, y, z)."""
        self.racks.step_counts(self.core.motors.position, self.bridge.period_s)
        if self.tip_udp is None:
            return
        self.tip_seq += 1
        try:
            self.tip_udp.sendto(encode_mocap_packet(self.tip_seq, now,
                                                    self.racks.measured_tip()[None], True),
                                self.tip_addr)
        except OSError:
            pass

    # -- wire ---------------------------------------------------------------------------------
    def _fault(self, data: bytes) -> bytes | None:
        if self.options.drop and self.rng.random() < self.options.drop:
            return None
        if self.options.corrupt and self.rng.random() < self.options.corrupt and data:
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
            if present:  # a new host: nothing of the last one's is still on the wire
                self.rx_pending.clear()
            # (a host that hung up: what it wrote before, on the wire still, arrives, as on a
            # UART; the DISARM of a Disconnect was dropped here and the watchdog tripped)
            self.tx_pending.clear()
            self.emit("host_connected" if present else "host_disconnected")

    def _check_host(self) -> None:
        po = select.poll()
        po.register(self.master, select.POLLIN)
        self._set_host(not any(ev & select.POLLHUP for _, ev in po.poll(0)))
    def _deliver(self, now: float) -> None:
        while self.rx_pending and self.rx_pending[0][0] <= now:
            _, data = self.rx_pending.pop(0)
            self.core.receive(data, now)
        self._flush_output(now)

    def _flush_output(self, now: float) -> None:
        """Put the device's new frames on the TX line (see :meth:`_send_due`)."""
        for frame in self.core.take_output():
            if self.cut or self.stalled or not self.host_present:
                continue
            frame = self._fault(frame)
            if frame is None:
                continue
            start = max(now, self.tx_busy_until)
            self.tx_busy_until = start + (len(frame) * 10 / self.baud if self.baud else 0.0)
            self.tx_pending.append((self.tx_busy_until, frame))
        self._send_due(now)

    def _send_due(self, now: float) -> None:
        """Write the frames whose last byte is due by ``now`` to the pty.

        Written by the device loop itself, not by a writer thread: a second thread at the same
        real-time priority waited for the loop's plant step and for the GIL before each frame,
        and on a loaded 2-core machine STATE frames reached the pty 17-23 ms after the device
        made them (the host calls the link lost after 40 ms of silence).
        """
        while self.tx_pending and self.tx_pending[0][0] <= now:
            _, frame = self.tx_pending.popleft()
            if not self.host_present or self.cut or self.stalled:
                continue  # nobody has the port open, or the wire is down: the bytes go nowhere
            try:
                os.write(self.master, frame)
            except BlockingIOError:
                self.dropped_overflow += 1  # nobody reads the pty: drop, like a UART
            except OSError:
                self._check_host()  # EIO: the host closed the port meanwhile

    def _send_soon(self, within: float) -> None:
        """Write the frames due within ``within`` s now, sleeping until each is due.

        Before the plant step: that step took up to 25 ms when other real-time work shared the
        CPU, and a STATE waiting for its wire time behind it reached the host up to 70 ms late
        (benchmarks/link_gaps.py).
        """
        while self.tx_pending:
            wait = self.tx_pending[0][0] - time.monotonic()
            if wait > within:
                return
            if wait > 0:
                time.sleep(wait)
            self._send_due(time.monotonic())

    # -- timer --------------------------------------------------------------------------------
    def _tick(self, now: float, late: float = 0.0) -> None:
        """One device period at ``now``, ``late`` s after it was due (see :meth:`_serve`)."""
        elapsed = now - self.t0
        a = self.options
        if a.stall_after is not None and elapsed >= a.stall_after and not self.stalled:
            self.stalled = True
            self.emit("stalled")
        if self.stalled:
            return
        if a.disconnect_after is not None:
            cut = elapsed >= a.disconnect_after and (
                a.disconnect_for is None or elapsed < a.disconnect_after + a.disconnect_for)
            if cut != self.cut:
                self.cut = cut
                self.rx_pending.clear()
                self.emit("link_cut" if cut else "link_restored")
        self.core.tick(now, late)
        self._flush_output(now)  # the STATE is due a wire time after the tick, not after the
        self._send_soon(0.002)  # plant step below: wait for that (< 1 ms at 1 Mbaud) and send
        ev = self.core.take_events()
        pos = [int(c) for c in self.core.motors.encoders]
        if ev.watchdog_tripped:
            self.emit("watchdog_tripped", positions=pos)
        if ev.armed:
            self.emit("armed", positions=pos)
        if ev.disarmed:
            self.emit("disarmed", positions=pos)
        if ev.superseded >= SUPERSEDED_EVENT:
            self.emit("demands_superseded", count=ev.superseded, late_ms=round(late * 1e3, 1))
        if self.plant is not None and self.udp is not None:
            self.plant.step(self.core.motors.position, self.bridge.period_s)
            self.mocap_seq += 1
            pts, valid = self.plant.mocap_frame()
            try:
                self.udp.sendto(encode_mocap_packet(self.mocap_seq, now, pts, valid),
                                self.mocap_addr)
            except OSError:
                pass
        if self.racks is not None:
            self._step_racks(now)
        self._flush_output(now)

    def status(self) -> None:
        """Print a status event (SIGUSR1)."""
        self.emit("status", armed=self.core.armed, tripped=self.core.tripped, estop=self.core.estop,
              positions=[int(c) for c in self.core.motors.encoders],
              rx_bad_frames=self.core.decoder.stats.bad_frames,
              tx_overflow=self.dropped_overflow, path=self.path)

    def _serve_requests(self, now: float) -> None:
        requests, self.requests = self.requests, set()
        if "status" in requests:
            self.status()
        if "estop" in requests:
            self.core.set_estop(not self.core.estop, now)
            self.emit("estop", pressed=self.core.estop)

    def run(self) -> None:
        priority = self.options.sched_priority
        keeper = None
        cpus = self.options.cpus
        if priority:  # a dedicated MCU is never preempted: neither is its stand-in, nor its wire
            from hw_bridge.realtime import TtyWorkerKeeper, promote_threads, thread_policy
            keeper = TtyWorkerKeeper(max(1, priority - 1)).start()  # (the pty's kworkers;
            # started before the move below, so its start-up runs where this one's did)
        if cpus:
            from hw_bridge.cpu_partition import pin_process
            pin_process(cpus)
        if priority:
            promote_threads(priority)
            self.emit("scheduling", policy="SCHED_FIFO" if thread_policy() == os.SCHED_FIFO
                  else "default", priority=priority, tty_workers=keeper.promoted)
        try:
            self._serve()
        finally:  # hand the kernel workers back even if serving failed
            if keeper is not None:
                keeper.stop()
        self.emit("exit")
        try:
            os.close(self.master)
        except OSError:
            pass
        for sock in (self.udp, self.control, self.tip_udp):
            if sock is not None:
                sock.close()

    def _serve(self) -> None:
        """Serve the protocol until :attr:`stop`."""
        period = self.bridge.period_s
        next_tick = time.monotonic() + period
        watch = self.host_watch
        while not self.stop and not (watch is not None and watch.poll(time.monotonic(), self.core)):
            now = time.monotonic()
            wake = min(next_tick, self.rx_pending[0][0] if self.rx_pending else next_tick,
                       self.tx_pending[0][0] if self.tx_pending else next_tick)
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
                self._deliver(now)  # (and writes the frames due by now)
            if self.requests:
                self._serve_requests(now)
            if self.scene is not None:
                self.scene.serve()
            if now >= next_tick:
                # A tick more than half a period late: this process could not run (its CPU was
                # taken; on the 2-core VM the loop and the emulator share one and stalls of
                # 35-60 ms were measured). A microcontroller is never late: the watchdog does
                # not count that time as the host's silence (DeviceCore.tick).
                late = now - next_tick
                self._tick(now, late if late > period / 2 else 0.0)
                next_tick += period
                if next_tick <= now:  # overrun: skip, do not catch up
                    next_tick = now + period
