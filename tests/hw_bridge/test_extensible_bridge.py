"""The extensible runner's bridge controls (the Hardware panel's connect / disconnect / arm /
disarm / health) on MockHardware and on the pty emulator, and the stall-tolerant serial
transport of the links they open. The rig is in ``extensible_rig.py``.
"""

from __future__ import annotations

import time
from typing import Iterator

import numpy as np
import pytest

from core.kinematics import delta as dk

pytest.register_assert_rewrite("extensible_rig")  # before its import: it holds fixtures
from extensible_rig import (Q0, ROBOT, TIP_TOL, Emulator,  # noqa: E402
                            serial_to, tip_from_counts, wait_for)
from hw_bridge.extensible_runner import ExtensibleRunner  # noqa: E402
from hw_bridge.interface import LifecycleState, LinkHealth  # noqa: E402
from hw_bridge.mock import MockHardware  # noqa: E402

pytest_plugins = ["extensible_rig"]  # its fixtures: mock, runner_on, emulator


# -- bridge controls (the Hardware panel's connect / disconnect / arm / disarm / health) --------

def received(ctl) -> int:
    h = ctl.health()
    return -1 if h is None else h.received


def test_bridge_controls_on_mock_hardware(mock: MockHardware, runner_on) -> None:
    # Before the loop runs, the controls only enqueue: the hardware is untouched.
    idle = ExtensibleRunner(ROBOT, lambda: mock)
    ctl = idle.bridge_controls
    assert ctl is idle.bridge_controls and ctl.health() is None
    ctl.connect("mock://", 0)
    ctl.arm()
    assert mock.state is LifecycleState.UNCONFIGURED and ctl.health() is None

    runner = runner_on(mock)
    ctl = runner.bridge_controls
    wait_for(lambda: ctl.health() is not None and ctl.health().armed, what="armed health")
    assert isinstance(ctl.health(), LinkHealth) and ctl.health().state == "active"

    ctl.disarm()  # DISARM: telemetry goes on, nothing commanded
    wait_for(lambda: runner.snapshot.state == "disarmed", what="disarmed")
    assert mock.state is LifecycleState.INACTIVE
    wait_for(lambda: not ctl.health().armed, what="health: disarmed")
    n = received(ctl)
    wait_for(lambda: received(ctl) > n + 5, what="telemetry while disarmed")
    assert runner.snapshot.measured_tip is not None

    ctl.arm()
    wait_for(lambda: runner.snapshot.state == "holding", what="re-armed")
    assert mock.state is LifecycleState.ACTIVE

    ctl.disconnect()
    wait_for(lambda: runner.snapshot.state == "disconnected", what="disconnected")
    wait_for(lambda: ctl.health().state == "unconfigured", what="health: unconfigured")
    ctl.arm()  # refused until Connect
    wait_for(lambda: "disconnected by the operator" in (ctl.health().fault or ""), what="refusal")
    assert mock.state is LifecycleState.UNCONFIGURED
    ctl.connect("/dev/ttyUSB9", 115200)  # the mock has no port: refused, nothing opened
    wait_for(lambda: "mock device" in (ctl.health().fault or ""), what="mock port refusal")
    assert mock.state is LifecycleState.UNCONFIGURED

    ctl.connect("mock://", 0)  # configured, not armed
    wait_for(lambda: runner.snapshot.state == "disarmed", what="reconnected")
    assert mock.state is LifecycleState.INACTIVE and ctl.health().fault is None
    n = received(ctl)
    wait_for(lambda: received(ctl) > n + 5, what="telemetry after reconnect")
    ctl.arm()
    wait_for(lambda: runner.snapshot.state == "holding", what="armed after reconnect")
    goal = dk.robot_rack_lengths(ROBOT, Q0)
    result = runner.wait(runner.move_to(goal), timeout=30)
    assert result is not None and result.ok, result
    np.testing.assert_allclose(tip_from_counts(mock.positions()), dk.tip_position(ROBOT, Q0),
                               atol=1e-3)

    # A cut cable while disarmed is a fault too; nothing re-arms.
    ctl.disarm()
    wait_for(lambda: runner.snapshot.state == "disarmed", what="disarmed again")
    mock.transport.connected = False
    wait_for(lambda: "link lost" in (ctl.health().fault or ""), what="fault in health")
    wait_for(lambda: runner.snapshot.state == "fault", what="fault in snapshot")
    time.sleep(0.3)
    assert mock.state is LifecycleState.UNCONFIGURED and not ctl.health().armed


