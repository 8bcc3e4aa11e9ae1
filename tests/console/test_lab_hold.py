"""Hold-to-run: a jog moves only while renewed, expires 300 ms after the last renewal, never moves
an arm point faster than 250 mm/s (checked with the kinematics, not the class's own helper),
stays inside the soft limits, stops for a lost lease, and a STOP latches until release."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fakes import FakeClock
from console.core.hold_to_run import HoldToRun
from console.core.model import model_for
from console.core.state import StateStore
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.robots import load


SOFT = load("soft-arm")
EXT = load("extensible")
CAP = 0.25



def planar_points(q: np.ndarray) -> np.ndarray:
    """Segment ends and the gripper's far end (x, y), from the planar FK."""
    poses = pk.forward_kinematics(q, SOFT.lengths, SOFT.base_pose)
    tip = poses[-1]
    far = tip[:2] + SOFT.gripper.length * np.array([math.cos(tip[2]), math.sin(tip[2])])
    return np.vstack([poses[1:, :2], far])


def make(robot, allowed=lambda cid: True, heard=None):
    clock = FakeClock(10.0)
    store = StateStore(model_for(robot))
    hold = HoldToRun(store, allowed=allowed, heard=heard, clock=clock, rate_hz=50.0)
    return store, hold, clock


def run(hold: HoldToRun, clock: FakeClock, seconds: float, renew=None, dt: float = 0.02):
    """Tick for ``seconds`` of fake time; ``renew()`` is called every 0.1 s if given."""
    states, next_renew = [], clock.t
    end = clock.t + seconds
    while clock.t < end - 1e-9:
        if renew is not None and clock.t >= next_renew - 1e-9:
            renew()
            next_renew += 0.1
        clock.t += dt
        states.append((clock.t, hold.tick()))
    return states


def test_a_held_jog_moves_only_while_renewed_and_expires_after_300_ms() -> None:
    store, hold, clock = make(SOFT)
    coord = hold.model.coordinates[0]
    assert hold.hold(1, coord, +1)
    moved = run(hold, clock, 1.0, renew=lambda: hold.hold(1, coord, +1))
    assert all(s is not None for _, s in moved)
    k_after_hold = store.command.q[0]
    assert k_after_hold > 0.5
    last_renewal = clock.t - 0.1 + 0.02  # run() renewed at the start of its last 0.1 s
    after = run(hold, clock, 1.0)
    moving = [t for t, s in after if s is not None]
    assert moving, "the jog should coast until its last renewal expires"
    assert max(moving) - last_renewal <= 0.3 + 0.02 + 1e-9
    assert max(moving) - last_renewal >= 0.3 - 0.04
    frozen = store.command.q[0]
    run(hold, clock, 0.5)
    assert store.command.q[0] == frozen and not hold.active


@pytest.mark.parametrize("coord_index", [0, 3, 5])
def test_no_arm_point_moves_faster_than_250_mm_per_s_while_jogging(coord_index: int) -> None:
    store, hold, clock = make(SOFT)
    hold.sweep_s = 0.5  # ask for a far faster sweep than the cap allows
    coord = hold.model.coordinates[coord_index]
    hold.hold(1, coord, +1)
    prev_t, prev = clock.t, planar_points(store.command.q)
    speeds = []
    for t, state in run(hold, clock, 0.6, renew=lambda: hold.hold(1, coord, +1)):
        if state is None:
            continue
        pts = planar_points(state.q)
        speeds.append(np.max(np.linalg.norm(pts - prev, axis=1)) / (t - prev_t))
        prev_t, prev = t, pts
    assert max(speeds) <= CAP * (1 + 1e-9)
    assert max(speeds) >= 0.9 * CAP  # the cap, not the sweep rate, set the speed


def test_planar_jog_stops_at_the_curvature_limit() -> None:
    store, hold, clock = make(SOFT)
    coord = hold.model.coordinates[5]
    hold.hold(1, coord, -1)
    run(hold, clock, 6.0, renew=lambda: hold.hold(1, coord, -1))
    assert store.command.q[5] == pytest.approx(-SOFT.kappa_max)
    assert np.all(np.abs(store.command.q) <= SOFT.kappa_max + 1e-12)


def test_extensible_set_point_move_keeps_racks_feasible_and_tip_speed_capped() -> None:
    store, hold, clock = make(EXT)
    target = np.array([[0.05, 0.0, 0.30], [0.0, -0.03, 0.12]])
    assert hold.move_to(1, target)
    prev_t, prev_tip = clock.t, dk.tip_position(EXT, store.command.q)
    beta = -EXT.phi + 2 * np.pi * np.arange(3) / 3
    for t, state in run(hold, clock, 5.0):
        if state is None:
            continue
        q = state.q
        racks = EXT.L0 + q[:, 2:3] - q[:, 0:1] * np.cos(beta) - q[:, 1:2] * np.sin(beta)
        assert np.all(racks >= EXT.rack_min - 1e-9) and np.all(racks <= EXT.rack_max + 1e-9)
        tip = dk.tip_position(EXT, q)
        assert np.linalg.norm(tip - prev_tip) / (t - prev_t) <= CAP * (1 + 1e-9)
        prev_t, prev_tip = t, tip
    expected, _ = hold.model.clamp(target)
    np.testing.assert_allclose(store.command.q, expected, atol=1e-12)
    assert not hold.active


