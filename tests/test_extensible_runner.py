"""The extensible arm's path runner on MockHardware and on the pty emulator.

Expectations are computed here, independently of the runner: measured tips come straight from
the hardware's encoder counts (+ the retracted pose's counts, L = U m, eq. 2, forward
kinematics), path ends from ``build_path``, speeds from finite differences of the samples.
Links use 0.5 s timeouts (test_hw_emulator.py uses 0.2 s; this 2-core box, shared with other
jobs, stalls processes for up to ~0.3 s) so these tests are about motion, not timing.
"""

from __future__ import annotations

import dataclasses
import functools
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from console.panels.repeatability import run_repeatability
from core.kinematics import delta as dk
from core.planning.paths import build_path, plan_path
from core.robots import load
from hw_bridge.config import BridgeConfig
from hw_bridge.extensible_runner import ExtensibleRunner, home_counts, joint_move, measure
from hw_bridge.interface import LifecycleState, SerialHardware
from hw_bridge.mock import MockHardware
from hw_bridge.transport import SerialTransport

ROOT = Path(__file__).resolve().parent.parent
ROBOT = load("extensible")
N = ROBOT.n_segments
Q0 = np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.03]])  # a little extended: short approach
TIP_TOL = 0.003  # m: "within a few mm"


def tolerant() -> BridgeConfig:
    return dataclasses.replace(BridgeConfig.from_robot(ROBOT), link_timeout_s=0.5, watchdog_s=0.5)


def serial_to(port: str) -> SerialHardware:
    """SerialHardware on the emulator's pty, tolerant like :func:`tolerant` (0.5 s writes too)."""
    return SerialHardware(tolerant(), port,
                          transport_factory=lambda url, baud: SerialTransport(url, baud,
                                                                              write_timeout=0.5))


def tip_from_counts(counts: np.ndarray) -> np.ndarray:
    """Independent: encoders (0 = retracted) -> absolute motor travel -> L = U m -> Delta -> tip."""
    retracted = np.full((N, 3), ROBOT.L0)
    m = np.asarray(counts, float).reshape(N, 3) / ROBOT.counts_per_metre
    m += np.vstack([retracted[:-1] - retracted[1:], retracted[-1:]])  # U^-1 L at retracted
    lengths = np.flip(np.cumsum(np.flip(m, 0), 0), 0)
    return dk.tip_position(ROBOT, dk.delta_from_actuators(lengths, ROBOT.phi, ROBOT.L0))


@functools.lru_cache(maxsize=None)
def short_path(kind: str = "linear", size: float = 0.03, speed: float = 0.1):
    """(MotionPath, waypoints). Plan before starting a runner: planning is seconds of CPU-bound
    Python, which in the loop's process starves it of the GIL (link timeouts, watchdog trips)
    -- the reason the console plans in a worker process."""
    centre = dk.tip_position(ROBOT, Q0)
    return plan_path(ROBOT, build_path(kind, centre, size, "xy"), speed=speed, start_delta=Q0), \
        build_path(kind, centre, size, "xy")


@pytest.fixture
def mock() -> Iterator[MockHardware]:
    hw = MockHardware(ROBOT)
    hw.config = tolerant()
    yield hw
    hw.shutdown()


@pytest.fixture
def runner_on(request: pytest.FixtureRequest) -> Iterator:
    """Factory ``runner_on(hw)``: a started runner; closed at teardown."""
    made: list[ExtensibleRunner] = []

    def make(hw, **kw) -> ExtensibleRunner:
        r = ExtensibleRunner(ROBOT, lambda: hw, **kw).start()
        made.append(r)
        deadline = time.monotonic() + 3.0
        while r.snapshot.state not in ("holding", "fault") and time.monotonic() < deadline:
            time.sleep(0.02)
        assert r.snapshot.state == "holding", r.snapshot
        return r

    yield make
    for r in made:
        r.close()


