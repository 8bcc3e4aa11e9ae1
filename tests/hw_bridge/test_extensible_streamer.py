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
from hw_bridge.extensible_jobs import JobResult, joint_move
from hw_bridge.extensible_streamer import Streamer

pytestmark = pytest.mark.timing

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
    streamer.start_job(1, "move", path, 0.0)
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