def test_losing_the_lease_stops_a_hold_and_a_move_at_the_next_step() -> None:
    lease = {"ok": True}
    store, hold, clock = make(SOFT, allowed=lambda cid: lease["ok"])
    coord = hold.model.coordinates[2]
    hold.hold(1, coord, +1)
    run(hold, clock, 0.2, renew=lambda: hold.hold(1, coord, +1))
    lease["ok"] = False
    q = store.command.q.copy()
    assert all(s is None for _, s in run(hold, clock, 0.2, renew=lambda: hold.hold(1, coord, +1)))
    assert np.array_equal(store.command.q, q)
    assert not hold.move_to(1, np.full(6, 5.0))  # refused outright without the lease
    lease["ok"] = True
    hold.move_to(1, np.full(6, 5.0))
    run(hold, clock, 0.1)
    lease["ok"] = False
    q = store.command.q.copy()
    run(hold, clock, 0.2)
    assert np.array_equal(store.command.q, q) and not hold.active


def test_stop_latches_a_held_button_until_it_is_released() -> None:
    store, hold, clock = make(SOFT)
    coord = hold.model.coordinates[0]
    renew = lambda: hold.hold(1, coord, +1)  # noqa: E731
    renew()
    run(hold, clock, 0.3, renew=renew)
    assert hold.cancel()
    assert store.command.source == "stop"
    q = store.command.q.copy()
    run(hold, clock, 1.0, renew=renew)  # the operator keeps holding: nothing moves
    assert np.array_equal(store.command.q, q)
    clock.t += 1.0  # renewals stalled for 1 s (a busy browser): still latched
    run(hold, clock, 0.5, renew=renew)
    assert np.array_equal(store.command.q, q)
    hold.release(1, coord)  # let go ...
    renew()  # ... and press again
    run(hold, clock, 0.2, renew=renew)
    assert store.command.q[0] > q[0]
    hold.cancel()  # a release whose click never arrived: 2 s without renewals also unlatch
    q = store.command.q.copy()
    clock.t += 2.1
    run(hold, clock, 0.2, renew=renew)
    assert store.command.q[0] > q[0]


def test_stop_between_two_late_renewals_still_latches_the_button() -> None:
    store, hold, clock = make(SOFT)
    coord = hold.model.coordinates[0]
    hold.hold(1, coord, +1)
    run(hold, clock, 0.5)  # a busy browser: no renewal for 0.5 s, the jog expired
    assert not hold.active
    assert not hold.cancel()  # STOP now: nothing was moving ...
    q = store.command.q.copy()
    run(hold, clock, 1.0, renew=lambda: hold.hold(1, coord, +1))  # ... and the late renewals
    assert np.array_equal(store.command.q, q)  # do not restart it


def test_someone_elses_command_cancels_a_set_point_move() -> None:
    store, hold, clock = make(SOFT)
    hold.move_to(1, np.full(6, 10.0))
    run(hold, clock, 0.1)
    planner = store.request(np.zeros(6), "planner")
    run(hold, clock, 0.2)
    assert store.command is planner and not hold.active


def test_bad_set_point_raises_and_changes_nothing() -> None:
    store, hold, _ = make(SOFT)
    with pytest.raises(ValueError, match="finite"):
        hold.move_to(1, [0, 0, np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match="direction"):
        hold.hold(1, hold.model.coordinates[0], 2)
    assert not hold.active and store.command.seq == 0


def test_a_set_point_move_steps_only_while_heartbeats_arrive() -> None:
    """Without an answer from the operator's tab for 300 ms the arm holds; answers resume it."""
    answers: list[float] = []
    store, hold, clock = make(SOFT, heard=lambda cid: answers[-1] if answers else None)
    target = np.full(6, 8.0)
    requested = clock.t
    assert hold.move_to(1, target)
    # No answer at all: the request itself counts for 300 ms, then nothing moves.
    states = run(hold, clock, 1.0)
    moving = [t for t, s in states if s is not None]
    assert moving and max(moving) - requested < 0.3 + 1e-9
    assert max(moving) - requested >= 0.3 - 0.02 - 1e-9
    q = store.command.q.copy()
    assert not np.allclose(q, target)
    run(hold, clock, 1.0)
    assert np.array_equal(store.command.q, q) and hold.active  # held, not given up
    # Heartbeats every 0.1 s (the lease probe): it moves on, no faster than the cap, and arrives.
    prev_t, prev = clock.t, planar_points(store.command.q)
    for t, state in run(hold, clock, 6.0, renew=lambda: answers.append(clock.t)):
        if state is None:
            continue
        pts = planar_points(state.q)
        assert np.max(np.linalg.norm(pts - prev, axis=1)) / (t - prev_t) <= CAP * (1 + 1e-9)
        prev_t, prev = t, pts
    np.testing.assert_allclose(store.command.q, target, atol=1e-12)
    assert not hold.active
    # Heartbeats stop mid-move: it holds within 300 ms of the last one.
    assert hold.move_to(1, np.zeros(6))
    run(hold, clock, 0.5, renew=lambda: answers.append(clock.t))
    last = answers[-1]
    states = run(hold, clock, 1.0)
    moving = [t for t, s in states if s is not None]
    assert moving and max(moving) - last < 0.3 + 1e-9
    assert hold.active and not np.allclose(store.command.q, 0.0)
