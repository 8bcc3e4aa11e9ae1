"""The extensible arm's path runner on MockHardware and on the pty emulator.

Expectations are computed here, independently of the runner: measured tips come straight from
the hardware's encoder counts (+ the retracted pose's counts, L = U m, eq. 2, forward
kinematics), path ends from ``build_path``, speeds from finite differences of the samples.
The rig (robot, tolerant links, emulator, started runners) is in ``extensible_rig.py``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from typing import Callable

import numpy as np
import pytest

from console.panels.extensible.repeatability import run_repeatability
from core.kinematics import delta as dk

pytest.register_assert_rewrite("extensible_rig")  # before its import: it holds fixtures
from extensible_rig import (N, Q0, ROBOT, TIP_TOL, Emulator,  # noqa: E402
                            serial_to, short_path, tip_from_counts, wait_for)
from hw_bridge.extensible_jobs import home_counts, joint_move, measure  # noqa: E402
from hw_bridge.extensible_runner import ExtensibleRunner  # noqa: E402
from hw_bridge.interface import LifecycleState  # noqa: E402
from hw_bridge.mock import MockHardware  # noqa: E402

pytest_plugins = ["extensible_rig"]  # its fixtures: mock, runner_on, emulator


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
    assert motor.max() <= ROBOT.motor_speed * 1.001
    assert tip.max() <= ROBOT.tip_speed * 1.01
    # ... and as fast as one of them allows (not needlessly slow).
    assert rack.max() >= 0.9 * ROBOT.rack_speed or motor.max() >= 0.9 * ROBOT.motor_speed \
        or tip.max() >= 0.9 * ROBOT.tip_speed


def test_joint_move_with_racks_in_opposite_directions_is_paced_by_the_motors() -> None:
    # Straight arm: segment 1's racks 0.10 -> 0.30 m, segment 2's 0.30 -> 0.10 m. The tip stays
    # put, the racks travel 0.2 m, motor 1 (m1 = L1 - L2) 0.4 m. Closed form: 0.4 m at the
    # planned motor speed (margin, one count per sample in reserve), rounded up to a sample.
    a = np.array([[0.10] * 3, [0.30] * 3])
    b = a[::-1].copy()
    mp = joint_move(ROBOT, a, b)
    v = min(0.98 * ROBOT.motor_speed, ROBOT.motor_speed - 100.0 / ROBOT.counts_per_metre)
    assert mp.duration == pytest.approx(np.ceil(0.4 / v * 100 - 1e-9) / 100, abs=1e-9)
    steps = np.abs(np.diff(mp.motor_counts, axis=0)).max(axis=1) / np.diff(mp.times)
    assert steps.max() <= ROBOT.motor_speed * ROBOT.counts_per_metre  # integer demands, counts/s
    np.testing.assert_allclose(mp.tips, np.tile([0, 0, 0.4], (len(mp.times), 1)), atol=1e-12)


def test_joint_move_goal_bent_beyond_the_limit_is_brought_within_it() -> None:
    a = dk.robot_rack_lengths(ROBOT, np.zeros((N, 3)))
    bent = dk.robot_rack_lengths(ROBOT, np.array([[0.09, 0.0, 0.25], [0.0, 0.0, 0.1]]))  # 3 rad
    mp = joint_move(ROBOT, a, bent)
    theta = np.hypot(mp.deltas[..., 0], mp.deltas[..., 1]) / ROBOT.rack_radius
    assert theta.max() <= ROBOT.theta_max
    np.testing.assert_allclose(mp.deltas[-1], [[ROBOT.rack_radius * ROBOT.theta_max, 0, 0.25],
                                               [0, 0, 0.1]], atol=1e-9)


def test_public_names_are_importable_from_the_modules_that_define_them() -> None:
    import hw_bridge.extensible_jobs as ej
    import hw_bridge.extensible_runner as er
    for module, names in ((er, ("ExtensibleRunner", "mock_factory")),
                          (ej, ("StoreLink", "PoseLink", "RunnerSnapshot", "JobResult",
                                "JobTrace", "home_counts", "measure", "joint_move"))):
        for name in names:
            assert getattr(module, name).__module__ == module.__name__, name


def test_bad_jobs_raise_and_queue_nothing(mock: MockHardware) -> None:
    runner = ExtensibleRunner(ROBOT, lambda: mock)
    with pytest.raises(ValueError, match="lengths"):
        runner.move_to(np.full((N, 3), np.nan))
    mp, _ = short_path()
    with pytest.raises(ValueError, match="motor counts"):
        runner.execute(dataclasses.replace(mp, motor_counts=mp.motor_counts[:, :3]))
    assert not runner.started


# -- on hardware ----------------------------------------------------------------------------

def _check_run(runner: ExtensibleRunner, hw, kind: str,
               superseded: Callable[[], int] = lambda: 0) -> None:
    """Run ``kind``'s short path; ``superseded()``: the demands the device replaced before
    acting on them during the run (the pty emulator's own stalls; 0 for the in-process mock)."""
    mp, waypoints = short_path(kind)  # planned before the runner started (see short_path)
    result = runner.wait(runner.execute(mp), timeout=60)
    assert result is not None and result.ok, result
    end = tip_from_counts(hw.positions())
    assert np.linalg.norm(end - waypoints[-1]) <= TIP_TOL
    assert np.linalg.norm(result.final_tip - end) <= 1e-3  # runner's own reading agrees
    snap = runner.snapshot
    n = snap.trace_count
    assert snap.state == "holding" and n == snap.n_samples and n >= len(mp.times)
    measured, commanded = snap.trace.measured[:n], snap.trace.commanded[:n]
    assert not np.isnan(measured).any()
    # The measured tip follows the commanded one, never ahead of it: each sample lies as near
    # to a tip commanded by then (one sample's slack for the encoder's quantisation) as to any
    # commanded later, within 0.5 mm (a path that comes back over itself, as the diagonal does
    # through its centre, commands the same points twice: a fresh run's sample 71 lay on the
    # return leg's sample 103 as well as on the way out). How
    # far behind, and so how far it cuts a corner of the path (the path runs at the motors' speed
    # limits: a device that fell behind chases the newest demand straight across the corner; 3.3
    # mm off the path at a loaded run's corner), depends on how the device was scheduled: a
    # figure (benchmarks/bench_serial_link.py), not asserted. A late loop tick no longer skips
    # samples (a loaded run once missed a corner by 39 mm); a stalled emulator still does, and
    # says how many (below): the tip passes every waypoint and ends on the last.
    for k in range(n):
        gap = np.linalg.norm(commanded - measured[k], axis=1)
        by_then, later = gap[:k + 2].min(), gap[k + 2:].min(initial=np.inf)
        assert by_then <= later + 5e-4, (
            f"sample {k} is ahead of the command: {by_then * 1e3:.2f} mm from the tips "
            f"commanded by then, {later * 1e3:.2f} mm from a later one")
    # A device that skipped demands (the emulator stalled: it logs how many) went straight
    # for the newest: a corner may be cut by the path's travel over the skipped samples.
    step = float(np.linalg.norm(np.diff(mp.tips, axis=0), axis=1).max())
    skipped = superseded()
    for w in waypoints:
        miss = np.linalg.norm(measured - w, axis=1).min()
        assert miss <= 2 * TIP_TOL + skipped * step, (
            f"waypoint {w} missed by {miss * 1e3:.1f} mm ({skipped} demands skipped)")


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
    _check_run(runner, hw, "diagonal", lambda: _skipped_demands(emulator))


def _skipped_demands(emulator: Emulator) -> int:
    """The demands the emulator replaced unacted (its own stalls), all stalls together: the
    device then chases the newest demand at the motors' speed limits, which the path runs at
    too, so the lags of two stalls add up (fresh41, a loaded machine: a corner cut by 54.8 mm,
    over the 54.0 mm that its longest stall, 49 demands, allowed by itself)."""
    events = [json.loads(line) for line in list(emulator.events) if line.startswith("{")]
    return sum(e["count"] for e in events if e.get("event") == "demands_superseded")


def running_at(runner: ExtensibleRunner, job: int, sample: int) -> bool:
    """Whether ``job`` runs and has streamed up to ``sample`` (of its path's samples)."""
    snap = runner.snapshot
    return snap.job_id == job and snap.state == "running" and snap.sample >= sample


def still(runner: ExtensibleRunner, hw, frames: int = 10) -> bool:
    """Whether ``hw``'s encoders read the same over the next ``frames`` telemetry frames."""
    before = hw.positions().copy()
    n = runner.bridge_controls.health().received
    wait_for(lambda: runner.bridge_controls.health().received >= n + frames, what="telemetry")
    return bool(np.array_equal(hw.positions(), before))


def test_stop_mid_path_holds_position(mock: MockHardware, runner_on) -> None:
    mp, waypoints = short_path("linear", size=0.08, speed=0.05)  # ~2 s
    runner = runner_on(mock)
    job = runner.execute(mp)
    # Stop early in the path (~0.3 s in; a fixed sleep could outlast the path on a busy box).
    wait_for(lambda: running_at(runner, job, 30), what="the path under way")
    runner.stop()
    result = runner.wait(job, timeout=30)
    assert result is not None and not result.ok and "stopped" in result.message
    wait_for(lambda: runner.snapshot.state == "holding", what="holding")
    # The hold is where the encoders last read: the motors, a tick or two further on by then,
    # go back there (about 1 mm) and stay.
    wait_for(lambda: still(runner, mock), what="the motors at rest")
    sent = runner.bridge_controls.health().sent
    held = mock.positions().copy()
    # Demands keep coming while it holds (no watchdog trip), and the motors stay put.
    wait_for(lambda: runner.bridge_controls.health().sent > sent + 20, what="demands streamed")
    assert mock.state is LifecycleState.ACTIVE
    assert np.abs(mock.positions() - held).max() <= 1
    assert np.linalg.norm(tip_from_counts(held) - waypoints[-1]) > 0.01  # stopped short
    assert runner.snapshot.state == "holding"


def test_killed_emulator_is_reported_and_commanding_stops(emulator: Emulator, runner_on) -> None:
    mp, _ = short_path("linear", size=0.08, speed=0.05)
    hw = serial_to(emulator.port)
    runner = runner_on(hw)
    job = runner.execute(mp)
    wait_for(lambda: running_at(runner, job, 20), what="the path under way")
    emulator.proc.kill()
    result = runner.wait(job, timeout=30)
    assert result is not None and not result.ok and "aborted" in result.message
    wait_for(lambda: runner.snapshot.state == "fault", what="the fault in the snapshot")
    snap = runner.snapshot
    assert snap.state == "fault" and snap.fault and "link lost" in snap.fault
    assert hw.state is LifecycleState.UNCONFIGURED and hw.fault
    failures = runner.loop.write_failures
    time.sleep(0.3)
    assert runner.loop.write_failures == failures <= 1  # no more writes after the fault
    later = runner.wait(runner.execute(mp), timeout=30)  # refused, nothing moves
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
    link.seq, link.q = link.seq + 1, goal  # a new command (Arm settled the last one)
    # The speed limits of the follow are checked tick by tick on simulated time
    # (test_extensible_streamer.py); here: the runner follows the link to the goal.
    wait_for(lambda: np.linalg.norm(tip_from_counts(mock.positions())
                                    - dk.tip_position(ROBOT, goal)) < 5e-4, what="at the goal")
    wait_for(lambda: runner.snapshot.state == "holding", what="holding at the goal")
    # A job's end becomes the console's command.
    result = runner.wait(runner.move_to(dk.robot_rack_lengths(ROBOT, Q0)), timeout=30)
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
