"""The emulator's rack slip (--slip) and tip stream (--tip-port), ticked in this process."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from core.kinematics import delta as dk
from core.robots import load
from hw_bridge.emulator import parse_args
from hw_bridge.extensible_jobs import home_counts
from hw_bridge.mocap import UdpMocapReceiver
from hw_bridge.pty_emulator import Emulator, EmulatorOptions

EXT = load("extensible")
L0 = EXT.L0


def _emulator(options: EmulatorOptions) -> Emulator:
    return Emulator(EXT, options, lambda event, **fields: None)


def _close(emu: Emulator) -> None:
    os.close(emu.master)
    if emu.tip_udp is not None:
        emu.tip_udp.close()


def _drive(emu: Emulator, lengths: np.ndarray) -> None:
    """Motors to the counts of rack lengths, ticking the device until they are there."""
    counts = dk.motor_counts_from_lengths(EXT, lengths) - home_counts(EXT)
    emu.core.motors.enabled = True
    emu.core.motors.target = counts.astype(float)
    now = emu.t0
    for _ in range(2000):
        now += emu.bridge.period_s
        emu._tick(now)
        if np.array_equal(emu.core.motors.position, emu.core.motors.target):
            break
    for _ in range(3):
        now += emu.bridge.period_s
        emu._tick(now)


def test_slip_makes_the_racks_fall_short_of_the_encoders_by_the_closed_form() -> None:
    rx = UdpMocapReceiver(0)
    rx.start()
    f, T1, T2 = 0.1, 0.2, 0.12
    emu = _emulator(EmulatorOptions(slip=f, slip_jitter=0.0, tip_noise=0.0005,
                                    tip_port=rx.addr[1]))
    try:
        _drive(emu, np.array([[L0 + T1] * 3, [L0 + T2] * 3]))
        # Encoders: the whole travel. Racks: motor 2 (load 1/2) loses f/2 of T2, motor 1 (load 1)
        # f of its travel T1 - T2; the tip of the straight arm is that much short.
        assert emu.core.motors.encoders == pytest.approx(
            (dk.motor_counts_from_lengths(EXT, np.array([[L0 + T1] * 3, [L0 + T2] * 3]))
             - home_counts(EXT)), abs=1)
        seg2 = L0 + (1 - f / 2) * T2
        seg1 = L0 + (1 - f) * (T1 - T2) + (1 - f / 2) * T2
        assert emu.racks.tip == pytest.approx([0, 0, seg1 + seg2], abs=5e-5)
        end = time.monotonic() + 20.0
        while ((frame := rx.latest()) is None or frame.seq != emu.tip_seq) \
                and time.monotonic() < end:  # the frame of the last tick
            time.sleep(0.01)
        assert frame is not None and frame.points.shape == (1, 3)
        assert frame.points[0] == pytest.approx([0, 0, seg1 + seg2], abs=0.003)  # 6 sigma
    finally:
        _close(emu)
        rx.stop()


def test_without_slip_flags_the_emulator_has_no_slip_and_no_tip_stream() -> None:
    emu = _emulator(EmulatorOptions())
    try:
        assert emu.racks is None and emu.tip_udp is None
        _drive(emu, np.array([[L0 + 0.1] * 3, [L0 + 0.05] * 3]))  # ticks as before
    finally:
        _close(emu)


def test_tip_stream_alone_measures_the_arm_without_slip() -> None:
    emu = _emulator(EmulatorOptions(tip_port=9, tip_noise=0.0))  # discard port
    try:
        cmd = np.array([[0.30, 0.22, 0.25], [0.15, 0.12, 0.10]])
        _drive(emu, cmd)
        expect = dk.tip_position(EXT, dk.delta_from_actuators(cmd, EXT.phi, EXT.L0))
        assert emu.racks.tip == pytest.approx(expect, abs=1e-4)
    finally:
        _close(emu)


def test_slip_flags_are_checked() -> None:
    with pytest.raises(SystemExit):
        parse_args(["--robot", "extensible", "--slip", "0.7"])
    with pytest.raises(SystemExit):
        parse_args(["--robot", "extensible", "--tip-noise", "-1"])
    assert parse_args(["--robot", "extensible", "--slip", "0.1"]).slip == 0.1
    with pytest.raises(ValueError, match="extensible"):
        Emulator(load("soft-arm"), EmulatorOptions(slip=0.1), lambda event, **f: None)
