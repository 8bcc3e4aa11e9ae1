"""ros2_control-like hardware lifecycle for the arms: configure -> activate -> read/write -> error.

States: ``UNCONFIGURED`` -> :meth:`configure` (port open, HELLO, CONFIG, telemetry) ->
``INACTIVE`` -> :meth:`activate` (ARM, demands streaming) -> ``ACTIVE``; :meth:`deactivate`
and :meth:`cleanup` go back. :meth:`read` / :meth:`write` return :class:`ReturnType`. Any
failure (no valid STATE for ``link_timeout`` while active, for ``hello_timeout`` while inactive:
:meth:`SerialHardware.state_timeout_s`; transport error; device reports watchdog/e-stop
while active) calls :meth:`on_error`: best-effort DISARM, port closed, state ``UNCONFIGURED``,
``fault`` set. Nothing re-arms automatically: the operator must configure (reconnect) and
activate (arm) again. configure/activate block for up to a few hundred ms; they are operator
actions, not per-cycle calls. Only the control thread may call these methods.

A receive thread (one per connection) reads the port in chunks, decodes and timestamps STATE
frames on arrival, so round trips do not include the control loop's phase; :meth:`read`
drains what it queued. The time this host itself stalled is not the device's silence
(:class:`hw_bridge.stall_credit.OwnStall`).
"""

from __future__ import annotations

import abc
import dataclasses
import enum
import itertools
import queue
import threading
import time
from typing import Callable

import numpy as np
import numpy.typing as npt

from hw_bridge import protocol as p
from hw_bridge.config import BridgeConfig
from hw_bridge.link import Link
from hw_bridge.stall_credit import OwnStall
from hw_bridge.transport import Transport, TransportError, open_serial


class LifecycleState(enum.Enum):
    """Lifecycle states (ros2_control naming)."""

    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"


class ReturnType(enum.Enum):
    """Result of every lifecycle transition and of read()/write()."""

    OK = "ok"
    ERROR = "error"


@dataclasses.dataclass(frozen=True)
class LinkHealth:
    """Snapshot for the UI; times in ms, counters cumulative since configure."""

    state: str
    port: str
    fault: str | None
    armed: bool
    watchdog_tripped: bool
    estop: bool
    rtt_ms_p50: float | None
    rtt_ms_p99: float | None
    rtt_ms_last: float | None
    sent: int
    received: int
    lost: int
    crc_errors: int
    bad_frames: int
    device_rx_errors: int
    state_age_ms: float | None


class HardwareInterface(abc.ABC):
    """Lifecycle + read/write contract shared by SerialHardware and MockHardware."""

    state: LifecycleState
    fault: str | None

    @abc.abstractmethod
    def configure(self) -> ReturnType: ...

    @abc.abstractmethod
    def activate(self) -> ReturnType: ...

    @abc.abstractmethod
    def deactivate(self) -> ReturnType: ...

    @abc.abstractmethod
    def cleanup(self) -> ReturnType: ...

    @abc.abstractmethod
    def read(self) -> ReturnType: ...

    @abc.abstractmethod
    def write(self, counts: npt.ArrayLike) -> ReturnType: ...

    @abc.abstractmethod
    def on_error(self, reason: str) -> ReturnType: ...

    @abc.abstractmethod
    def positions(self) -> npt.NDArray[np.int64] | None: ...

    @abc.abstractmethod
    def health(self) -> LinkHealth: ...


