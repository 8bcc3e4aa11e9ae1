"""Lifecycle of the hardware interface against the in-process device (MockHardware) and loop://.

The link's timing (speed limit, link-lost timeouts, the device's watchdog) is checked on a
stoppable clock (:mod:`mock_lockstep`): nothing here asserts a wall-clock figure. The real-time
figures of the link (round trips, detection of a cut) are measured in ``benchmarks/``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from mock_lockstep import Lockstep

from core.robots import load
from hw_bridge import protocol as p
from hw_bridge.config import BridgeConfig, EmulatorConfig
from hw_bridge.device import DeviceCore
from hw_bridge.interface import LifecycleState, ReturnType, SerialHardware
from hw_bridge.mock import DeviceRunner, DeviceTransport, MockHardware
from hw_bridge.plants import MotorBank

ROBOT = load("extensible")
SPEED = EmulatorConfig.from_robot(ROBOT).motor_speed_counts


@pytest.fixture
def rig():
    lock = Lockstep(ROBOT)
    yield lock
    lock.shutdown()


@pytest.fixture
def hw():
    mock = MockHardware(ROBOT)
    yield mock
    mock.shutdown()


def test_configure_activate_move_deactivate(rig: Lockstep) -> None:
    hw = rig.hw
    assert hw.write(np.zeros(6)) is ReturnType.ERROR  # unconfigured: nothing is commanded
    assert hw.configure() is ReturnType.OK and hw.state is LifecycleState.INACTIVE
    assert hw.device.decoder.stats.frames >= 2  # HELLO + CONFIG reached the device
    assert hw.write(np.zeros(6)) is ReturnType.ERROR  # inactive: still nothing
    rig.freeze()
    assert hw.activate() is ReturnType.OK and hw.state is LifecycleState.ACTIVE
    target = np.array([300, -200, 0, 0, 0, 50])
    t0 = rig.clock()
    assert all(r is ReturnType.OK for r in rig.run(target, 3))
    elapsed = rig.clock() - t0
    assert elapsed == pytest.approx(0.03)
    moved = hw.device.motors.position.copy()
    # speed limit: no motor moved further than speed * elapsed
    assert np.all(np.abs(moved) <= SPEED * elapsed + 1e-6)
    assert np.any(np.abs(moved) > 0)  # but they move
    assert abs(moved[0]) < 300  # 300 counts take 66 ms at the limit
    assert all(r is ReturnType.OK for r in rig.run(target, 15))
    np.testing.assert_array_equal(hw.positions(), target)
    h = hw.health()
    assert h.armed and h.lost == 0 and h.crc_errors == 0 and h.rtt_ms_p50 is not None
    assert hw.deactivate() is ReturnType.OK and hw.state is LifecycleState.INACTIVE
    rig.step()
    assert hw.read() is ReturnType.OK
    assert hw.cleanup() is ReturnType.OK and hw.state is LifecycleState.UNCONFIGURED


def test_write_rejects_bad_demands_and_moves_nothing(hw: MockHardware) -> None:
    assert hw.configure() is ReturnType.OK and hw.activate() is ReturnType.OK
    frames = hw.device.decoder.stats.frames
    assert hw.write(np.zeros(5)) is ReturnType.ERROR and "6 finite counts" in hw.fault
    assert hw.write(np.array([np.nan] * 6)) is ReturnType.ERROR
    assert hw.write(np.full(6, 3e9)) is ReturnType.ERROR and "int32" in hw.fault
    assert hw.device.decoder.stats.frames == frames
    assert hw.state is LifecycleState.ACTIVE  # bad input is refused, not a link fault


def test_link_cut_gives_error_within_timeout_and_no_automatic_rearm(rig: Lockstep) -> None:
    hw = rig.hw
    rig.connect_and_arm()
    target = np.full(6, 5000)
    assert all(r is ReturnType.OK for r in rig.run(target, 10))
    assert hw.transport is not None
    hw.transport.connected = False  # cable cut mid-motion
    t_cut = rig.clock()
    while hw.read() is ReturnType.OK:
        assert hw.write(target) is ReturnType.OK
        rig.step()
        assert rig.clock() - t_cut < 1.0
    detected = rig.clock() - t_cut
    # last STATE arrived at the cut, so detection is at the first read past the timeout (the
    # read at exactly 40 ms may go either way: the times are sums of float periods)
    timeout = hw.config.link_timeout_s
    assert timeout - 1e-9 <= detected <= timeout + rig.period + 1e-9, detected
    assert hw.state is LifecycleState.UNCONFIGURED and "no valid STATE" in hw.fault
    frames = hw.device.decoder.stats.frames
    for _ in range(10):  # the loop keeps calling: nothing is sent, nothing re-arms
        assert hw.read() is ReturnType.ERROR and hw.write(target) is ReturnType.ERROR
        rig.step()
    assert hw.device.decoder.stats.frames == frames
    assert hw.device.tripped and not hw.device.armed  # the device stopped on its watchdog
    stopped = hw.device.motors.position.copy()
    # operator: reconnect (configure) then arm (activate)
    rig.thaw()
    assert hw.configure() is ReturnType.OK
    assert hw.health().watchdog_tripped  # latched until ARM
    rig.freeze()
    assert hw.activate() is ReturnType.OK and not hw.device.tripped
    assert all(r is ReturnType.OK for r in rig.run(target, 10))
    assert np.all(hw.device.motors.position > stopped)


def test_a_late_state_on_a_disarmed_link_is_not_link_lost(rig: Lockstep) -> None:
    """Issue 19.3: both arms showed "link lost: no valid STATE for 45 ms" at start, before
    anyone armed. A disarmed (INACTIVE) link commands nothing, so it waits the configure
    patience (hello_timeout, 500 ms) for a STATE, not the armed link's 40 ms; a cable cut
    while disarmed is still found, after that patience."""
    hw = rig.hw
    assert hw.configure() is ReturnType.OK and hw.state is LifecycleState.INACTIVE
    assert hw.state_timeout_s() == hw.config.hello_timeout_s > 5 * hw.config.link_timeout_s
    rig.freeze()
    rig.step()  # the last STATE before the cut arrives now
    assert hw.read() is ReturnType.OK
    assert hw.transport is not None
    hw.transport.connected = False  # no STATE arrives any more
    t_cut = rig.clock()
    late_ok = 0
    while hw.read() is ReturnType.OK:
        if rig.clock() - t_cut > 2 * hw.config.link_timeout_s:
            late_ok += 1  # 80 ms without a STATE: not link lost while disarmed
        rig.step()
        assert rig.clock() - t_cut < 3.0
    detected = rig.clock() - t_cut
    assert late_ok > 0
    patience = hw.config.hello_timeout_s
    assert patience - 1e-9 <= detected <= patience + rig.period + 1e-9, detected
    assert hw.state is LifecycleState.UNCONFIGURED and "no valid STATE" in (hw.fault or "")
    hw.transport.connected = True
    rig.connect_and_arm()
    assert hw.state_timeout_s() == hw.config.link_timeout_s  # armed: the 40 ms rule


def test_config_is_retried_until_acknowledged() -> None:
    cfg = BridgeConfig.from_robot(ROBOT)
    device = DeviceCore(MotorBank(6, SPEED), cfg.watchdog_s, cfg.period_s, now=time.perf_counter())
    runner = DeviceRunner(device)
    seen = {"config": 0}

    class LossyConfig(DeviceTransport):
        def write(self, data: bytes) -> None:
            msgs = p.StreamDecoder().feed(data)
            if any(isinstance(m, p.Config) for m in msgs):
                seen["config"] += 1
                if seen["config"] <= 2:
                    return  # first two CONFIG frames are lost
            super().write(data)

    # A lost CONFIG costs one retry wait of real time; an answered one must not be retried
    # because its CONFIG_ACK took long to reach the host (a 2-core box under load can stall
    # the receive thread for 50 ms, the robot file's retry time): 500 ms of patience here.
    cfg = dataclasses.replace(cfg, config_retry_s=0.5)
    hw = SerialHardware(cfg, "lossy://",
                        transport_factory=lambda port, baud: LossyConfig(runner))
    assert hw.configure() is ReturnType.OK
    assert seen["config"] == 3
    hw.cleanup()
    runner.stop()


def test_config_gives_up_after_retries() -> None:
    cfg = BridgeConfig.from_robot(ROBOT)
    device = DeviceCore(MotorBank(6, SPEED), cfg.watchdog_s, cfg.period_s, now=time.perf_counter())
    runner = DeviceRunner(device)

    class NoConfig(DeviceTransport):
        def write(self, data: bytes) -> None:
            if not any(isinstance(m, p.Config) for m in p.StreamDecoder().feed(data)):
                super().write(data)

    hw = SerialHardware(cfg, "x://", transport_factory=lambda a, b: NoConfig(runner))
    assert hw.configure() is ReturnType.ERROR
    assert "CONFIG_ACK" in hw.fault and hw.state is LifecycleState.UNCONFIGURED
    runner.stop()


def test_loopback_url_is_not_a_device() -> None:
    # loop:// echoes our own HELLO (n_motors=0): configure must refuse with a clear reason.
    hw = SerialHardware(BridgeConfig.from_robot(ROBOT), "loop://")
    assert hw.configure() is ReturnType.ERROR
    assert "0 motors" in hw.fault and hw.state is LifecycleState.UNCONFIGURED


def test_bad_port_is_reported() -> None:
    hw = SerialHardware(BridgeConfig.from_robot(ROBOT), "/dev/does-not-exist")
    assert hw.configure() is ReturnType.ERROR
    assert "does-not-exist" in hw.fault


def test_demands_are_latest_wins_on_the_device() -> None:
    cfg = BridgeConfig.from_robot(ROBOT)
    dev = DeviceCore(MotorBank(6, SPEED), cfg.watchdog_s, cfg.period_s, now=0.0)
    dev.receive(p.encode(p.Arm()) + p.encode(p.Demand.full(10, [100] * 6))
                + p.encode(p.Demand.full(9, [-100] * 6)), now=0.001)
    np.testing.assert_array_equal(dev.motors.target, [100] * 6)  # older seq 9 ignored
    acks = [m.ack_seq for m in p.StreamDecoder().feed(b"".join(dev.take_output()))
            if isinstance(m, p.State)]
    assert acks == [10]


@pytest.mark.parametrize("armed", [False, True])
def test_device_echoes_demand_seq_armed_or_not(armed: bool) -> None:
    dev = DeviceCore(MotorBank(2, 100.0), 0.05, 0.01, now=0.0)
    if armed:
        dev.receive(p.encode(p.Arm()), 0.0)
    dev.receive(p.encode(p.Demand.full(42, [7, 7])), 0.001)
    states = [m for m in p.StreamDecoder().feed(b"".join(dev.take_output()))
              if isinstance(m, p.State)]
    assert states[-1].ack_seq == 42
    assert bool(states[-1].status & p.Status.ARMED) is armed
    np.testing.assert_array_equal(dev.motors.target, [7, 7] if armed else [0, 0])


def test_device_watchdog_latches_until_arm() -> None:
    dev = DeviceCore(MotorBank(1, 1000.0), 0.05, 0.01, now=0.0)
    dev.receive(p.encode(p.Arm()) + p.encode(p.Demand.full(1, [1000])), 0.0)
    t = 0.0
    for _ in range(4):
        t += 0.01
        dev.tick(t)
    assert dev.armed and dev.motors.position[0] == pytest.approx(40.0)
    for _ in range(3):  # 70 ms without a DEMAND
        t += 0.01
        dev.tick(t)
    assert dev.tripped and not dev.armed
    pos = dev.motors.position[0]
    dev.receive(p.encode(p.Demand.full(2, [1000])), t)  # demands alone do not clear the trip
    for _ in range(5):
        t += 0.01
        dev.tick(t)
    assert dev.tripped and dev.motors.position[0] == pos
    dev.receive(p.encode(p.Arm()), t)
    assert dev.armed and not dev.tripped


def test_device_watchdog_does_not_count_the_devices_own_stall() -> None:
    """The emulator shares the loop's CPU: when that CPU is taken for 50 ms, its tick runs late
    and the host's DEMANDs are still on their way in. That lateness is not the host's
    silence; the time the device ran without a DEMAND still is."""
    def armed_device() -> DeviceCore:
        dev = DeviceCore(MotorBank(1, 1000.0), 0.05, 0.01, now=0.0)
        dev.receive(p.encode(p.Arm()) + p.encode(p.Demand.full(1, [10])), 0.0)
        return dev

    dev = armed_device()
    dev.tick(0.01)
    dev.tick(0.065, stalled_s=0.045)  # due at 0.02, ran 45 ms late: 20 ms of host silence
    assert dev.armed and not dev.tripped
    dev.receive(p.encode(p.Demand.full(2, [20])), 0.066)  # the DEMAND that was on its way
    dev.tick(0.075)
    assert dev.armed
    dev.tick(0.12)
    dev.tick(0.127)  # 61 ms after the last DEMAND, all of it running: the host was silent
    assert dev.tripped and not dev.armed

    dev = armed_device()  # the same lateness not declared (a microcontroller): trips
    dev.tick(0.01)
    dev.tick(0.065)
    assert dev.tripped

    dev = armed_device()  # credit does not outlive the next DEMAND
    dev.tick(0.065, stalled_s=0.045)
    dev.receive(p.encode(p.Demand.full(2, [20])), 0.066)
    dev.tick(0.12)
    assert dev.tripped  # 54 ms since that DEMAND


class _NullTransport:
    def __init__(self) -> None:
        self.written: list[bytes] = []

    def read_chunk(self) -> bytes:
        return b""

    def write(self, data: bytes) -> None:
        self.written.append(data)

    def reset_input(self) -> None:
        pass

    def close(self) -> None:
        pass


def _active_link(clock) -> SerialHardware:
    """An armed SerialHardware whose last STATE arrived at clock time 0 (no threads)."""
    from hw_bridge.link import Link
    hw = SerialHardware(BridgeConfig.from_robot(ROBOT), "null://", clock=clock)
    hw.link = Link(_NullTransport(), clock)
    hw.state = LifecycleState.ACTIVE
    hw.link.last_state = p.State(1, 0, 0, int(p.Status.ARMED), 0, (0,) * 6)
    hw.link.last_state_time = 0.0
    return hw


def test_link_lost_counts_only_the_time_the_host_listened() -> None:
    """The host's own stall (its read() late because its CPU was taken) is not the device's
    silence: the link is lost after 40 ms without STATE while the host was reading."""
    now = [0.0]
    clock = lambda: now[0]  # noqa: E731
    timeout = BridgeConfig.from_robot(ROBOT).link_timeout_s
    assert timeout == pytest.approx(0.04)

    hw = _active_link(clock)  # a punctual host: unchanged, lost at the first read past 40 ms
    for k in range(1, 6):
        now[0] = k * 0.01
        r = hw.read()
        assert (r is ReturnType.OK) == (k * 0.01 <= timeout + 1e-9), k
    assert "no valid STATE for 50 ms" in (hw.fault or "") and "stalled" not in hw.fault

    hw = _active_link(clock)  # reads at 10, 20, 30 ms, then the host stalls until 90 ms
    for t in (0.01, 0.02, 0.03, 0.09):
        now[0] = t
        assert hw.read() is ReturnType.OK, t  # 90 ms old, 50 of them the host's own stall
    hw.link.last_state_time = 0.092  # the device was there all along
    now[0] = 0.10
    assert hw.read() is ReturnType.OK
    for t in (0.11, 0.12, 0.13):  # and the credit went with that STATE
        now[0] = t
        assert hw.read() is ReturnType.OK
    now[0] = 0.14
    assert hw.read() is ReturnType.ERROR  # 48 ms without STATE, listening all the time

    hw = _active_link(clock)  # a stall, then still no STATE: lost 40 listening ms after it
    for t in (0.01, 0.02, 0.03, 0.09):
        now[0] = t
        assert hw.read() is ReturnType.OK
    now[0] = 0.10
    assert hw.read() is ReturnType.ERROR
    assert "no valid STATE for 100 ms (this host stalled 50 ms of it)" in (hw.fault or "")


def test_device_reports_demands_replaced_before_a_tick_acted_on_them() -> None:
    """One DEMAND per period leaves none unacted; a burst read at once (the emulator stalled,
    the host's demands queued in the pty) moves the motors toward the newest only, and the
    device says how many it skipped (the emulator logs it: ``demands_superseded``)."""
    cfg = BridgeConfig.from_robot(ROBOT)
    device = DeviceCore(MotorBank(6, SPEED), cfg.watchdog_s, cfg.period_s, now=0.0)
    device.receive(p.encode(p.Arm()), 0.0)
    t, seq = 0.0, 0
    for _ in range(5):  # paced: a demand, then a tick
        seq += 1
        device.receive(p.encode(p.Demand.full(seq, [seq] * 6)), t)
        t += cfg.period_s
        device.tick(t)
    assert device.take_events().superseded == 0
    for _ in range(7):  # a burst of seven before the next tick
        seq += 1
        device.receive(p.encode(p.Demand.full(seq, [seq] * 6)), t)
    t += cfg.period_s
    device.tick(t)
    assert device.take_events().superseded == 6
    assert device.motors.target.tolist() == [seq] * 6  # the newest wins
