"""Device side of the protocol as pure logic, shared by the emulator process and MockHardware.

The caller owns the clock and the I/O: it feeds received bytes with :meth:`DeviceCore.receive`,
calls :meth:`DeviceCore.tick` on its own 100 Hz timer and sends what :meth:`take_output`
returns. Behaviour (mirrors ``firmware/arduino_due/arduino_due.ino``):

* STATE is sent on the device timer every ``period`` and, in addition, right after each
  accepted DEMAND; the timer is then re-phased so the STATE rate stays one per period
  ("demand-synchronous telemetry": round trip = wire time, not timer phase).
* Every accepted (newer-sequence) DEMAND is echoed in ``ack_seq``, armed or not; it moves the
  motors only when armed and not tripped.
* Watchdog: armed and no valid DEMAND for ``watchdog_s`` -> motors hold and are disabled,
  ``WATCHDOG_TRIPPED`` latched until the next ARM.
"""

from __future__ import annotations

import dataclasses

from hw_bridge import protocol as p
from hw_bridge.plants import MotorBank


@dataclasses.dataclass
class DeviceEvents:
    """Things that happened during the last receive/tick, for logs and tests."""

    watchdog_tripped: bool = False
    armed: bool = False
    disarmed: bool = False
    # Longest run of DEMANDs replaced before a tick acted on them: a microcontroller reading
    # one DEMAND per period never has one; the emulator has them after its own stall (or a
    # late pty), and then moves toward the newest only (a path's corner skipped).
    superseded: int = 0


class DeviceCore:
    """Protocol state machine of the arm controller.

    Args:
        motors: The plant (encoders + drives).
        watchdog_s: Default watchdog period (CONFIG may change it).
        period_s: Telemetry period.
        now: Start time on the caller's clock, s.
    """

    def __init__(self, motors: MotorBank, watchdog_s: float, period_s: float, now: float = 0.0):
        self.motors = motors
        self.watchdog_s = watchdog_s
        self.period_s = period_s
        self.velocities = False
        self.decoder = p.StreamDecoder()
        self.armed = False
        self.tripped = False
        self.estop = False
        self._t0 = now
        self._last_tick = now
        self._last_demand = now
        self._stalled = 0.0  # the device's own stalls since the last DEMAND (see tick)
        self._seq = 0
        self._ack_seq = 0
        self._seq_valid = False
        self._next_state = now + period_s
        self._out: list[bytes] = []
        self.events = DeviceEvents()
        self._unticked = 0  # DEMANDs that set targets since the last tick

    # -- inputs ---------------------------------------------------------------------------
    def receive(self, data: bytes, now: float) -> None:
        """Feed bytes from the wire and act on complete messages."""
        for msg in self.decoder.feed(data):
            self._handle(msg, now)

    def set_estop(self, pressed: bool, now: float) -> None:
        """Hardware e-stop input; pressing it disarms."""
        self.estop = pressed
        if pressed and self.armed:
            self._disarm(now)

    def _handle(self, msg: p.Message, now: float) -> None:
        if isinstance(msg, p.Hello):
            self._seq_valid = False
            self._send(p.Hello(p.PROTOCOL_VERSION, self.motors.n, round(self.watchdog_s * 1000)))
        elif isinstance(msg, p.Arm):
            self._seq_valid = False
            if self.estop:
                return
            self.armed, self.tripped = True, False
            self.motors.hold()
            self.motors.enabled = True
            self._last_demand, self._stalled = now, 0.0
            self.events.armed = True
        elif isinstance(msg, p.Disarm):
            self._disarm(now)
        elif isinstance(msg, p.Demand):
            if self._seq_valid and not p.seq_newer(msg.seq, self._ack_seq):
                return  # older or repeated: the latest demand wins
            if msg.mask >> self.motors.n:
                return  # addresses motors we do not have: ignore the whole demand
            self._seq_valid = True
            self._ack_seq = msg.seq
            self._last_demand, self._stalled = now, 0.0
            if self.armed and not self.tripped:
                self.motors.set_targets(msg.mask, msg.counts)
                self._unticked += 1
            self._send_state(now)
            self._next_state = now + self.period_s
        elif isinstance(msg, p.Config):
            ok = 10 <= msg.watchdog_ms <= 1000 and msg.max_speed >= 0
            if ok:
                self.watchdog_s = msg.watchdog_ms / 1000.0
                self.velocities = bool(msg.telemetry & p.TELEMETRY_VELOCITIES)
                if msg.max_speed:
                    self.motors.max_speed = float(msg.max_speed)
            self._send(p.ConfigAck(msg.config_id, p.CONFIG_OK if ok else p.CONFIG_REJECTED))
        # HELLO answers, STATE and CONFIG_ACK are host-bound; a device ignores them.

    def _disarm(self, now: float) -> None:
        if self.armed:
            self.events.disarmed = True
        self.armed = False
        self.motors.hold()
        self.motors.enabled = False

    # -- timer ----------------------------------------------------------------------------
    def tick(self, now: float, stalled_s: float = 0.0) -> None:
        """Control tick: watchdog, plant step, periodic STATE.

        ``stalled_s``: how late this tick runs because the device itself could not (0 on a
        microcontroller; the emulator on a shared CPU passes its own lateness). The watchdog
        does not count that time as the host's silence (the DEMANDs the host sent meanwhile
        are still on their way in); the time since the last DEMAND while the device ran does.
        """
        self._stalled += max(0.0, stalled_s)
        if self.armed and now - self._last_demand - self._stalled > self.watchdog_s:
            self.armed, self.tripped = False, True
            self.motors.hold()
            self.motors.enabled = False
            self.events.watchdog_tripped = True
        if self._unticked > 1:
            self.events.superseded = max(self.events.superseded, self._unticked - 1)
        self._unticked = 0
        self.motors.step(now - self._last_tick)
        self._last_tick = now
        if now >= self._next_state:
            self._send_state(now)
            self._next_state += self.period_s
            if self._next_state <= now:  # overrun: skip, do not catch up
                self._next_state = now + self.period_s

    @property
    def status(self) -> int:
        """Status bits of the next STATE."""
        return ((p.Status.ARMED if self.armed else 0)
                | (p.Status.WATCHDOG_TRIPPED if self.tripped else 0)
                | (p.Status.ESTOP if self.estop else 0))

    def _send_state(self, now: float) -> None:
        self._seq = (self._seq + 1) & 0xFFFFFFFF
        vel = tuple(int(v) for v in self.motors.velocity.round()) if self.velocities else None
        self._send(p.State(
            seq=self._seq, ack_seq=self._ack_seq,
            mcu_time_us=int((now - self._t0) * 1e6) & 0xFFFFFFFF,
            status=int(self.status), rx_errors=self.decoder.stats.bad_frames & 0xFFFF,
            positions=tuple(int(c) for c in self.motors.encoders), velocities=vel))

    def _send(self, msg: p.Message) -> None:
        self._out.append(p.encode(msg))

    def take_output(self) -> list[bytes]:
        """Frames produced since the last call, in order."""
        out, self._out = self._out, []
        return out

    def take_events(self) -> DeviceEvents:
        """Events since the last call."""
        ev, self.events = self.events, DeviceEvents()
        return ev