class SerialHardware(HardwareInterface):
    """The arm controller over the framed serial protocol.

    Args:
        config: Link settings (``BridgeConfig.from_robot``).
        port: Device path or pyserial URL.
        baud: Overrides ``config.baud``.
        transport_factory: ``(port, baud) -> Transport`` (tests and MockHardware inject one).
        clock: Monotonic seconds.
    """

    def __init__(self, config: BridgeConfig, port: str, baud: int | None = None,
                 transport_factory: Callable[[str, int], Transport] = open_serial,
                 clock: Callable[[], float] = time.perf_counter):
        self.config = config
        self.port = port
        self.baud = config.baud if baud is None else baud
        self._factory = transport_factory
        self._clock = clock
        self.state = LifecycleState.UNCONFIGURED
        self.fault: str | None = None
        self.link: Link | None = None
        self._config_ids = itertools.count(1)
        self._rxq: queue.SimpleQueue[p.Message | TransportError] = queue.SimpleQueue()
        self._rx_stop = threading.Event()
        self._rx_thread: threading.Thread | None = None
        self._own_stall = OwnStall(config.period_s)  # this host's stalls since the last STATE

    # -- receive thread ---------------------------------------------------------------------
    def _start_rx(self, link: Link) -> None:
        self._rxq = queue.SimpleQueue()
        self._rx_stop = threading.Event()
        self._rx_thread = threading.Thread(target=_rx_loop, args=(link, self._rxq, self._rx_stop),
                                           daemon=True, name=f"hw-rx {self.port}")
        self._rx_thread.start()

    def _close(self) -> None:
        self._rx_stop.set()
        if self._rx_thread is not None and self._rx_thread is not threading.current_thread():
            self._rx_thread.join(timeout=1.0)
        self._rx_thread = None
        if self.link is not None:
            self.link.transport.close()

    # -- transitions ------------------------------------------------------------------------
    def configure(self) -> ReturnType:
        """Open the port, handshake (HELLO), send CONFIG with retry, wait for telemetry."""
        if self.state is not LifecycleState.UNCONFIGURED:
            return self._refuse(f"configure: already {self.state.value}")
        self.fault = None
        self._own_stall.reset()
        try:
            transport = self._factory(self.port, self.baud)
        except TransportError as exc:
            self.fault = str(exc)
            return ReturnType.ERROR
        self.link = Link(transport, self._clock)
        try:
            transport.reset_input()
            transport.write(p.DELIMITER)  # terminate any partial frame the device holds
            self._start_rx(self.link)
            self.link.send(p.Hello())
            hello = self._wait_for(lambda m: isinstance(m, p.Hello), self.config.hello_timeout_s)
            if hello is None:
                return self.on_error(f"no HELLO answer from {self.port} within "
                                     f"{self.config.hello_timeout_s * 1000:.0f} ms")
            if hello.version != p.PROTOCOL_VERSION or hello.n_motors != self.config.n_motors:
                return self.on_error(
                    f"device speaks protocol v{hello.version} with {hello.n_motors} motors; "
                    f"expected v{p.PROTOCOL_VERSION} with {self.config.n_motors}")
            if not self._send_config():
                return self.on_error(f"no CONFIG_ACK after {self.config.config_retries} tries")
            if self._wait_for(lambda m: isinstance(m, p.State), self.config.hello_timeout_s) is None:
                return self.on_error("no STATE telemetry after configure")
        except TransportError as exc:
            return self.on_error(str(exc))
        self.state = LifecycleState.INACTIVE
        return ReturnType.OK

    def _send_config(self) -> bool:
        assert self.link is not None
        cid = next(self._config_ids) & 0xFFFF
        msg = p.Config(cid, round(self.config.watchdog_s * 1000),
                       p.TELEMETRY_VELOCITIES if self.config.velocities else 0)
        for _ in range(max(1, self.config.config_retries)):
            self.link.send(msg)
            ack = self._wait_for(lambda m: isinstance(m, p.ConfigAck) and m.config_id == cid,
                                 self.config.config_retry_s)
            if ack is not None:
                return ack.result == p.CONFIG_OK
        return False

    def activate(self) -> ReturnType:
        """ARM and stream hold demands until the device reports ARMED (or time out)."""
        if self.state is not LifecycleState.INACTIVE or self.link is None:
            return self._refuse(f"activate: must be inactive, is {self.state.value}")
        hold = self.positions()
        if hold is None:
            return self.on_error("activate: no position telemetry")
        try:
            self.link.send(p.Arm())
            self.link.reset_sequence()
            deadline = self._clock() + self.config.hello_timeout_s
            while self._clock() < deadline:
                self.link.send_demand(hold)
                st = self._wait_for(
                    lambda m: isinstance(m, p.State)
                    and bool(m.status & (p.Status.ARMED | p.Status.ESTOP)), self.config.period_s)
                if st is not None and st.status & p.Status.ARMED:
                    self.state = LifecycleState.ACTIVE
                    return ReturnType.OK
                if st is not None and st.status & p.Status.ESTOP:
                    return self._refuse("activate: hardware e-stop is pressed")
        except TransportError as exc:
            return self.on_error(str(exc))
        return self._refuse("activate: device did not report ARMED")

    def deactivate(self) -> ReturnType:
        """DISARM (controlled stop) and keep telemetry."""
        if self.state is not LifecycleState.ACTIVE or self.link is None:
            return self._refuse(f"deactivate: must be active, is {self.state.value}")
        self.state = LifecycleState.INACTIVE
        try:
            self.link.send(p.Disarm())
        except TransportError as exc:
            return self.on_error(str(exc))
        return ReturnType.OK

    def cleanup(self) -> ReturnType:
        """Disarm if needed and close the port."""
        if self.link is not None:
            if self.state is LifecycleState.ACTIVE:
                try:
                    self.link.send(p.Disarm())
                except TransportError:
                    pass
        self._close()
        self.state = LifecycleState.UNCONFIGURED
        return ReturnType.OK

    def on_error(self, reason: str) -> ReturnType:
        """Stop commanding: best-effort DISARM, close, UNCONFIGURED; keep link stats for the UI."""
        self.fault = reason
        if self.link is not None:
            try:
                self.link.send(p.Disarm())
            except TransportError:
                pass
        self._close()
        self.state = LifecycleState.UNCONFIGURED
        return ReturnType.ERROR

    def _refuse(self, reason: str) -> ReturnType:
        self.fault = reason
        return ReturnType.ERROR

    # -- cycle ------------------------------------------------------------------------------
    def read(self) -> ReturnType:
        """Decode waiting telemetry; ERROR on link loss, transport failure or device fault."""
        if self.state is LifecycleState.UNCONFIGURED or self.link is None:
            return ReturnType.ERROR
        while True:
            try:
                item = self._rxq.get_nowait()
            except queue.Empty:
                break
            if isinstance(item, TransportError):
                return self.on_error(f"link lost: {item}")
        now = self._clock()
        last = self.link.last_state_time
        age = now - last if last is not None else float("inf")
        stalled = self._own_stall.credit(now, last)
        if age - stalled > self.state_timeout_s():
            note = f" (this host stalled {stalled * 1000:.0f} ms of it)" if stalled else ""
            return self.on_error(f"link lost: no valid STATE for {age * 1000:.0f} ms{note}")
        st = self.link.last_state
        if self.state is LifecycleState.ACTIVE and st is not None:
            if st.status & p.Status.WATCHDOG_TRIPPED:
                return self.on_error("device watchdog tripped")
            if st.status & p.Status.ESTOP:
                return self.on_error("hardware e-stop pressed")
            if not st.status & p.Status.ARMED:
                return self.on_error("device disarmed itself")
        return ReturnType.OK

    def state_timeout_s(self) -> float:
        """How long :meth:`read` waits for a STATE before it calls the link lost.

        While ACTIVE the host commands the arm: ``link_timeout_s`` (40 ms), so it stops within
        the device's watchdog. While INACTIVE nothing is commanded, so a late STATE is only late
        telemetry: the patience :meth:`configure` gives the first STATE (``hello_timeout_s``,
        500 ms). At start-up the loop's first reads come while the console, the planner and the
        emulator are still starting on 2 CPUs (a receive thread or the device can be late by
        tens of ms), which with 40 ms showed "link lost" before anyone had armed.
        """
        if self.state is LifecycleState.ACTIVE:
            return self.config.link_timeout_s
        return max(self.config.link_timeout_s, self.config.hello_timeout_s)

    def write(self, counts: npt.ArrayLike) -> ReturnType:
        """Send one DEMAND (all motors, int32 counts); refused unless ACTIVE."""
        if self.state is not LifecycleState.ACTIVE or self.link is None:
            return ReturnType.ERROR
        c = np.asarray(counts)
        if c.shape != (self.config.n_motors,) or not np.all(np.isfinite(c)):
            return self._refuse(f"write: need {self.config.n_motors} finite counts, got {c.shape}")
        if np.any(np.abs(c) >= 2**31):
            return self._refuse("write: counts out of int32 range")
        try:
            self.link.send_demand(np.rint(c).astype(np.int64))
        except TransportError as exc:
            return self.on_error(f"link lost: {exc}")
        return ReturnType.OK

    # -- observers --------------------------------------------------------------------------
    def positions(self) -> npt.NDArray[np.int64] | None:
        """Latest encoder counts, or None before the first STATE."""
        if self.link is None or self.link.last_state is None:
            return None
        return np.asarray(self.link.last_state.positions, dtype=np.int64)

    def device_state(self) -> p.State | None:
        """Latest STATE message."""
        return None if self.link is None else self.link.last_state

    def health(self) -> LinkHealth:
        link = self.link
        st = link.last_state if link else None
        pct = link.rtt_percentiles_ms() if link else {"p50": None, "p99": None}
        age = (None if link is None or link.last_state_time is None
               else (self._clock() - link.last_state_time) * 1000)
        return LinkHealth(
            state=self.state.value, port=self.port, fault=self.fault,
            armed=self.state is LifecycleState.ACTIVE and bool(st and st.status & p.Status.ARMED),
            watchdog_tripped=bool(st and st.status & p.Status.WATCHDOG_TRIPPED),
            estop=bool(st and st.status & p.Status.ESTOP),
            rtt_ms_p50=pct["p50"], rtt_ms_p99=pct["p99"],
            rtt_ms_last=link.rtts[-1] * 1000 if link and link.rtts else None,
            sent=link.counters.sent if link else 0,
            received=link.counters.received if link else 0,
            lost=link.counters.lost if link else 0,
            crc_errors=link.decoder.stats.crc_errors if link else 0,
            bad_frames=link.decoder.stats.bad_frames if link else 0,
            device_rx_errors=link.counters.device_rx_errors if link else 0,
            state_age_ms=age)

    def _wait_for(self, pred: Callable[[p.Message], bool], timeout: float) -> p.Message | None:
        assert self.link is not None
        deadline = self._clock() + timeout
        while True:
            remaining = deadline - self._clock()
            if remaining <= 0:
                return None
            try:
                item = self._rxq.get(timeout=remaining)
            except queue.Empty:
                return None
            if isinstance(item, TransportError):
                raise item
            if pred(item):
                return item


def _rx_loop(link: Link, out: "queue.SimpleQueue[p.Message | TransportError]",
             stop: threading.Event) -> None:
    """Receive thread: chunked reads, decode on arrival, hand messages to the control thread."""
    while not stop.is_set():
        try:
            chunk = link.transport.read_chunk()
        except TransportError as exc:
            if not stop.is_set():
                out.put(exc)
            return
        if chunk:
            for m in link.feed(chunk, link.clock()):
                out.put(m)
