"""The extensible runner's per-tick Streamer, driven tick by tick without a loop thread.

A job's result wakes whoever waits for it (``ExtensibleRunner.wait``); what they read next is
the runner's snapshot. The result must come after the snapshot that shows the job ended, or a
waiter on another thread reads the previous tick's ``settling`` (seen as a flaky
test_runner_executes_a_path_on_mock_hardware under load).
"""

from __future__ import annotations

import numpy as np
import pytest

from core.kinematics import delta as dk
from core.robots import load
from hw_bridge.extensible_jobs import JobResult, joint_move, measure
from hw_bridge.extensible_streamer import Streamer

ROBOT = load("extensible")
N = ROBOT.n_segments


def test_a_jobs_result_is_told_after_the_snapshot_that_shows_it_ended() -> None:
    streamer = Streamer(ROBOT, 0.01, None, settle_counts=3, settle_timeout=3.0)
    start = dk.robot_rack_lengths(ROBOT, np.zeros((N, 3)))
    goal = dk.robot_rack_lengths(ROBOT, np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.0]]))
    path = joint_move(ROBOT, start, goal)
    seen: list[tuple[JobResult, str, JobResult | None]] = []
    streamer.on_result = lambda r: seen.append((r, streamer.snapshot.state,
                                                streamer.snapshot.last_result))
    encoders = dk.motor_counts_from_lengths(ROBOT, start) - streamer.home
    streamer.connected(encoders, follow=False)
    streamer.start_job(1, "move", path)
    states = []
    for k in range(len(path.times) + 5):  # the motors follow each demand exactly
        demand, snap = streamer.update(encoders, k * 0.01)
        states.append(snap.state)
        if demand is not None:
            encoders = demand
        if seen:
            break
    assert states[0] == "running" and "settling" in states, states
    assert len(seen) == 1
    result, state, last = seen[0]
    assert result.ok and result.job_id == 1, result
    assert state == "holding" and last is result  # the snapshot already told it
    assert states[-1] == "holding"


class _Console:
    """A PoseLink whose command the test sets (the console's newest set-point)."""

    always_report = False

    def __init__(self, q: np.ndarray) -> None:
        self.seq, self.q = 1, q

    def setpoint(self) -> tuple[int, np.ndarray]:
        return self.seq, self.q

    def measured(self, delta: np.ndarray) -> None:
        pass

    def settled(self, delta: np.ndarray) -> int:
        self.seq, self.q = self.seq + 1, np.array(delta)
        return self.seq


@pytest.mark.parametrize("periods", [1, 3])
def test_idle_streamer_follows_the_console_within_every_speed_limit(periods: int) -> None:
    """Idle, the demands follow the console's new command at most one period's travel of each
    speed limit per period elapsed (``periods`` > 1: the loop skipped deadlines after a stall),
    on simulated time: the rate limit is the streamer's, whatever the wall clock did."""
    dt = 0.01 * periods
    console = _Console(np.zeros((N, 3)))
    streamer = Streamer(ROBOT, 0.01, console, settle_counts=3, settle_timeout=3.0)
    start = dk.robot_rack_lengths(ROBOT, np.zeros((N, 3)))
    encoders = dk.motor_counts_from_lengths(ROBOT, start) - streamer.home
    streamer.connected(encoders, follow=False)
    goal = np.array([[0.02, 0.0, 0.04], [0.0, -0.01, 0.02]])
    console.seq, console.q = console.seq + 1, goal  # a new command
    demands, states = [encoders], []
    for k in range(2000):
        demand, snap = streamer.update(encoders, k * dt, periods)
        states.append(snap.state)
        assert demand is not None
        demands.append(demand)
        encoders = demand  # the motors follow each demand exactly
        if snap.state == "holding" and k > 0:
            break
    assert states[0] == "following" and states[-1] == "holding", states[-3:]
    measured = [measure(ROBOT, np.asarray(c), streamer.home) for c in demands]
    np.testing.assert_allclose(measured[-1][2], dk.tip_position(ROBOT, goal), atol=1e-4)
    count = 1.0 / ROBOT.counts_per_metre  # demands are whole counts: one count of rounding
    racks = np.array([m[0].ravel() for m in measured])
    motors = np.array(demands, dtype=float) * count
    tips = np.array([m[2] for m in measured])
    assert (np.abs(np.diff(racks, axis=0)).max(axis=1) <= ROBOT.rack_speed * dt + 2 * count).all()
    assert (np.abs(np.diff(motors, axis=0)).max(axis=1) <= ROBOT.motor_speed * dt + count).all()
    assert (np.linalg.norm(np.diff(tips, axis=0), axis=1) <= ROBOT.tip_speed * dt + 1e-4).all()
    # It moved at a limited speed over many periods, not in one step.
    assert len(demands) - 1 >= 10


def test_a_late_tick_delays_the_path_and_skips_no_sample() -> None:
    """After ticks the loop could not keep (``periods`` > 1, the time 3 periods on), the job
    streams its next sample, not the one due by the wall clock: every sample in order, one
    per tick, so the motors never chase a demand across a corner faster than planned."""
    streamer = Streamer(ROBOT, 0.01, None, settle_counts=3, settle_timeout=3.0)
    start = dk.robot_rack_lengths(ROBOT, np.zeros((N, 3)))
    goal = dk.robot_rack_lengths(ROBOT, np.array([[0.02, 0.0, 0.03], [0.0, 0.01, 0.0]]))
    path = joint_move(ROBOT, start, goal)
    expected = path.motor_counts - streamer.home
    encoders = dk.motor_counts_from_lengths(ROBOT, start) - streamer.home
    streamer.connected(encoders, follow=False)
    streamer.start_job(1, "move", path)
    demands, samples = [], []
    t = 0.0
    for k in range(len(path.times)):
        demand, snap = streamer.update(encoders, t, 3 if k % 5 == 4 else 1)
        demands.append(demand)
        samples.append(snap.sample)
        encoders = demand
        t += 0.03 if k % 5 == 4 else 0.01  # every fifth tick comes two periods late
    np.testing.assert_array_equal(np.array(demands), expected)
    assert samples == list(range(len(path.times)))
