"""The extensible arm's runner in its own process (hw_bridge.extensible_process): connects
disarmed, holds once armed, runs a move to the commanded posture within a few mm, reports it to the console's store,
follows the console's newer commands (not its own settled one), obeys the Hardware panel's
bridge verbs and refuses bad jobs before anything is sent."""

from __future__ import annotations

import time
from typing import Iterator

import numpy as np
import pytest

from console.core.model import model_for
from console.core.state import StateStore
from core.kinematics import delta as dk
from core.robots import load
from hw_bridge.extensible_process import ExtensibleProcess

ROBOT = load("extensible")
Q0 = np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.03]])
Q1 = np.array([[0.01, 0.0, 0.05], [0.0, -0.01, 0.04]])
TIP_TOL = 0.003  # m


def wait_for(pred, timeout: float = 20.0, what: str = "") -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


@pytest.fixture
def proc() -> Iterator[tuple[ExtensibleProcess, StateStore]]:
    store = StateStore(model_for(ROBOT), mirror_commands=True)
    p = ExtensibleProcess(ROBOT, store, "mock", cpus=None, sched_priority=None)
    try:
        yield p, store
    finally:
        p.close()


def test_move_report_follow_and_bridge_verbs_in_the_child(proc) -> None:
    p, store = proc
    assert not p.started and p.snapshot.state == "disconnected"
    p.start()
    assert p.connecting is not None and p.connecting.result(30) is None  # no fault
    # Connecting configures the link and never arms it: only the operator's Arm does.
    wait_for(lambda: p.snapshot.state == "disarmed", what="connected, disarmed")
    # (the link's health and the loop's view travel apart: wait for the health too)
    wait_for(lambda: p.bridge_controls.health() is not None, what="health")
    assert not p.bridge_controls.health().armed
    # The mock starts at the console's start pose (mid-range), so arming moves nothing.
    np.testing.assert_allclose(p.snapshot.measured_delta, model_for(ROBOT).initial(), atol=5e-5)
    job = p.move_to(dk.robot_rack_lengths(ROBOT, Q0))
    refused = p.wait(job, timeout=30)
    assert refused is not None and not refused.ok and "arm first" in refused.message, refused
    p.bridge_controls.arm()
    wait_for(lambda: p.snapshot.state in ("holding", "following"), what="armed")
    wait_for(lambda: p.bridge_controls.health().armed, what="health: armed")
    assert p.port == "mock://"

    job = p.move_to(dk.robot_rack_lengths(ROBOT, Q0))
    result = p.wait(job, timeout=30)
    assert result is not None and result.ok and result.error < TIP_TOL, result
    wait_for(lambda: store.command.source == "runner", what="settled command")
    np.testing.assert_allclose(store.command.q, Q0, atol=1e-6)  # the job's end is the command
    # The job's answer and the loop's published view travel apart: the view may be a cycle
    # older than the answer, so wait for it to show the arm there.
    wait_for(lambda: p.snapshot.measured_tip is not None and np.linalg.norm(
        p.snapshot.measured_tip - dk.tip_position(ROBOT, Q0)) < TIP_TOL, what="view at Q0")

    q1 = store.request(Q1, "jog")  # the console's newer command (the console core sends it
    p.setpoint(q1.seq, q1.q)       # on as a set-point, nothing watches the store): followed
    wait_for(lambda: np.linalg.norm(p.snapshot.measured_tip - dk.tip_position(ROBOT, Q1))
             < TIP_TOL, what="following the console")

    p.bridge_controls.disarm()
    wait_for(lambda: p.snapshot.state == "disarmed", what="disarmed")
    wait_for(lambda: not p.bridge_controls.health().armed, what="health: disarmed")
    p.bridge_controls.disconnect()
    p.bridge_controls.arm()  # refused until Connect
    wait_for(lambda: "disconnected by the operator" in (p.bridge_controls.health().fault or ""),
             what="refusal")
    p.bridge_controls.connect("mock://", 0)
    p.bridge_controls.arm()
    wait_for(lambda: p.snapshot.state == "holding", what="armed again")

    p.close()
    assert not p.alive
    with pytest.raises(RuntimeError, match="not running"):
        p.stop().result(10)


def test_bad_jobs_raise_before_anything_is_sent(proc) -> None:
    p, _ = proc
    with pytest.raises(ValueError, match="lengths"):
        p.move_to(np.full((ROBOT.n_segments, 3), np.nan))
    assert not p.started


def test_a_settled_reply_never_takes_back_a_set_point_sent_after_what_the_runner_saw() -> None:
    """Where the runner holds comes back as the console's command (a halt, a job's end), tagged
    with the newest set-point it had seen. A set-point sent after that one (a jog started again
    after a hold-to-run expiry, while the reply was on its way) is what the runner follows next:
    the console's command stays with it. Before, the reply replaced it and the console's
    command jumped back to the old pose while the arm followed the jog (a loaded fresh run:
    Δx₁ read -1e-16 after a + jog)."""
    from hw_bridge.extensible_process import SOURCE

    store = StateStore(model_for(ROBOT))
    runner = ExtensibleProcess(ROBOT, store, cpus=None)  # not started: its parent side only
    runner._proc = FakeChild()  # noqa: SLF001 -- "alive": set-points are sent (queued)
    held = np.zeros((ROBOT.n_segments, 3))
    held[:, 2] = 0.02  # extended: bends are allowed
    seen = store.request(held, "jog")
    runner.setpoint(seen.seq, seen.q)  # the runner had this one when it halted
    jogged = held.copy()
    jogged[0, 0] = 0.004
    newer = store.request(jogged, "jog")  # the operator's next command, after the halt
    np.testing.assert_array_equal(newer.q, jogged)  # (within the limits)
    runner.setpoint(newer.seq, newer.q)
    runner.on_message(("settled", held, seen.seq))
    assert store.command.seq == newer.seq
    np.testing.assert_array_equal(store.command.q, jogged)
    runner.on_message(("settled", jogged, newer.seq))  # it saw the newest: its hold is the command
    assert store.command.source == SOURCE and store.command.seq > newer.seq
    np.testing.assert_allclose(store.command.q, jogged)
    # A STOP's own command is never sent to the runner: its hold replaces it.
    stop = store.request(jogged, "stop")
    runner.on_message(("settled", held, newer.seq))
    assert store.command.seq > stop.seq and store.command.source == SOURCE
    np.testing.assert_allclose(store.command.q, held)


class FakeChild:
    """A child process that is alive (what ``LoopProcess.alive`` asks)."""

    pid = 1

    def is_alive(self) -> bool:
        return True