class Emulator:
    """``python -m hw_bridge.emulator --robot extensible``; its JSON events kept in ``events``."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot",
                                      "extensible"], cwd=ROOT, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.port = self.proc.stdout.readline().strip()
        assert self.port.startswith("/dev/"), self.port
        self.events: list[str] = []
        threading.Thread(target=lambda: self.events.extend(self.proc.stdout), daemon=True).start()


@pytest.fixture
def emulator() -> Iterator[Emulator]:
    emu = Emulator()
    yield emu
    if emu.proc.poll() is None:
        emu.proc.terminate()
    emu.proc.wait(timeout=5)


# -- pure parts -----------------------------------------------------------------------------

def test_home_counts_read_as_the_retracted_pose() -> None:
    assert np.array_equal(home_counts(ROBOT), np.rint(np.repeat([0.0, ROBOT.L0], 3)
                                                      * ROBOT.counts_per_metre))
    L, delta, tip = measure(ROBOT, np.zeros(3 * N, dtype=np.int64), home_counts(ROBOT))
    np.testing.assert_allclose(L, ROBOT.L0)
    np.testing.assert_allclose(delta, 0.0, atol=1e-12)
    np.testing.assert_allclose(tip, [0, 0, N * ROBOT.L0], atol=1e-12)
    counts = np.array([1234, -500, 77, 9000, 4000, 100])
    np.testing.assert_allclose(measure(ROBOT, counts, home_counts(ROBOT))[2],
                               tip_from_counts(counts), atol=1e-12)


def test_joint_move_stays_in_limits_and_under_every_speed_limit() -> None:
    a = dk.robot_rack_lengths(ROBOT, np.zeros((N, 3)))
    b = np.array([[0.30, 0.22, 0.25], [0.12, 0.20, 0.16]])
    mp = joint_move(ROBOT, a, b)
    np.testing.assert_allclose(mp.lengths[0], a)
    np.testing.assert_allclose(mp.lengths[-1], b)
    assert mp.lengths.min() >= ROBOT.rack_min - 1e-12 and mp.lengths.max() <= ROBOT.rack_max + 1e-12
    dt = np.diff(mp.times)
    np.testing.assert_allclose(dt, 0.01)
    rack = np.abs(np.diff(mp.lengths.reshape(len(dt) + 1, -1), axis=0)).max(axis=1) / dt
    motors = dk.motors_from_lengths(mp.lengths).reshape(len(dt) + 1, -1)
    motor = np.abs(np.diff(motors, axis=0)).max(axis=1) / dt
    tips = dk.tip_position(ROBOT, dk.delta_from_actuators(mp.lengths, ROBOT.phi, ROBOT.L0))
    tip = np.linalg.norm(np.diff(tips, axis=0), axis=1) / dt
    assert rack.max() <= ROBOT.rack_speed * 1.001
    assert motor.max() <= ROBOT.rack_speed * 1.001
    assert tip.max() <= ROBOT.tip_speed * 1.01
    # ... and as fast as one of them allows (not needlessly slow).
    assert max(rack.max(), motor.max()) >= 0.9 * ROBOT.rack_speed \
        or tip.max() >= 0.9 * ROBOT.tip_speed


def test_bad_jobs_raise_and_queue_nothing(mock: MockHardware) -> None:
    runner = ExtensibleRunner(ROBOT, lambda: mock)
    with pytest.raises(ValueError, match="lengths"):
        runner.move_to(np.full((N, 3), np.nan))
    mp, _ = short_path()
    with pytest.raises(ValueError, match="motor counts"):
        runner.execute(dataclasses.replace(mp, motor_counts=mp.motor_counts[:, :3]))
    assert not runner.started


# -- on hardware ----------------------------------------------------------------------------

def _check_run(runner: ExtensibleRunner, hw, kind: str) -> None:
    mp, waypoints = short_path(kind)  # planned before the runner started (see short_path)
    result = runner.wait(runner.execute(mp), timeout=30)
    assert result is not None and result.ok, result
    end = tip_from_counts(hw.positions())
    assert np.linalg.norm(end - waypoints[-1]) <= TIP_TOL
    assert np.linalg.norm(result.final_tip - end) <= 1e-3  # runner's own reading agrees
    snap = runner.snapshot
    n = snap.trace_count
    assert snap.state == "holding" and n == snap.n_samples and n >= len(mp.times)
    measured, commanded = snap.trace.measured[:n], snap.trace.commanded[:n]
    assert not np.isnan(measured).any()
    # The measured tip follows the commanded one: each sample lies within TIP_TOL of a tip
    # commanded in the 0.3 s before it (motor lag), and the tip passes every waypoint.
    lag = 30
    for k in range(n):
        assert np.linalg.norm(commanded[max(0, k - lag):k + 1] - measured[k], axis=1).min() \
            <= TIP_TOL, f"sample {k}"
    for w in waypoints:
        assert np.linalg.norm(measured - w, axis=1).min() <= 2 * TIP_TOL


def test_runner_executes_a_path_on_mock_hardware(mock: MockHardware, runner_on) -> None:
    short_path("corners")
    runner = runner_on(mock)
    _check_run(runner, mock, "corners")
    before = mock.positions().copy()
    time.sleep(0.3)  # holding: still armed and streaming, motors still
    assert mock.state is LifecycleState.ACTIVE
    assert np.abs(mock.positions() - before).max() <= 1


def test_runner_executes_a_path_on_the_emulator_over_a_pty(emulator: Emulator, runner_on) -> None:
    short_path("diagonal")
    hw = serial_to(emulator.port)
    runner = runner_on(hw)
    _check_run(runner, hw, "diagonal")


def test_stop_mid_path_holds_position(mock: MockHardware, runner_on) -> None:
    mp, waypoints = short_path("linear", size=0.08, speed=0.05)  # ~2 s
    runner = runner_on(mock)
    job = runner.execute(mp)
    time.sleep(0.8)
    runner.stop()
    result = runner.wait(job, timeout=5)
    assert result is not None and not result.ok and "stopped" in result.message
    time.sleep(0.1)
    held = mock.positions().copy()
    time.sleep(0.5)
    assert mock.state is LifecycleState.ACTIVE  # demands kept coming: no watchdog trip
    assert np.abs(mock.positions() - held).max() <= 1
    assert np.linalg.norm(tip_from_counts(held) - waypoints[-1]) > 0.01  # stopped short
    assert runner.snapshot.state == "holding"


def test_killed_emulator_is_reported_and_commanding_stops(emulator: Emulator, runner_on) -> None:
    mp, _ = short_path("linear", size=0.08, speed=0.05)
    hw = serial_to(emulator.port)
    runner = runner_on(hw)
    job = runner.execute(mp)
    time.sleep(0.6)
    emulator.proc.kill()
    result = runner.wait(job, timeout=5)
    assert result is not None and not result.ok and "aborted" in result.message
    time.sleep(0.1)
    snap = runner.snapshot
    assert snap.state == "fault" and snap.fault and "link lost" in snap.fault
    assert hw.state is LifecycleState.UNCONFIGURED and hw.fault
    failures = runner.loop.write_failures
    time.sleep(0.3)
    assert runner.loop.write_failures == failures <= 1  # no more writes after the fault
    later = runner.wait(runner.execute(mp), timeout=2)  # refused, nothing moves
    assert later is not None and not later.ok and "not started" in later.message


class FakeLink:
    """A PoseLink recording what the runner tells the console."""

    always_report = False

    def __init__(self, q: np.ndarray) -> None:
        self.seq, self.q = 1, q
        self.settled_at: list[np.ndarray] = []

    def setpoint(self):
        return self.seq, self.q

    def measured(self, delta) -> None:
        pass

    def settled(self, delta) -> int:
        self.settled_at.append(np.array(delta))
        self.seq += 1
        self.q = np.array(delta)
        return self.seq


def test_idle_runner_follows_the_console_within_speed_limits(mock: MockHardware, runner_on) -> None:
    link = FakeLink(np.zeros((N, 3)))
    runner = runner_on(mock, link=link)
    goal = np.array([[0.02, 0.0, 0.04], [0.0, -0.01, 0.02]])
    link.seq, link.q = 2, goal
    samples = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < 4.0:
        samples.append((time.monotonic(), mock.positions().copy()))
        if np.linalg.norm(tip_from_counts(samples[-1][1]) - dk.tip_position(ROBOT, goal)) < 5e-4:
            break
        time.sleep(0.05)
    assert np.linalg.norm(tip_from_counts(mock.positions()) - dk.tip_position(ROBOT, goal)) < 1e-3
    (ta, ca), (tb, cb) = samples[0], samples[-1]
    assert tb - ta > 0.2  # it moved at a limited speed, not in one step
    motor_speed = np.abs(cb - ca).max() / ROBOT.counts_per_metre / (tb - ta)
    assert motor_speed <= 1.2 * ROBOT.rack_speed
    # A job's end becomes the console's command.
    result = runner.wait(runner.move_to(dk.robot_rack_lengths(ROBOT, Q0)), timeout=10)
    assert result is not None and result.ok
    np.testing.assert_allclose(link.settled_at[-1], Q0, atol=1e-4)


def test_repeatability_run_reports_per_axis_spread(mock: MockHardware, runner_on) -> None:
    runner = runner_on(mock)
    point = np.array([0.01, -0.005, 0.13])
    result = run_repeatability(runner, ROBOT, point, 2)
    assert result.tips.shape == (2, 3) and result.message == ""
    assert np.linalg.norm(result.tips - point, axis=1).max() <= TIP_TOL
    np.testing.assert_allclose(result.spread, (result.tips.max(0) - result.tips.min(0)) / 2)
    np.testing.assert_allclose(result.offset, result.tips.mean(0) - point)
    with pytest.raises(ValueError, match="unreachable"):
        run_repeatability(runner, ROBOT, [2.0, 0.0, 0.0], 1)
    with pytest.raises(ValueError, match="repetitions"):
        run_repeatability(runner, ROBOT, point, 0)