def test_bridge_controls_on_the_emulator_over_a_pty(emulator: Emulator, runner_on) -> None:
    hw = serial_to(emulator.port)
    runner = runner_on(hw)
    ctl = runner.bridge_controls
    wait_for(lambda: ctl.health() is not None and ctl.health().armed, what="armed health")
    assert ctl.health().port == emulator.port

    ctl.disconnect()
    wait_for(lambda: ctl.health().state == "unconfigured", what="health: unconfigured")
    wait_for(lambda: runner.snapshot.state == "disconnected", what="disconnected")
    n = received(ctl)
    time.sleep(0.2)
    assert received(ctl) == n  # nothing flows

    ctl.connect(emulator.port, 1_000_000)  # the same pty again: a new SerialHardware
    wait_for(lambda: ctl.health().state == "inactive", what="configured")
    new = runner.device.hw
    assert new is not hw and new.port == emulator.port and new.state is LifecycleState.INACTIVE
    n = received(ctl)
    wait_for(lambda: received(ctl) > n + 10, what="telemetry after reconnect")
    assert runner.snapshot.state == "disarmed" and runner.snapshot.measured_tip is not None

    ctl.arm()
    wait_for(lambda: ctl.health().armed and runner.snapshot.state == "holding", what="armed")
    result = runner.wait(runner.move_to(dk.robot_rack_lengths(ROBOT, Q0)), timeout=30)
    assert result is not None and result.ok, result
    assert np.linalg.norm(tip_from_counts(new.positions()) - dk.tip_position(ROBOT, Q0)) < TIP_TOL

    emulator.proc.kill()
    wait_for(lambda: "link lost" in (ctl.health().fault or ""), what="fault in health")
    wait_for(lambda: runner.snapshot.state == "fault", what="fault in snapshot")
    failures = runner.loop.write_failures
    time.sleep(0.5)
    h = ctl.health()
    assert h.state == "unconfigured" and not h.armed and "link lost" in h.fault
    assert new.state is LifecycleState.UNCONFIGURED  # not re-armed, not even reconfigured
    assert runner.loop.write_failures == failures and runner.snapshot.state == "fault"


# -- the stall-tolerant transport of links the operator opens ---------------------------------

@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    import os
    import tty
    master, slave = os.openpty()
    tty.setraw(slave)
    yield master, os.ttyname(slave)
    os.close(master)
    os.close(slave)


def test_a_completed_write_never_times_out_even_after_a_stall(pty_pair, monkeypatch) -> None:
    import os
    import serial.serialutil
    from hw_bridge.transport import SerialTransport as StallTolerantSerialTransport
    master, path = pty_pair

    class Stalling:
        """A monotonic clock that jumps 1 s at every reading: as if the writing thread had
        waited a second for the GIL around each system call."""

        def __init__(self) -> None:
            self.t = 0.0

        def __call__(self) -> float:
            self.t += 1.0
            return self.t

    frame = bytes(range(1, 40)) + b"\x00"
    plain = serial.serial_for_url(path, baudrate=1_000_000, write_timeout=0.05)  # pyserial alone
    monkeypatch.setattr(serial.serialutil.Timeout, "TIME", Stalling())
    with pytest.raises(serial.SerialTimeoutException, match="Write timeout"):
        plain.write(frame)  # the frame went out, yet it "timed out"
    assert os.read(master, 100) == frame
    plain.close()

    tolerant = StallTolerantSerialTransport(path, 1_000_000)
    monkeypatch.setattr("hw_bridge.transport.time.monotonic", Stalling())
    for _ in range(3):
        tolerant.write(frame)  # written whole: no error whatever the clock says
    got = b""  # the pty's kernel worker may hand the bytes over in more than one piece
    for _ in range(50):
        got += os.read(master, 200)
        if len(got) >= 3 * len(frame):
            break
    assert got == frame * 3
    tolerant.close()


def test_bytes_really_stuck_still_fail_after_the_write_timeout(pty_pair) -> None:
    from hw_bridge.transport import SerialTransport as StallTolerantSerialTransport
    from hw_bridge.transport import TransportError
    master, path = pty_pair
    t = StallTolerantSerialTransport(path, 1_000_000, write_timeout=0.05)
    t0 = time.monotonic()
    with pytest.raises(TransportError, match="stuck for 50 ms"):
        for _ in range(10_000):  # nobody reads the other end: the pty buffer fills up
            t.write(b"x" * 1000)
    assert time.monotonic() - t0 < 60.0  # it fails, not hangs (50 ms each: a generous bound)
    t.close()
