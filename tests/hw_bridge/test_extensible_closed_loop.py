"""Closed loop on the emulator's tip stream: the runner's moves corrected for rack slip."""

from __future__ import annotations

import subprocess
import sys
from typing import Iterator

import numpy as np
import pytest

from core.control.closed_loop import ClosedLoopSettings
from core.kinematics import delta as dk
from hw_bridge.extensible_closed_loop import TipSensor, closed_loop_move
from hw_bridge.mocap import MocapFrame, UdpMocapReceiver

from extensible_rig import ROBOT, ROOT, runner_on, serial_to  # noqa: F401

# A short move (racks travel <= 0.1 m, about 2 s at the motor speed limit).
TARGET = dk.tip_position(ROBOT, np.array([[0.012, -0.006, 0.09], [-0.006, 0.012, 0.06]]))
SLIP = 0.1


@pytest.fixture
def slipping() -> Iterator[tuple[str, UdpMocapReceiver]]:
    """Emulator with 10 % slip (no jitter) streaming the tip (1 mm noise) to a receiver."""
    rx = UdpMocapReceiver(0)
    rx.start()
    proc = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot", "extensible",
                             "--slip", str(SLIP), "--slip-jitter", "0", "--tip-noise", "0.001",
                             "--tip-port", str(rx.addr[1]), "--seed", "3"],
                            cwd=ROOT, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    port = proc.stdout.readline().strip()
    assert port.startswith("/dev/"), port
    yield port, rx
    proc.terminate()
    proc.wait(timeout=5)
    rx.stop()


def test_tip_loop_corrects_the_slip_the_encoders_cannot_see(slipping, runner_on) -> None:
    port, rx = slipping
    runner = runner_on(serial_to(port))
    tip = TipSensor(rx, samples=10)
    res = closed_loop_move(runner, TARGET, tip, settings=ClosedLoopSettings(iterations=6))
    open_miss = np.linalg.norm(res.measured[0] - TARGET)
    assert open_miss > 0.005  # the open-loop move fell short (slip 10 %)
    assert np.linalg.norm(res.measured[-1] - TARGET) < 0.003
    assert res.corrections >= 1
    # The encoders read the corrected command, not the target: the command overshoots the
    # target by about what slipped, and only the tip sensor told the loop so.
    enc_tip = runner.snapshot.measured_tip  # forward kinematics of the encoders
    assert enc_tip is not None and np.linalg.norm(enc_tip - TARGET) > 0.003


class _Frames:
    """A MocapSource returning scripted frames (newest last)."""

    def __init__(self, frames: list[MocapFrame]) -> None:
        self.frames = frames

    def latest(self) -> MocapFrame | None:
        return self.frames.pop(0) if self.frames else None


def test_tip_sensor_averages_fresh_valid_frames_and_times_out() -> None:
    import time
    now = time.monotonic() + 10  # received "after" the request
    pts = lambda x: np.array([[x, 0.0, 0.3]])  # noqa: E731
    src = _Frames([MocapFrame(1, now, now, pts(0.01), True),
                   MocapFrame(1, now, now, pts(9.0), True),     # same frame again: skipped
                   MocapFrame(2, now, now, pts(9.0), False),    # invalid: skipped
                   MocapFrame(3, now, now, pts(0.03), True)])
    assert TipSensor(src, samples=2).measure() == pytest.approx([0.02, 0.0, 0.3])
    src = _Frames([MocapFrame(4, now, now, pts(0.04), True),
                   MocapFrame(5, now, now, pts(9.0), True)])
    assert TipSensor(src, samples=2).measure(samples=1) == pytest.approx([0.04, 0.0, 0.3])
    with pytest.raises(TimeoutError):
        TipSensor(_Frames([]), samples=1, timeout=0.05).measure()


def test_unreachable_target_moves_nothing(slipping, runner_on) -> None:
    port, rx = slipping
    runner = runner_on(serial_to(port))
    with pytest.raises(ValueError, match="out of reach"):
        closed_loop_move(runner, [0.0, 0.0, 3.0], TipSensor(rx))
    assert runner.snapshot.job_id == 0


def test_repeatability_run_open_vs_closed_loop_on_the_tip_sensor(slipping, runner_on) -> None:
    from console.panels.extensible.repeatability import run_repeatability
    port, rx = slipping
    runner = runner_on(serial_to(port))
    tip = TipSensor(rx)
    enc = run_repeatability(runner, ROBOT, TARGET, 1)  # the encoders: no miss to be seen
    assert enc.source == "encoders" and np.linalg.norm(enc.offset) < 0.001
    open_ = run_repeatability(runner, ROBOT, TARGET, 2, tip=tip)
    closed = run_repeatability(runner, ROBOT, TARGET, 2, tip=tip, closed_loop=True)
    assert open_.message == "" and closed.message == "" and len(closed.tips) == 2
    assert open_.source == closed.source == "tip sensor" and closed.closed_loop
    # 10 % slip, no jitter: the open loop misses the same way twice, the closed loop does not.
    assert np.linalg.norm(open_.offset) > 0.005
    assert np.linalg.norm(closed.offset) < 0.003
